"""The planted legs' Jacobians (feet.PlantedFeet.leg_jacobians) against finite differences of the
forward kinematics, on the Oshita-like figure whose feet are two-axis (universal) joints: the
foot's angular velocity and head velocity are J v for any velocity, so the legs' inverse
kinematics see the foot's parent-side axis where Data.joint_motion puts it (it turns with the
shin, not with the foot)."""

import numpy as np
import pytest

from humananim.solver.dynamics import kinematics, oshita_figure
from humananim.solver.motion_control import ControlSettings
from humananim.solver.motion_control.controller import ControlLoop
from humananim.solver.motion_control.vector_math import rotation_log
from humananim.solver.trajectories import Trajectories


def standing(sk, n=5, fps=30.0):
    rot = np.zeros((n, sk.joint_count, 4))
    rot[..., 0] = 1.0
    return Trajectories(np.arange(n) + 1.0, fps, rot, np.zeros((n, sk.joint_count, 3)), np.eye(4))


@pytest.fixture(scope="module")
def loop():
    sk = oshita_figure()
    return ControlLoop(sk, standing(sk), ControlSettings())


def foot_frames(body, q):
    d = body.model.create_data()
    kinematics.update_frames(body.model, d, q)
    return [d.frames[b] @ off for b, off in zip(body.foot_body, body.foot_offset)]


def test_the_feet_are_two_axis_joints(loop):
    m = loop.body.model
    for b in loop.body.foot_body:
        assert m.free[b].sum() == 2


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_leg_jacobians_match_finite_differences(loop, seed):
    body, m = loop.body, loop.body.model
    rng = np.random.default_rng(seed)
    q = loop.tracking.q_d[0].copy()
    # every joint turned well away from rest (a two-axis foot's parent-side axis then differs
    # from the bone's own frame's)
    q = kinematics.integrate(m, q, np.r_[np.zeros(6), rng.normal(0.0, 0.5, m.nv - 6)])
    v = rng.normal(0.0, 1.0, m.nv)
    legs = loop.feet.leg_jacobians(body, q, np.array([True, True]))
    eps = 1e-6
    before = foot_frames(body, q)
    after_plus = foot_frames(body, kinematics.integrate(m, q, v * eps))
    after_minus = foot_frames(body, kinematics.integrate(m, q, -v * eps))
    for s in (0, 1):
        leg = legs[s]
        rate = leg.full @ v[leg.dofs]
        omega = (rotation_log(after_plus[s][:3, :3] @ before[s][:3, :3].T)
                 - rotation_log(after_minus[s][:3, :3] @ before[s][:3, :3].T)) / (2 * eps)
        head = (after_plus[s][:3, 3] - after_minus[s][:3, 3]) / (2 * eps)
        assert np.allclose(rate[:3], omega, atol=1e-6), (rate[:3], omega)
        assert np.allclose(rate[3:], head, atol=1e-6), (rate[3:], head)
        # the leg's own columns are the Jacobian's columns of those DOFs
        assert np.array_equal(leg.leg, leg.full[:, np.searchsorted(leg.dofs, leg.cols)])
