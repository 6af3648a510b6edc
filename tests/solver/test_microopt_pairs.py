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
        assert all(getattr(owner, attr) is trick.version("plain", attr) for owner, attr in trick.targets)
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


def test_balance_pair_tests_and_projects_alike_on_polygons(micro):
    """The ZMP test and the MMP on floats and on arrays: inside, on the boundary, outside beside
    an edge and beyond a vertex, on a hull of real-looking sole points and on degenerate ones."""
    from humananim.solver.dynamics.balance import closest_boundary_point, convex_hull, inside
    rng = np.random.default_rng(12)
    soles = np.r_[rng.normal((0.1, 0.0), (0.05, 0.03), (6, 2)), rng.normal((-0.1, 0.05), (0.05, 0.03), (6, 2))]
    polygons = [convex_hull(soles), np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]),
                np.array([[0.0, 0.0], [2.0, 0.0]]), np.array([[1.0, 1.0]])]
    for polygon in polygons:
        points = np.r_[rng.uniform(polygon.min(axis=0) - 0.3, polygon.max(axis=0) + 0.3, (200, 2)),
                       polygon, 0.5 * (polygon + np.roll(polygon, 1, axis=0))]  # vertices, edge midpoints
        for point in points:
            want_in = micro.inside_floats(polygon, point)
            want_mmp = micro.closest_boundary_point_floats(polygon, point)
            assert micro.inside_plain(polygon, point) == want_in == inside(polygon, point), (polygon, point)
            for fn in (micro.closest_boundary_point_plain, closest_boundary_point):
                assert np.allclose(fn(polygon, point), want_mmp, rtol=0, atol=1e-12), (polygon, point)
    square = polygons[1]
    assert micro.inside_plain(square, (1.0, 0.5)) and not micro.inside_plain(square, (1.0 + 1e-6, 0.5))
    assert np.allclose(micro.closest_boundary_point_plain(square, (2.0, 3.0)), (1.0, 1.0))
    assert np.allclose(micro.closest_boundary_point_plain(square, (0.5, -2.0)), (0.5, 0.0))


def test_balance_error_pair_is_equal_on_the_bakes_steps(micro):
    """_balance_error on floats and on arrays: the same ZMP, MMP and distance on the benchmark's
    loaded figure's and CMU walk's steps (the walk leaves its support polygon: the MMP acts)."""
    bc = micro.balance_control
    held = bc._balance_error
    seen = {"inside": 0, "outside": 0}

    def spy(state, wrench, polygon):
        out = held(state, wrench, polygon)
        for fn in (micro.balance_error_floats, micro.balance_error_plain):
            got = fn(state, wrench, polygon)
            if out[1] is None:
                assert got == (None, None, 0.0)
                continue
            assert np.array_equal(got[0], out[0])
            assert np.allclose(got[1], out[1], rtol=0, atol=1e-12)
            assert abs(got[2] - out[2]) <= 1e-12
        if out[1] is not None:
            seen["inside" if out[2] == 0.0 else "outside"] += 1
        return out
    for owner, attr in micro._holders("_balance_error", held):
        setattr(owner, attr, spy)
    try:
        for bake in micro.control_workload():
            bake()
    finally:
        for owner, attr in micro._holders("_balance_error", spy):
            setattr(owner, attr, held)
    assert seen["inside"] > 50 and seen["outside"] > 5, seen


def test_pgs_pair_gives_the_same_impulses_on_the_bakes_contacts(micro):
    """Projected Gauss-Seidel row by row and by contact blocks: the same impulses (to the sweeps'
    convergence) on the contact systems of a fallen body and of a fist, from the benchmark's
    contacts workload; the normal impulses never pull, friction stays within mu times them."""
    col = micro.collisions
    held = col.pgs
    seen = []

    def spy(w, rel, targets, mu, iterations):
        out = held(w, rel, targets, mu, iterations)
        if len(seen) < 60 or len(targets) > 20:
            for fn in (micro.pgs_blocks, micro.pgs_plain, micro.pgs_blocks_calls):
                got = fn(w, rel, targets, mu, iterations)
                assert np.allclose(got, out, rtol=1e-6, atol=1e-6 * max(1.0, np.abs(out).max()))
                normal, friction = got[0::3], got.reshape(-1, 3)[:, 1:]
                assert normal.min() >= 0.0 and np.all(np.abs(friction) <= mu * normal[:, None] + 1e-12)
            seen.append(len(targets))
        return out
    for owner, attr in micro._holders("pgs", held):
        setattr(owner, attr, spy)
    try:
        for bake in micro.contacts_workload():
            bake()
    finally:
        for owner, attr in micro._holders("pgs", spy):
            setattr(owner, attr, held)
    assert len(seen) > 60 and max(seen) > 20, (len(seen), max(seen))


def test_pgs_pair_on_a_small_system_meets_the_targets(micro):
    """Two contacts, one sliding: the normal speeds reach their targets, the sliding one's friction
    sits on its cone's box edge, and both versions agree."""
    rng = np.random.default_rng(13)
    jac = rng.standard_normal((6, 9))
    w = jac @ jac.T + 0.1 * np.eye(6)
    rel = np.array([-1.0, 3.0, 0.0, -0.5, 0.01, 0.0])
    targets = np.array([0.2, 0.0])
    for fn in (micro.pgs_blocks, micro.pgs_plain):
        p = fn(w, rel, targets, 0.3, 200)
        speed = rel + w @ p
        assert np.all(p[0::3] > 0) and np.allclose(speed[0::3], targets, atol=1e-5)
        assert abs(abs(p[1]) - 0.3 * p[0]) < 1e-9  # sliding: friction at its bound
    assert np.allclose(micro.pgs_plain(w, rel, targets, 0.3, 200), micro.pgs_blocks(w, rel, targets, 0.3, 200),
                       atol=1e-6)


def test_text_pair_fails_loudly_unless_each_expression_occurs_once(micro):
    """text_pair / rewritten build the other version of an inline trick by replacing one
    expression: an expression missing, twice in the source, or the two versions mixed is an error
    naming the function, never a silently unchanged or doubly changed copy."""
    def twice(x):
        return (x * x).sum(axis=1) + (x * x).sum(axis=1)

    def once(x):
        y = np.abs(x).max()
        return y + x.sum()

    x = np.arange(6.0).reshape(2, 3)
    with pytest.raises(LookupError, match=r"twice.*occurs 2 times"):
        micro.text_pair(twice, ("(x * x).dot(ONES3)", "(x * x).sum(axis=1)"), names={"ONES3": np.ones(3)})
    with pytest.raises(LookupError, match=r"once.*neither"):
        micro.text_pair(once, ("np.maximum.reduce(np.abs(x))", "np.abs(x).min()"))
    with pytest.raises(LookupError, match=r"once.*neither"):  # one replacement found, the other not
        micro.text_pair(once, ("np.maximum.reduce(np.abs(x))", "np.abs(x).max()"), ("x.cumsum()", "x.prod()"))
    with pytest.raises(LookupError, match=r"once.*occurs 0 times"):
        micro.rewritten(once, ("x.prod()", "x.sum()"))
    trick, plain = micro.text_pair(once, ("np.maximum.reduce(np.abs(x), None)", "np.abs(x).max()"))
    assert plain is once and trick is not once and trick(x) == once(x) == 20.0


def test_a_partial_run_is_merged_into_the_committed_rows_by_name(micro):
    """--json with --only: the tricks measured get this run's rows, the others keep theirs, rows
    in the tricks' order, each run listing the tricks it measured (a run left with none dropped)."""
    def row(name, ratio):
        return {"trick": name, "capability": "control", "plain_formula": "x", "ratio_trick_over_plain": ratio,
                "ratio_min": ratio, "ratio_max": ratio, "rounds": 5, "worth_keeping": ratio <= 0.95}
    previous = {"tricks": [row("a", 1.0), row("b", 0.9), row("gone", 1.0)],
                "runs": [{"tricks": ["a", "gone"], "date": "old"}, {"tricks": ["b"], "date": "older"}]}
    out = micro.merged([row("b", 0.97), row("c", 0.8)], previous, ["a", "b", "c"])
    assert [r["trick"] for r in out["tricks"]] == ["a", "b", "c"]
    assert [r["ratio_trick_over_plain"] for r in out["tricks"]] == [1.0, 0.97, 0.8]
    assert [c["met"] for c in out["claims"]] == [False, False, True] and len(out["claims"]) == 3
    assert [r["tricks"] for r in out["runs"]] == [["a"], ["b", "c"]] and out["runs"][0]["date"] == "old"
    assert out["runs"][-1]["machine_speed"] == out["machine_speed"]
    whole = micro.merged([row("a", 1.0)], None, ["a"])
    assert [r["tricks"] for r in whole["runs"]] == [["a"]] and len(whole["claims"]) == 1
