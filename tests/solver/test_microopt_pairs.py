"""benchmarks/microopt.py times each micro-optimisation beside its plain formula: the two versions
of every pair must compute the same thing (else the benchmark compares different work), and the
product code's version must be one of them. Nothing here looks at a time."""

import importlib.util
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from humananim.solver.cloth.dynamics import ParticleSum
from humananim.solver.hands import ik
from humananim.solver.motion_control import feet
from humananim.solver.motion_control.comfort_control import joint_stress, pinv

BENCHMARKS = Path(__file__).resolve().parents[2] / "benchmarks"


@pytest.fixture(scope="module")
def micro():
    spec = importlib.util.spec_from_file_location("benchmarks_microopt", BENCHMARKS / "microopt.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_every_trick_is_switched_where_the_product_code_holds_it(micro):
    for trick in micro.tricks():
        assert trick.targets, f"{trick.name}: no product code holds it"
        held = [getattr(owner, attr) for owner, attr in trick.targets]
        trick.use("plain")
        assert all(getattr(owner, attr) is trick.versions["plain"] for owner, attr in trick.targets)
        for (owner, attr), value in zip(trick.targets, held):
            setattr(owner, attr, value)


def test_pseudo_inverse_pair_cuts_the_same_singular_values(micro):
    rng = np.random.default_rng(1)
    a = rng.standard_normal((3, 8))
    a[2] = a[0] + 1e-9 * rng.standard_normal(8)  # nearly rank 2: the cut decides
    for rcond in (1e-6, 1e-12, 0.05):
        want = micro.pinv_trick(a, rcond)
        assert np.allclose(micro.pinv_plain(a, rcond), want, atol=1e-9)
        assert np.allclose(pinv(a, rcond), want, atol=1e-9)
    assert micro.pinv_plain(np.zeros((0, 4)), 1e-6).shape == (4, 0)


def test_joint_stress_pair_is_equal(micro):
    rng = np.random.default_rng(2)
    tau = rng.standard_normal(40) * 3
    limits = (-np.ones(40) - rng.random(40), np.ones(40) + rng.random(40))
    want = micro.joint_stress_trick(tau, limits, 0.1)
    assert np.array_equal(micro.joint_stress_plain(tau, limits, 0.1), want)
    assert np.array_equal(joint_stress(tau, limits, 0.1), want)


def test_planted_legs_pairs_give_the_same_step(micro):
    rng = np.random.default_rng(3)
    jac, r = rng.standard_normal((6, 7)), rng.standard_normal(6)
    jac[5] = jac[4] + 1e-3 * jac[3]  # near singular: the adaptive damping acts
    legs = SimpleNamespace(singular=(0.05 ** 2, 0.1 ** 2), eye6=1e-4 * np.eye(6), _dls_factors={})
    for damping in (micro.damping_trick, micro.damping_plain):
        assert np.allclose(damping(legs, jac @ jac.T), micro.damping_trick(legs, jac @ jac.T))
    legs.damping = lambda jj: micro.damping_plain(legs, jj)
    want = micro.dls_trick(legs, jac, r)
    legs._dls_factors = {}
    assert np.allclose(micro.dls_plain(legs, jac, r), want, atol=1e-10)
    legs._dls_factors = {}
    assert np.allclose(feet.PlantedFeet.dls(legs, jac, r), want, atol=1e-10)


@pytest.mark.parametrize("shape", [(6, 12), (3, 4), (6, 4), (6, 6)])
def test_ik_step_pair_is_the_same_step(micro, shape):
    rng = np.random.default_rng(4)
    jac, dx, dz = rng.standard_normal(shape), rng.standard_normal(shape[0]), rng.standard_normal(shape[1])
    jac[-1] = jac[0] * 1e-3  # a nearly singular row: damped
    active = (rng.random(shape[1]) > 0.2).astype(float)
    want = micro.null_space_step_trick(jac, dx, dz, active)
    assert np.allclose(micro.null_space_step_plain(jac, dx, dz, active), want, atol=1e-10)
    assert np.allclose(ik.null_space_step(jac, dx, dz, active), want, atol=1e-10)
    singular = np.zeros(shape)  # no damping can make it positive definite: the SVD fallback
    assert np.allclose(ik.null_space_step(singular, dx, dz), micro.null_space_step_trick(singular, dx, dz))


def test_cholesky_pair_solves_in_the_buffers(micro):
    rng = np.random.default_rng(5)
    m = rng.standard_normal((7, 7))
    spd = m @ m.T + 7 * np.eye(7)
    b0 = rng.standard_normal(7)
    outs = []
    for cls in (micro.CholeskyInPlace, micro.CholeskyPlain):
        A, b = spd.copy(), b0.copy()
        solver = cls(A, b)
        assert solver.solve()
        first = b.copy()
        b[:] = b0
        solver.resolve()
        outs.append((first, b.copy()))
        assert not cls(-np.eye(7), b0.copy()).solve()  # not positive definite
    want = np.linalg.solve(spd, b0)
    for first, again in outs:
        assert np.allclose(first, want) and np.allclose(again, want)


def test_particle_sum_pair_and_the_product_code_add_alike(micro):
    rng = np.random.default_rng(6)
    first, second = rng.integers(0, 10, 30), rng.integers(0, 10, 30)
    w0, w1 = rng.random(30), -rng.random(30)
    values = rng.standard_normal((30, 3))
    want = np.zeros((10, 3))
    np.add.at(want, first, w0[:, None] * values)
    np.add.at(want, second, w1[:, None] * values)
    for cls in (micro.SumPlanned, micro.SumAddAt, ParticleSum):
        out = np.full((10, 3), np.nan)
        assert np.allclose(cls(first, second, w0, w1, 10).into(values, out), want)


def test_dynamics_pairs_give_the_same_inverse_dynamics(micro):
    from humananim.solver.dynamics import build_model, integrate, oshita_figure, rnea
    from humananim.solver.dynamics.model import Data
    model = build_model(oshita_figure(), loads={"hand.L": 4.0})
    rng = np.random.default_rng(7)
    q = integrate(model, model.neutral(), 0.6 * rng.normal(size=model.nv))
    v, a = rng.normal(size=model.nv), rng.normal(size=model.nv)
    assert np.array_equal(micro.expand_plain(model, v), micro.expand_trick(model, v))
    assert np.array_equal(model.expand(v), micro.expand_trick(model, v))
    want = rnea(model, model.create_data(), q, v, a)
    for name in ("dynamics_expand_buffer", "dynamics_inertia_take", "dynamics_velocity_terms_dot",
                 "dynamics_subtree_wrenches_dot"):
        trick = next(t for t in micro.tricks() if t.name == name)
        held = [(owner, attr, getattr(owner, attr)) for owner, attr in trick.targets]
        try:
            for version in ("trick", "plain"):
                trick.use(version)
                assert np.allclose(rnea(model, model.create_data(), q, v, a), want, rtol=1e-12, atol=1e-9), \
                    (name, version)
        finally:
            for owner, attr, value in held:
                setattr(owner, attr, value)
    assert isinstance(Data.__dict__["inertia"], property)


def test_cloth_product_and_corner_sum_pairs_are_equal(micro):
    from scipy import sparse
    from humananim.solver.cloth.fast import CornerSum, Product, difference_matrix
    rng = np.random.default_rng(8)
    first, second = rng.integers(0, 12, 20), rng.integers(0, 12, 20)
    dense = rng.standard_normal((12, 3))
    matrix = difference_matrix(first, second, 12)
    assert np.array_equal(matrix @ dense, dense[second] - dense[first])
    want = sparse.csr_matrix(matrix) @ dense
    for cls in (micro.ProductKept, micro.ProductPlain, Product):
        product = cls(matrix, 3)
        assert np.array_equal(product(dense), want)
        out = np.full((20, 3), np.nan)
        assert np.array_equal(product.into(dense, out), want)
    faces = rng.integers(0, 9, (14, 3))
    values = rng.standard_normal((42, 3))
    want = np.zeros((9, 3))
    np.add.at(want, faces.ravel(), values)
    for cls in (micro.CornerSumBincount, micro.CornerSumAddAt, CornerSum):
        assert np.allclose(cls(faces, 9) @ values, want, rtol=0, atol=1e-12)


def test_control_pairs_bake_the_same_motion(micro):
    """Every Dynamic Control pair (its trick and its plain version) bakes the benchmark's loaded
    figure to the same stress and balance error (to rounding: the plain formulas may sum in
    another order)."""
    bake = micro.control_workload()[0]  # figure_15kg: comfort control acting
    want = bake()
    for trick in micro.tricks():
        if trick.capability != "control":
            continue
        held = [(owner, attr, getattr(owner, attr)) for owner, attr in trick.targets]
        try:
            for version in ("trick", "plain"):
                trick.use(version)
                got = bake()
                assert np.allclose(got.stress, want.stress, rtol=1e-6, atol=1e-6), (trick.name, version)
                assert np.allclose(got.balance_error, want.balance_error, atol=1e-9, equal_nan=True), (trick.name, version)
                assert np.array_equal(got.control, want.control), (trick.name, version)
        finally:
            for owner, attr, value in held:
                setattr(owner, attr, value)


def test_cross_pair_is_np_cross(micro):
    from humananim.solver.vectors import cross
    rng = np.random.default_rng(9)
    a, b = rng.standard_normal((7, 3)), rng.standard_normal(3)
    for fn in (micro.cross_trick, micro.cross_plain, cross):
        assert np.array_equal(fn(a, b), np.cross(a, b))
        assert np.array_equal(fn(b, a[:, None, :]), np.cross(b, a[:, None, :]))


def test_cloth_difference_pair_is_the_index_difference(micro):
    from humananim.solver.cloth.fast import IndexDifference
    rng = np.random.default_rng(10)
    first, second = rng.integers(0, 9, 20), rng.integers(0, 9, 20)
    second[second == first] = (first[second == first] + 1) % 9
    x = rng.standard_normal((9, 3))
    for cls in (micro.DifferenceProduct, IndexDifference):
        assert np.array_equal(cls(first, second)(x), x[second] - x[first])


def test_ground_wrenches_pair_is_equal_on_one_and_two_feet(micro):
    """The Dynamic Control bake above covers every control pair; the ground wrenches directly too,
    on the benchmark's loaded figure's steps."""
    cc = micro.comfort_control
    seen = []
    held = cc._ground_wrenches

    def spy(state, wrench):
        out = held(state, wrench)
        if out is not None and len(seen) < 40:
            plain = micro.ground_wrenches_plain(state, wrench)
            assert np.array_equal(plain[0], out[0])
            assert np.allclose(plain[1], out[1], rtol=1e-9, atol=1e-9)
            seen.append(len(out[0]))
        return out
    for owner, attr in micro._holders("_ground_wrenches", held):
        setattr(owner, attr, spy)
    try:
        micro.control_workload()[0]()
    finally:
        for owner, attr in micro._holders("_ground_wrenches", spy):
            setattr(owner, attr, held)
    assert seen


def test_length_pair_is_the_norm(micro):
    from humananim.solver.hands.sensors import length
    v = np.random.default_rng(11).standard_normal((5, 4, 3))
    for fn in (micro.length_trick, micro.length_plain, length):
        assert np.allclose(fn(v), np.linalg.norm(v, axis=-1), rtol=1e-15, atol=0)
