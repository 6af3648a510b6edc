"""Exactness of the rigid-body algorithms: RNEA, CRBA, ABA and their consistency."""

import numpy as np
import pytest

from humananim.solver.body_roles import RoleMap
from humananim.solver.dynamics import (aba, bias_forces, build_model, crba, external_forces,
                                       external_wrenches, forward_dynamics_dense, gravity_forces,
                                       inertia_block, integrate, oshita_figure, point_jacobian, rnea)
from humananim.solver.dynamics.kinematics import body_jacobian, com_jacobian
from humananim.solver.skeleton import Skeleton


def random_state(model, seed, spread=0.6):
    rng = np.random.default_rng(seed)
    q = integrate(model, model.neutral(), spread * rng.normal(size=model.nv))
    return q, rng.normal(size=model.nv), rng.normal(size=model.nv), rng


def awkward_skeleton():
    """The figure plus what real rigs contain: a parent bone above the root, a separate root tree,
    a welded massive bone, a massless leaf with free axes and a massless welded chain."""
    fig = oshita_figure()
    extra = [  # name, parent name, dof, mass
        ("hand_prop", "forearm.R", (False, False, False), 0.8),
        ("finger_helper", "hand.L", (True, True, True), 0.0),
        ("finger_tip", "finger_helper", (True, False, False), 0.0),
        ("twist", "upper_arm.L", (False, False, False), 0.0),
    ]
    names = ["root_ctrl"] + list(fig.names) + [e[0] for e in extra] + ["ik_target"]
    idx = {n: i for i, n in enumerate(names)}
    J = len(names)
    parents = np.full(J, -1)
    parents[1:1 + fig.joint_count] = np.where(fig.parents >= 0, fig.parents + 1, 0)
    for e in extra:
        parents[idx[e[0]]] = idx[e[1]]
    rest = np.broadcast_to(np.eye(4), (J, 4, 4)).copy()
    rest[1:1 + fig.joint_count] = fig.rest
    for e in extra:
        rest[idx[e[0]]] = rest[idx[e[1]]].copy()
        rest[idx[e[0]], :3, 3] += rest[idx[e[1]], :3, 1] * 0.05  # 5 cm down the parent bone
    dof = np.zeros((J, 3), bool)
    dof[1:1 + fig.joint_count] = fig.dof
    dof[0] = dof[-1] = True
    mass = np.zeros(J)
    mass[1:1 + fig.joint_count] = fig.mass
    com = np.zeros((J, 3))
    com[1:1 + fig.joint_count] = fig.com
    inertia = np.zeros((J, 3, 3))
    inertia[1:1 + fig.joint_count] = fig.inertia
    for e in extra:
        dof[idx[e[0]]] = e[2]
        mass[idx[e[0]]] = e[3]
        if e[3]:
            com[idx[e[0]]] = (0.0, 0.05, 0.0)
            inertia[idx[e[0]]] = np.eye(3) * 1e-3
    mass[0] = mass[-1] = 5.0  # outside the body: must be ignored
    limits = np.zeros((J, 3, 2))
    limits[..., 0], limits[..., 1] = -np.inf, np.inf
    return Skeleton(names=names, parents=parents, rest=rest, lengths=np.full(J, 0.1),
                    connected=np.zeros(J, bool), dof=dof, limits=limits, mass=mass, com=com,
                    inertia=inertia, roles=RoleMap({"pelvis": ("pelvis",)}))


@pytest.fixture(scope="module", params=["figure", "awkward", "loaded"])
def model(request):
    if request.param == "figure":
        return build_model(oshita_figure())
    if request.param == "awkward":
        return build_model(awkward_skeleton())
    return build_model(oshita_figure(), loads={"hand.L": 12.0, "hand.R": 3.0}, armature=0.01)


def test_figure_model_counts():
    m = build_model(oshita_figure())
    assert m.nb == 18 and m.nv == 6 + 39 and m.nq == 3 + 4 * 18
    assert m.mass.sum() == pytest.approx(72.0)


def test_awkward_rig_merges_and_excludes():
    sk = awkward_skeleton()
    m = build_model(sk)
    kinds = dict(zip(sk.names, m.joint_kind))
    assert kinds["root_ctrl"] == "outside" and kinds["ik_target"] == "outside"
    assert kinds["hand_prop"] == "welded" and kinds["twist"] == "welded"
    assert kinds["finger_helper"] == "kinematic" and kinds["finger_tip"] == "kinematic"
    assert m.nb == 18 and m.nv == 45
    assert m.mass.sum() == pytest.approx(72.8)  # the prop counts, bones outside do not
    assert m.joint_body[sk.index("hand_prop")] == m.joint_body[sk.index("forearm.R")]


def test_loads_add_mass_to_hands():
    m = build_model(oshita_figure(), loads={"hand.L": 10.0})
    assert m.mass.sum() == pytest.approx(82.0)


@pytest.mark.parametrize("seed", range(3))
def test_aba_inverts_rnea(model, seed):
    """Forward dynamics of the torques from inverse dynamics returns the accelerations."""
    d = model.create_data()
    q, v, a, rng = random_state(model, seed)
    f_ext = rng.normal(size=(model.nb, 6)) * 20.0
    tau = rnea(model, d, q, v, a, f_ext=f_ext)
    np.testing.assert_allclose(aba(model, d, q, v, tau, f_ext=f_ext), a, atol=1e-8)
    np.testing.assert_allclose(forward_dynamics_dense(model, d, q, v, tau, f_ext=f_ext), a, atol=1e-8)


@pytest.mark.parametrize("seed", range(3))
def test_inertia_matrix_spd_and_jacobian_form(model, seed):
    d = model.create_data()
    q, v, a, _ = random_state(model, seed)
    h = crba(model, d, q)
    np.testing.assert_allclose(h, h.T, atol=1e-12)
    assert np.linalg.eigvalsh(h).min() > 0.0
    # H = sum over bodies of J_b' I_b J_b with world spatial Jacobians and inertias
    ref = sum(body_jacobian(model, d, q, b).T @ d.inertia[b] @ body_jacobian(model, d, q, b)
              for b in range(model.nb))
    ref[np.diag_indices_from(ref)] += model.armature_v
    np.testing.assert_allclose(h, ref, atol=1e-10)
    np.testing.assert_allclose(h @ a + bias_forces(model, d, q, v), rnea(model, d, q, v, a), atol=1e-9)


def test_inertia_blocks_and_columns(model):
    d = model.create_data()
    q, _, _, _ = random_state(model, 7)
    h = crba(model, d, q)
    np.testing.assert_allclose(inertia_block(model, d, q, slice(None), [9]), h[:, [9]], atol=1e-12)
    rows, cols = [0, 5, 17, 30], [2, 9, 17, 44]
    np.testing.assert_allclose(inertia_block(model, d, q, rows, cols), h[np.ix_(rows, cols)], atol=1e-12)


def test_coriolis_against_inertia_derivative():
    """v' C(q, v) = v' Hdot v / 2 (the skew symmetry of Hdot - 2C), with Hdot by differences."""
    m = build_model(oshita_figure())
    d = m.create_data()
    q, v, _, _ = random_state(m, 3)
    c = rnea(m, d, q, v, np.zeros(m.nv), gravity=np.zeros(3))
    eps = 1e-6
    hdot = (crba(m, d, integrate(m, q, v * eps)) - crba(m, d, integrate(m, q, -v * eps))) / (2 * eps)
    assert v @ c == pytest.approx(0.5 * v @ hdot @ v, rel=1e-6)


def test_gravity_and_external_terms():
    m = build_model(oshita_figure())
    d = m.create_data()
    q, _, _, rng = random_state(m, 4)
    g = gravity_forces(m, d, q)
    np.testing.assert_allclose(g, -m.mass.sum() * com_jacobian(m, d, q).T @ m.gravity, atol=1e-9)
    joint = m.skeleton.index("hand.L")
    point, force = np.array([0.01, 0.12, 0.02]), rng.normal(size=3) * 50
    w = external_wrenches(m, d, q, [joint], [point], [force])
    np.testing.assert_allclose(external_forces(m, d, q, w), -point_jacobian(m, d, q, joint, point).T @ force,
                               atol=1e-9)
    zero = np.zeros(m.nv)
    np.testing.assert_allclose(bias_forces(m, d, q, zero, f_ext=w),
                               g + external_forces(m, d, q, w), atol=1e-9)
