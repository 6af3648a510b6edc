"""Forward kinematics, Jacobians (by finite differences) and conservation laws of passive motion."""

import numpy as np
import pytest

from humananim.solver import rotations
from humananim.solver.dynamics import (build_model, center_of_mass, com_jacobian, difference,
                                       integrate, joint_frames, oshita_figure, point_accelerations,
                                       point_jacobian, point_positions, point_velocities, rk4_step,
                                       segment_jacobian)
from humananim.solver.dynamics.kinematics import kinetic_energy, spatial_momentum


@pytest.fixture(scope="module")
def fig():
    m = build_model(oshita_figure())
    return m, m.create_data()


def state(m, seed):
    rng = np.random.default_rng(seed)
    q = integrate(m, m.neutral(), 0.7 * rng.normal(size=m.nv))
    return q, rng.normal(size=m.nv), rng.normal(size=m.nv)


def test_neutral_pose_matches_skeleton_rest(fig):
    m, d = fig
    np.testing.assert_allclose(joint_frames(m, d, m.neutral()), m.skeleton.rest, atol=1e-12)


def test_frames_match_skeleton_world_frames(fig):
    """The model's frames equal the lead's Skeleton.world_frames for the same local rotations
    (two-axis joints at rotations they can reach, R_i(a) R_k(b) with i, k their free axes)."""
    m, d = fig
    sk = m.skeleton
    rng = np.random.default_rng(1)
    local = rotations.normalize(rng.normal(size=(sk.joint_count, 4)))
    for j in np.flatnonzero(sk.dof.sum(axis=1) == 2):
        i, k = np.flatnonzero(sk.dof[j])
        local[j] = rotations.multiply(rotations.axis_rotation(i, rng.uniform(-1.5, 1.5)),
                                      rotations.axis_rotation(k, rng.uniform(-1.5, 1.5)))
    basis = np.broadcast_to(np.eye(4), (sk.joint_count, 4, 4)).copy()
    basis[:, :3, :3] = rotations.to_matrix(local)
    basis[sk.root, :3, 3] = (0.3, -0.2, 0.1)
    ref = sk.world_frames(basis)
    q = m.configuration(ref[sk.root, :3, 3], rotations.from_matrix(ref[sk.root, :3, :3]), local)
    np.testing.assert_allclose(joint_frames(m, d, q), ref, atol=1e-12)


def test_integrate_and_difference_are_inverse(fig):
    m, _ = fig
    q, v, _ = state(m, 2)
    np.testing.assert_allclose(difference(m, q, integrate(m, q, 0.3 * v)), 0.3 * v, atol=1e-10)


@pytest.mark.parametrize("seed", range(3))
def test_point_and_segment_jacobians_by_finite_differences(fig, seed):
    m, d = fig
    q, v, _ = state(m, seed)
    eps = 1e-6
    qp, qm = integrate(m, q, v * eps), integrate(m, q, -v * eps)
    for name, point in (("hand.L", (0.01, 0.1, -0.02)), ("foot.R", (0.0, 0.05, 0.03)), ("head", (0, 0.2, 0)),
                        ("pelvis", (0.1, 0.0, 0.0))):
        j = m.skeleton.index(name)
        num = (point_positions(m, d, qp, [j], [point]) - point_positions(m, d, qm, [j], [point]))[0]
        num /= 2 * eps
        np.testing.assert_allclose(point_jacobian(m, d, q, j, point) @ v, num, atol=1e-7)
        np.testing.assert_allclose(point_velocities(m, d, q, v, [j], [point])[0], num, atol=1e-7)
        fp, fm, f0 = (joint_frames(m, d, x)[j] for x in (qp, qm, q))
        w_hat = (fp[:3, :3] - fm[:3, :3]) / (2 * eps) @ f0[:3, :3].T
        seg = segment_jacobian(m, d, q, j) @ v
        np.testing.assert_allclose(seg[:3], [w_hat[2, 1], w_hat[0, 2], w_hat[1, 0]], atol=1e-7)
        np.testing.assert_allclose(seg[3:], (fp[:3, 3] - fm[:3, 3]) / (2 * eps), atol=1e-7)


def test_com_jacobian_by_finite_differences(fig):
    m, d = fig
    q, v, _ = state(m, 5)
    eps = 1e-6
    ahead, behind = integrate(m, q, v * eps), integrate(m, q, -v * eps)
    num = (center_of_mass(m, d, ahead) - center_of_mass(m, d, behind)) / (2 * eps)
    np.testing.assert_allclose(com_jacobian(m, d, q) @ v, num, atol=1e-8)


@pytest.mark.parametrize("seed", range(2))
def test_point_acceleration_by_finite_differences(fig, seed):
    """Along q(t) = q (+) (v t + b t^2 / 2), whose model acceleration is a (for the root's linear
    entries b = a + w x v, because they are velocities in the turning root axes)."""
    m, d = fig
    q, v, a = state(m, seed)
    b = a.copy()
    b[3:6] += np.cross(v[:3], v[3:6])
    h = 1e-4
    j = m.skeleton.index("hand.R")
    point = [(0.02, 0.1, 0.0)]
    x = [point_positions(m, d, integrate(m, q, v * t + 0.5 * b * t * t), [j], point)[0] for t in (-h, 0.0, h)]
    num = (x[2] - 2 * x[1] + x[0]) / h ** 2
    np.testing.assert_allclose(point_accelerations(m, d, q, v, a, [j], point)[0], num, atol=2e-5)


def test_passive_body_conserves_energy_and_momentum(fig):
    """Free floating, no gravity, no damping: 2 s of tumbling keep energy and spatial momentum."""
    m, d = fig
    q, v, _ = state(m, 11)
    zero, g0 = np.zeros(m.nv), np.zeros(3)
    e0, h0 = kinetic_energy(m, d, q, v), spatial_momentum(m, d, q, v)
    for _ in range(800):
        q, v = rk4_step(m, d, q, v, zero, 2.5e-3, gravity=g0)
    assert kinetic_energy(m, d, q, v) == pytest.approx(e0, rel=1e-6)
    np.testing.assert_allclose(spatial_momentum(m, d, q, v), h0, atol=1e-6 * np.abs(h0).max())
    assert np.abs(v).max() > 0.5  # it really moved
