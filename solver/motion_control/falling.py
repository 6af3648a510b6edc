"""Falling (Oshita 2003, sec. 2.3.3) and the fallen body.

When balance control has reported for `fall_time` that the ZMP cannot be brought inside the
support polygon (one glitch of a captured motion does not fell the figure) and the capture point
lies beyond the feet (can_stop: the figure could not stop without a step), that step's output
turns the body about the MMP (balance_control.Falling.base_acceleration) and the figure is
released; an instant impulse whose momentum carries the capture point that far out releases it
at once (knocked_over). Released, it is a ragdoll (ragdoll_velocity: no joint torques but damping,
the joint limits as stiff springs, both implicit) kept on the ground by the contact impulses
(collisions.py) at the steps its contact spheres' speed needs (fall_steps).
"""

import math
from dataclasses import dataclass

import numpy as np
from scipy.linalg import cho_factor, cho_solve

from ..dynamics import kinematics
from ..dynamics.balance import closest_boundary_point, inside
from ..dynamics.inertia_matrix import bias_forces, crba
from ..dynamics.strength import limit_torques
from .balance_control import support_polygon
from .vector_math import cross

KNOCKED_OVER = "knocked over"  # a step's fall from an impulse (no base acceleration: released as it is)
FALL_STEP_TRAVEL = 0.01  # m a contact sphere may travel in one step of a fallen body (fall_steps)
RAGDOLL_JOINT_SPEED = 40.0  # rad/s (ragdoll_velocity; strength.py's fastest joints: 40)
# m beyond the input's own capture-point excursion (arms swung by passive control move the centre
# of mass quickly without the body falling; a 150 N s push: 0.6 m)
CAPTURE_TOLERANCE = 0.2


def capture_offset(cs, ground, gravity, v=None):
    """The capture point's offset (x, y) from the support polygon (from its nearest point; 0
    inside or without support), with velocities `v` (default the control state's): the centre of
    mass extrapolated by its velocity over sqrt(h / g) (Hof 2005), where a standing figure can
    still stop without a step."""
    polygon = support_polygon(cs)
    if len(polygon) < 3:
        return 0.0, 0.0
    m, d = cs.model, cs.data
    com = kinematics.center_of_mass(m, d, cs.q)
    vel = kinematics.com_jacobian(m, d, cs.q) @ (cs.v if v is None else v)
    g = max(abs(float(gravity[2])), 1e-6)
    point = com[:2] + vel[:2] * np.sqrt(max(com[2] - ground, 1e-3) / g)
    if inside(polygon, point):
        return 0.0, 0.0
    near = closest_boundary_point(polygon, point)
    return float(point[0] - near[0]), float(point[1] - near[1])


@dataclass
class FallCriterion:
    """Whether the figure falls: the time the ZMP has stayed out of reach, and the input's own
    capture-point excursion per frame (allowed: a walk's capture point runs ahead of its feet)."""

    ground: float
    gravity: tuple
    fall_time: float
    allow_capture: np.ndarray = None  # (F,) m, or None (no input allowance)
    unbalanced: float = 0.0  # s the ZMP has stayed outside what balance control can reach

    def capture_error(self, cs):
        """How far (m) the capture point lies outside the support polygon (0 inside)."""
        return math.hypot(*capture_offset(cs, self.ground, self.gravity))

    def can_stop(self, cs, frame):
        """Whether the figure can still stop over its feet: its capture point no further outside
        the support polygon than the input's own at that frame, plus CAPTURE_TOLERANCE."""
        allowed = (self.allow_capture[frame] if self.allow_capture is not None else 0.0) + CAPTURE_TOLERANCE
        return self.capture_error(cs) <= allowed

    def knocked_over(self, cs, frame, v):
        """After an instant impulse (velocities `v`): whether its momentum carries the capture point
        further outside the support polygon than the figure could stop from: CAPTURE_TOLERANCE,
        plus the input's own excursion when it stays on the side where the figure's capture point
        already was (a walk's runs ahead of its feet; a push the other way gets no such allowance)."""
        ax, ay = capture_offset(cs, self.ground, self.gravity, v)
        bx, by = capture_offset(cs, self.ground, self.gravity)
        own = self.allow_capture[frame] if self.allow_capture is not None and ax * bx + ay * by > 0.0 else 0.0
        return math.hypot(ax, ay) > own + CAPTURE_TOLERANCE

    def falls(self, unreachable, dt, cs, frame):
        """One step's verdict: `unreachable` (balance control reported a fall) for fall_time and the
        figure unable to stop over its feet."""
        self.unbalanced = self.unbalanced + dt if unreachable else 0.0
        return unreachable and self.unbalanced >= self.fall_time - 1e-9 and not self.can_stop(cs, frame)


def fall_steps(body, q, v, settings, dt_frame):
    """Steps in a frame of a fallen body: enough that no contact sphere travels more than
    FALL_STEP_TRAVEL in one (a body knocked over hits the ground fast: at 120 Hz, 4 steps a frame
    at 30 fps, a hand sank 4 cm), at most fall_rate a second, at least `substeps` a frame. A body
    lying on the ground, or coming to rest, needs no more steps than a standing one."""
    most = max(settings.substeps, math.ceil(settings.fall_rate * dt_frame - 1e-9))
    m, d = body.model, body.data
    kinematics.update_frames(m, d, q)
    bodies = body.spheres[0]
    centres = kinematics.body_points(d, bodies, body.sphere_hom)
    vel = kinematics.body_velocities(m, d, q, v).take(bodies, axis=0)
    speed = float(np.sqrt(((vel[:, 3:] + cross(vel[:, :3], centres)) ** 2).sum(axis=1).max()))
    return int(min(max(math.ceil(speed * dt_frame / FALL_STEP_TRAVEL), settings.substeps, 1), most))


def ragdoll_velocity(body, q, v, dt, f_ext, settings):
    """The fallen body's velocities after a step: no joint torques but damping (fall_damping times
    each DOF's H_ii) and the joint limits as stiff springs, both implicit:
    (H + dt D + dt^2 K) dv = dt (tau - bias)."""
    st, m, d = settings, body.model, body.data
    h = crba(m, d, q)
    hd = np.diag(h).copy()
    spring = limit_torques(m, q, np.zeros_like(v), st.limit_stiffness, 0.0)
    at_limit = spring != 0.0
    damp = st.fall_damping * hd + at_limit * (st.limit_damping + dt * st.limit_stiffness)
    damp[:6] = 0.0
    rhs = spring - bias_forces(m, d, q, v, f_ext=f_ext) - damp * v
    mat = h.copy()
    mat.flat[::m.nv + 1] += dt * damp
    out = v + dt * cho_solve(cho_factor(mat), rhs)
    # the velocity terms are explicit: a light segment spun fast (a toe, H_ii 2e-5 kg m^2) feeds
    # them quadratically and the fall diverged (numpy 2, a 40 N s push); no joint of a body turns
    # faster than RAGDOLL_JOINT_SPEED
    out[6:] = np.clip(out[6:], -RAGDOLL_JOINT_SPEED, RAGDOLL_JOINT_SPEED)
    return out
