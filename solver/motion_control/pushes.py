"""Pushes: Impulse entries of ControlSettings. One with a duration is an external force the
inverse dynamics takes as a known wrench; an instant one changes the velocities through the
inertia matrix, dv = H^-1 J' p, with the joints' servo resisting it over the step
(servoed_inertia) and the planted feet held (feet.PlantedFeet.through_feet: the ground takes its
share)."""

from dataclasses import dataclass

import numpy as np
from scipy.linalg import cho_factor, cho_solve

from ..dynamics import kinematics
from .body import inertia
from .vector_math import cross


@dataclass
class Push:
    """An Impulse resolved on the skeleton: time (s), duration (s), bone index, point (bone frame,
    m) and the world impulse (N s) or force (N) vector."""

    time: float
    duration: float
    joint: int
    point: np.ndarray
    vector: np.ndarray

    @classmethod
    def of(cls, impulse, skeleton):
        d = np.asarray(impulse.direction, float)
        d = d / max(np.linalg.norm(d), 1e-12)
        return cls(float(impulse.time), float(impulse.duration), skeleton.index(impulse.bone),
                   np.asarray(impulse.point, float), float(impulse.magnitude) * d)


def push_forces(pushes, body, q, t):
    """World wrenches (nb, 6) of the pushes with a duration active at t, or None."""
    m, d = body.model, body.data
    out = None
    for p in pushes:
        if p.duration > 0.0 and p.time <= t < p.time + p.duration:
            x = kinematics.point_positions(m, d, q, [p.joint], [p.point])[0]
            w = np.zeros((m.nb, 6))
            w[m.joint_body[p.joint]] = np.r_[cross(x, p.vector), p.vector]
            out = w if out is None else out + w
    return out


def apply_impulses(pushes, body, q, v, t, dt, servo_times=None, feet=None):
    """Instant impulses falling in [t, t + dt): dv = H^-1 J' p, with the tracking servo's damping
    over the step (servoed_inertia; `servo_times` the tracking's target times at t, None for a
    body without servo) and the planted feet held (`feet`: a function dv -> dv given H^-1, or
    None). Returns (v, whether any)."""
    m, d = body.model, body.data
    pushed = False
    for p in pushes:
        if p.duration == 0.0 and t - 1e-9 <= p.time < t + dt - 1e-9:
            jac = kinematics.point_jacobian(m, d, q, p.joint, p.point)
            factor = cho_factor(servoed_inertia(body, q, t, dt, servo_times))
            dv = cho_solve(factor, jac.T @ p.vector)
            if feet is not None:
                dv = feet(lambda x: cho_solve(factor, x), dv)
            v = v + dv
            pushed = True
    return v, pushed


def servoed_inertia(body, q, t, dt, servo_times):
    """H with the tracking servo's damping over the step: H_ii (1 + 4 dt / h_i) on each actuated
    DOF, h_i its horizon (servo_times - t). The Ferguson acceleration (eq. 2.6) falls by 4 / h per
    unit of velocity; within the step of an impulse it resists the velocity the impulse gives,
    taken implicitly as the step integrates it. Without it a push met free joints: 45 N s on the
    standing metarig's pelvis spun the light pelvis at 14 rad/s and its legs thrashed. A fallen
    body has no servo (servo_times None: its ragdoll damping is the step's own)."""
    m = body.model
    h = inertia(m, body.data, q)
    if servo_times is not None:
        gain = (4.0 * dt) / (servo_times - t)
        gain[:6] = 0.0  # the root is not actuated
        h.flat[::m.nv + 1] *= 1.0 + gain
    return h
