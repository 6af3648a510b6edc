"""Analytic 7-DOF limb IK (motion_control.limb_ik) on the real-rig fixtures.

The fixtures' rest frames come from Blender in single precision: rigid only to ~1e-7, so FK of the
IK solution matched the source to 1.3e-6 m only. The tests re-orthonormalise them (rigid()); then
round trips are exact to 1.3e-15 m."""

from dataclasses import replace

import numpy as np
import pytest

from humananim.solver import rotations
from humananim.solver.motion_control import LimbIK
from humananim.solver.trajectories import Trajectories

from test_dynamics_closed_loop_rigs import load


def rigid(m):
    m = np.array(m, float)
    m[..., :3, :3] = rotations.to_matrix(rotations.from_matrix(m[..., :3, :3]))
    return m


@pytest.fixture(scope="module", params=["metarig_legs", "cmu_131_01"])
def rig(request):
    sk, tr = load(request.param)
    sk = replace(sk, rest=rigid(sk.rest))
    tr = Trajectories(tr.frames, tr.fps, tr.rotations, tr.translations, rigid(tr.armature_to_world))
    return sk, tr


@pytest.mark.parametrize("limb", ["leg", "arm"])
def test_ik_of_fk_round_trips(rig, limb):
    """The 7-DOF limb (end effector's position and orientation, and the swivel angle) solved back
    from its own forward kinematics, legs and arms: the end frame and the middle joint exact."""
    sk, tr = rig
    basis, world = tr.basis(), tr.world_frames(sk)
    for side in "LR":
        for f in range(0, tr.frame_count, 11):
            ik = LimbIK(sk, side, limb, basis=basis[f])
            w = world[f]
            q, _, reached = ik.solve(ik.parent_frame(w), w[ik.end], ik.swivel(w))
            assert reached
            w2, _ = ik.pose(basis[f], q, tr.armature_to_world)
            assert np.abs(w2[ik.end] - w[ik.end]).max() < 1e-9  # foot or hand frame
            assert np.abs(w2[ik.lower, :3, 3] - w[ik.lower, :3, 3]).max() < 1e-9  # knee or elbow
            assert ik.swivel(w2) == pytest.approx(ik.swivel(w), abs=1e-9)


def moved_pelvis(sk, tr, f, offset, turn):
    basis = tr.basis()[f].copy()
    r = sk.root
    # the offset is world (down lowers the pelvis, so the planted foot stays reachable)
    to_bone = (tr.armature_to_world[:3, :3] @ sk.rest_local[r][:3, :3]).T
    basis[r, :3, 3] += to_bone @ np.asarray(offset, float)
    basis[r, :3, :3] = basis[r, :3, :3] @ rotations.to_matrix(rotations.from_axis_angle(np.r_[turn, 0.0, 0.0, 1.0]))
    return basis


def test_planted_foot_stays_while_the_pelvis_moves(rig):
    sk, tr = rig
    f = 0
    basis = tr.basis()[f]
    w = tr.world_frames(sk)[f]
    ik = LimbIK(sk, "L", basis=basis)
    foot, s = w[ik.end].copy(), ik.swivel(w)
    for offset, turn in (((0.02, -0.03, -0.05), 0.1), ((-0.04, 0.02, -0.1), -0.2), ((0.0, 0.0, -0.02), 0.0)):
        b = moved_pelvis(sk, tr, f, offset, turn)
        wb = sk.world_frames(b, tr.armature_to_world)
        q, _, reached = ik.solve(ik.parent_frame(wb), foot, s)
        assert reached
        w2, _ = ik.pose(b, q, tr.armature_to_world)
        assert np.abs(w2[ik.end] - foot).max() < 1e-9


def test_swivel_moves_the_knee_on_its_circle(rig):
    sk, tr = rig
    basis, w = tr.basis()[30], tr.world_frames(sk)[30]
    ik = LimbIK(sk, "R", basis=basis)
    parent, foot, s = ik.parent_frame(w), w[ik.end], ik.swivel(w)
    hip = w[ik.upper, :3, 3]
    axis = (foot[:3, 3] - hip) / np.linalg.norm(foot[:3, 3] - hip)
    knees = []
    for ds in np.linspace(-0.6, 0.6, 5):
        q, _, _ = ik.solve(parent, foot, s + ds)
        w2, _ = ik.pose(basis, q, tr.armature_to_world)
        knees.append(w2[ik.lower, :3, 3])
        assert np.abs(w2[ik.end] - foot).max() < 1e-9
        assert ik.swivel(w2) == pytest.approx(s + ds, abs=1e-9)
    rel = np.array(knees) - hip
    along = rel @ axis
    radius = np.linalg.norm(rel - along[:, None] * axis, axis=1)
    assert np.ptp(along) < 1e-9 and np.ptp(radius) < 1e-9 and radius[0] > 1e-3
    assert np.linalg.norm(knees[0] - knees[-1]) > 0.5 * radius[0]


def test_unreachable_target_straightens_the_limb(rig):
    sk, tr = rig
    basis, w = tr.basis()[0], tr.world_frames(sk)[0]
    ik = LimbIK(sk, "L", basis=basis)
    foot = w[ik.end].copy()
    hip = w[ik.upper, :3, 3]
    foot[:3, 3] = hip + 3.0 * (foot[:3, 3] - hip)
    q, phi, reached = ik.solve(ik.parent_frame(w), foot, ik.swivel(w))
    assert not reached and np.all(np.isfinite(q))
    w2, _ = ik.pose(basis, q, tr.armature_to_world)
    reach = np.linalg.norm(w2[ik.end, :3, 3] - hip)
    d = (foot[:3, 3] - hip) / np.linalg.norm(foot[:3, 3] - hip)
    assert np.allclose((w2[ik.end, :3, 3] - hip) / reach, d, atol=1e-9)  # pointing at the target
    assert np.allclose(w2[ik.end, :3, :3], foot[:3, :3], atol=1e-9)  # orientation still met
    near = foot.copy()
    near[:3, 3] = hip + 1e-3 * d  # closer than the folded limb can reach
    q, _, reached = ik.solve(ik.parent_frame(w), near, ik.swivel(w))
    assert not reached and np.all(np.isfinite(q))


@pytest.mark.parametrize("limb", ["leg", "arm"])
def test_acceleration_form_matches_finite_differences(rig, limb):
    sk, tr = rig
    basis, w = tr.basis()[20], tr.world_frames(sk)[20]
    ik = LimbIK(sk, "L", limb, basis=basis)
    if limb == "arm":  # hanging arms are straight (singular): bend the elbow, the hand halfway in
        hand = w[ik.end].copy()
        hand[:3, 3] = 0.5 * (hand[:3, 3] + w[ik.upper][:3, 3])
        q, _, reached = ik.solve(ik.parent_frame(w), hand, ik.swivel(w))
        assert reached
        w, _ = ik.pose(basis, q, tr.armature_to_world)
    parent, foot, s = ik.parent_frame(w), w[ik.end], ik.swivel(w)
    pr = (np.array([0.3, -0.2, 0.1]), np.array([0.5, 0.2, -1.0]), np.array([1.0, 2.0, -3.0]), np.array([4.0, -2.0, 1.0]))
    er = (np.array([0.1, 0.4, 0.0]), np.array([-0.3, 0.6, 0.2]), np.array([-2.0, 0.5, 1.0]), np.array([1.0, 3.0, -2.0]))
    sr = (0.7, -3.0)
    vel, acc = ik.rates(parent, foot, s, pr, er, sr)
    # an independent check: the local angular velocity of the IK solution along the path, by
    # differences of the body velocity between t = -dt and dt (larger step, second order)
    from humananim.solver.motion_control.limb_ik import _advance
    from humananim.solver.dynamics import spatial

    def q_at(t):
        return ik.solve(_advance(parent, pr, t), _advance(foot, er, t), s + sr[0] * t + 0.5 * sr[1] * t * t)[0]

    def omega(t, d=1e-5):
        a, b = q_at(t - d), q_at(t + d)
        return spatial.quat_log(spatial.quat_multiply(spatial.quat_conjugate(a), b)) / (2 * d)

    dt = 1e-3
    # (LimbIK.rates is central differences of the analytic solution, O(h^2) with h = 1e-3: the bent
    # arm's larger third derivatives leave up to ~5e-4 of its largest rate, measured)
    exact = omega(0.0)
    np.testing.assert_allclose(vel, exact, atol=1e-5 if limb == "leg" else 1e-3 * max(1.0, np.abs(exact).max()))
    np.testing.assert_allclose(acc, (omega(dt) - omega(-dt)) / (2 * dt), atol=2e-3 * max(1.0, np.abs(acc).max()))
    assert np.abs(acc).max() > 1.0  # not trivially zero
    # the knee (elbow) turns about its hinge only
    assert np.linalg.norm(np.cross(vel[1], ik.hinge)) < 1e-6 * max(1.0, np.linalg.norm(vel[1]))
