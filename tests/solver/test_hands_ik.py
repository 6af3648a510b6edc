"""IK with a main and a secondary task (Huang 1996 eq. 2-1): the secondary task moves the chain
without disturbing the main task, joint limits hold, damped least squares stays finite at a
singularity, chains follow the body roles."""

from dataclasses import replace

import numpy as np
import pytest

from hands_cases import metarig
from humananim.solver.errors import RigError
from humananim.solver.hands import ik


@pytest.fixture(scope="module")
def rig():
    return metarig()


def test_chains_by_role(rig):
    sk, basis, a2w = rig
    arm = ik.chain_joints(sk, "R")
    assert [sk.names[j] for j in arm] == ["shoulder.R", "upper_arm.R", "forearm.R", "hand.R"]
    spine = ik.chain_joints(sk, "L", with_spine=True)
    names = [sk.names[j] for j in spine]
    assert names[0] == "spine.001" and "spine.003" in names and names[-1] == "hand.L"
    with pytest.raises(RigError):
        ik.chain_joints(replace(sk, roles=type(sk.roles)({})), "R")


def test_jacobian_matches_finite_differences(rig):
    sk, basis, a2w = rig
    ch = ik.Chain.arm(sk, "R", point=(0.01, 0.05, 0.0))
    base = ik.chain_base(ch, sk.world_frames(basis, a2w))
    th = ch.angles(basis) + 0.2
    world, axes = ch.frames(ch.euler(th, basis), basis, base)
    jac = ch.jacobian(world, axes)
    x0 = ch.effector(world)[0]
    for i in range(ch.n):
        d = np.zeros(ch.n)
        d[i] = 1e-6
        x1 = ch.effector(ch.frames(ch.euler(th + d, basis), basis, base)[0])[0]
        assert np.allclose((x1 - x0) / 1e-6, jac[3:, i], atol=1e-4)


def test_secondary_task_lies_in_the_null_space(rig):
    sk, basis, a2w = rig
    ch = ik.Chain.arm(sk, "R")
    base = ik.chain_base(ch, sk.world_frames(basis, a2w))
    th = ch.angles(basis)
    world, axes = ch.frames(ch.euler(th, basis), basis, base)
    jac = ch.jacobian(world, axes)
    dz = np.random.default_rng(1).normal(size=ch.n) * 0.05
    dq = ik.null_space_step(jac, np.zeros(6), dz)
    assert np.linalg.norm(dq) > 1e-3  # the chain moves ...
    assert np.linalg.norm(jac @ dq) < 1e-9  # ... and the hand does not (first order)


def test_solve_reaches_with_a_secondary_task(rig):
    sk, basis, a2w = rig
    ch = ik.Chain.arm(sk, "R")
    world = sk.world_frames(basis, a2w)
    base = ik.chain_base(ch, world)
    target = np.array([-0.3, -0.3, 1.2])
    rot = world[sk.role_index("hand.R")][:3, :3]
    free = ik.solve(ch, basis, base, target, rot)
    rest = ch.angles(basis)
    # secondary: stay near the rest posture (the animator's reference)
    pulled = ik.solve(ch, basis, base, target, rot, secondary=lambda th, w, a: 0.2 * (rest - th), iterations=120)
    assert free.position_error < 2e-4 and pulled.position_error < 2e-4
    assert pulled.rotation_error < np.radians(0.1)
    assert np.linalg.norm(pulled.theta - rest) < np.linalg.norm(free.theta - rest)


def test_joint_limits_hold(rig):
    sk, basis, a2w = rig
    limited = sk.limits.copy()
    fa = sk.role_index("forearm.R")
    limited[fa] = [[-0.3, 0.3]] * 3
    sk2 = replace(sk, limits=limited)
    ch = ik.Chain.arm(sk2, "R")
    res = ik.solve(ch, basis, ik.chain_base(ch, sk2.world_frames(basis, a2w)), np.array([-0.1, -0.35, 1.45]))
    eul = ch.euler(res.theta, basis)
    k = ch.joints.index(fa)
    assert np.all(np.abs(eul[k]) <= 0.3 + 1e-9)
    assert np.all(res.theta >= ch.lower - 1e-12) and np.all(res.theta <= ch.upper + 1e-12)


def test_damped_least_squares_at_a_singularity(rig):
    sk, basis, a2w = rig
    ch = ik.Chain.arm(sk, "R")
    world = sk.world_frames(basis, a2w)
    far = world[sk.role_index("upper_arm.R")][:3, 3] + np.array([-3.0, 0, 0])  # out of reach: arm stretched
    res = ik.solve(ch, basis, ik.chain_base(ch, world), far, iterations=100)
    assert np.all(np.isfinite(res.theta))
    jac = np.array([[1.0, 0.0], [0.0, 1e-9]])
    step = ik.null_space_step(jac, np.array([0.0, 1.0]))
    assert np.linalg.norm(step) < 50  # the undamped inverse would step 1e9


def test_update_world_is_forward_kinematics_of_the_moved_joints(rig):
    """A pose differing from a known one in a few joints (a root among them, frames batched):
    their subtrees recomputed level by level equal the whole body's forward kinematics."""
    sk, basis, a2w = rig
    rng = np.random.default_rng(0)
    moved = [0, 5, sk.role_index("hand.R")]
    poses = np.repeat(basis[None], 3, axis=0)
    for j in moved:
        poses[:, j, :3, :3] = ik.matrix_xyz(rng.normal(size=(3, 3)) * 0.3)
    expected = sk.world_frames(poses, a2w)
    out = ik.update_world(sk, poses, sk.world_frames(basis, a2w), moved, armature_to_world=a2w)
    assert np.abs(out - expected).max() < 1e-12
    with pytest.raises(ValueError):
        ik.update_world(sk, poses, sk.world_frames(basis, a2w), moved)


def test_normal_equation_step_equals_the_svd_step(rig):
    """null_space_step (normal equations, one Cholesky solve) and its batched form give the damped
    pseudo-inverse's step: undamped, near a singularity, with fewer DOFs than rows, with limits."""
    rng = np.random.default_rng(1)
    cases = [rng.normal(size=(6, 12)), rng.normal(size=(3, 5)), rng.normal(size=(6, 4))]
    near = np.outer(np.ones(6), np.linspace(0, 1, 12)) + 1e-4 * rng.normal(size=(6, 12))
    cases.append(near)
    for jac in cases:
        n = jac.shape[1]
        dx, dz = rng.normal(size=jac.shape[0]), rng.normal(size=n)
        jp = ik.damped_pinv(jac)
        expected = jp @ dx + dz - jp @ (jac @ dz)
        assert np.allclose(ik.null_space_step(jac, dx, dz), expected, atol=1e-10)
        assert np.allclose(ik.null_space_steps(jac[None], dx[None], dz[None])[0], expected, atol=1e-10)
        mask = np.arange(n) % 3 != 0
        jm = jac * mask
        jpm = ik.damped_pinv(jm)
        masked = (jpm @ dx + (np.eye(n) - jpm @ jm) @ (dz * mask)) * mask
        assert np.allclose(ik.null_space_step(jac, dx, dz, active=mask), masked, atol=1e-10)
