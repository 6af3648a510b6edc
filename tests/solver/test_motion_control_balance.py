"""Balance control (Oshita 2003, eq. 2.11-2.14, sec. 2.3.3 and 2.5.3): ZMP to MMP by the arms,
the back, then the legs through the pelvis, and the falling criterion."""

import numpy as np
import pytest

from humananim.solver import rotations
from humananim.solver.dynamics import build_model, default_strength, oshita_figure, zmp
from humananim.solver.motion_control.balance_control import (augmented_body, balance_control,
                                                             support_polygon, zmp_jacobian)
from humananim.solver.motion_control.comfort_control import required_torques
from humananim.solver.motion_control.dynamic_control import dynamic_control

from test_motion_control_comfort import on_ground, posed, squat, state


@pytest.fixture(scope="module")
def figure():
    return oshita_figure()


def pushed_forward(m, st, acc):
    """Tracking acceleration: the pelvis accelerating forward (-Y) with the feet held."""
    return st.pelvis_jacobian() @ np.array([0.0, -acc, 0.0])


def check_zmp(m, st, a, point):
    got = zmp(m, st.data, st.q, st.v, a, ground_height=st.ground_height)
    assert np.linalg.norm(got - point) < 1e-3


def test_balanced_motion_changes_nothing(figure):
    m = build_model(figure)
    st = state(m, on_ground(m, posed(m, squat())))
    res = balance_control(st, pushed_forward(m, st, 0.75))
    assert np.array_equal(res.delta, np.zeros(m.nv)) and res.falling is None


def test_zmp_jacobian_matches_differences(figure):
    """Eq. 2.13-2.14 through the augmented bodies against finite differences of the ZMP."""
    m = build_model(figure)
    st = state(m, on_ground(m, posed(m, squat())))
    a = pushed_forward(m, st, 1.0)
    w = required_torques(st, a)[1]
    dofs = np.r_[st.parts.arms, st.parts.back]
    jac = zmp_jacobian(st, w, dofs)
    for k, d in enumerate(dofs):
        e = np.zeros(m.nv)
        e[d] = 1e-4
        num = (zmp(m, st.data, st.q, st.v, a + e) - zmp(m, st.data, st.q, st.v, a - e)) / 2e-4
        np.testing.assert_allclose(jac[:, k], num, atol=1e-6)
    body = augmented_body(st, st.parts.back)
    spine = figure.index("spine")
    assert body.mass[0] == pytest.approx(figure.mass[[spine, *figure.descendants(spine)]].sum())


def test_small_error_is_corrected_by_the_arms_alone(figure):
    m = build_model(figure)
    st = state(m, on_ground(m, posed(m, squat())))
    a = pushed_forward(m, st, 1.5)
    res = balance_control(st, a)
    assert [p for p, _ in res.log.actions] == ["arms"]
    moved = np.flatnonzero(res.delta)
    assert set(moved) <= set(st.parts.arms)
    assert res.zmp_before[1] > support_polygon(st)[:, 1].max()  # behind the heels
    check_zmp(m, st, a + res.delta, res.mmp)
    assert res.falling is None


@pytest.mark.parametrize("acc, parts", [(3.0, ["arms", "back"]), (8.0, ["arms", "back", "legs"])])
def test_larger_errors_go_on_to_the_back_then_the_legs(figure, acc, parts):
    m = build_model(figure)
    st = state(m, on_ground(m, posed(m, squat())))
    a = pushed_forward(m, st, acc)
    res = balance_control(st, a)
    assert [p for p, k in res.log.actions if k == "balance"] == parts
    check_zmp(m, st, a + res.delta, res.mmp)
    assert res.falling is None
    print(acc, "ZMP error (m):", np.linalg.norm(zmp(m, st.data, st.q, st.v, a + res.delta) - res.mmp))


def test_huge_lean_falls_forward_about_the_mmp(figure):
    m = build_model(figure)
    lean = np.radians(65.0)  # the legs cannot bring the ZMP back within max_pelvis_acceleration
    q = posed(m, {"foot.L": (0, -65.0), "foot.R": (0, -65.0)})
    q[3:7] = rotations.multiply(rotations.axis_rotation(0, lean), q[3:7])  # whole body about world X
    st = state(m, on_ground(m, q))
    res = dynamic_control(st, np.zeros(m.nv))
    assert res.falling is not None
    poly = res.polygon
    assert res.mmp[1] == pytest.approx(poly[:, 1].min())  # the toes' edge
    assert res.falling.angular_acceleration[0] > 0.5  # turning forward (-Y): +X
    assert abs(res.falling.angular_acceleration[1]) < 1e-6
    assert res.falling.segment in (figure.index("foot.L"), figure.index("foot.R"))
    print("fall", res.falling.angular_acceleration, res.log.actions)


def test_real_rig_balance():
    from test_dynamics_closed_loop_rigs import load
    from humananim.solver.motion_control.comfort_control import ControlState, body_parts
    from humananim.solver.dynamics.kinematics import point_positions
    sk, tr = load("metarig_legs", frames=1)
    m = build_model(sk, reference_basis=tr.basis()[0])
    parts = body_parts(m)
    data = m.create_data()
    q = m.neutral()
    ground = min(point_positions(m, data, q, j, p)[:, 2].min() for j, p in zip(parts.sole_joints, parts.sole_points))
    st = ControlState(m, data, q, np.zeros(m.nv), (True, True), parts, default_strength(m), ground_height=ground)
    for acc in (1.0, 3.0):
        a = st.pelvis_jacobian() @ np.array([0.0, -acc, 0.0])
        res = balance_control(st, a)
        if res.falling is None and res.mmp is not None:
            assert np.linalg.norm(zmp(m, data, q, st.v, a + res.delta, ground_height=ground) - res.mmp) < 1e-3
        print(acc, res.log.actions, res.zmp_before, res.zmp)


def _hull_indices(pts):
    from humananim.solver.dynamics import convex_hull
    where = {p: i for i, p in reversed(list(enumerate(map(tuple, pts.tolist()))))}
    return [where[p] for p in map(tuple, convex_hull(pts).tolist())]


def test_support_hull_reuse_gives_the_hull_of_the_moved_points():
    """The support polygon reuses a hull's vertex indices when the monotone chain takes the same
    path on the moved sole points (_same_path: the sort order and every turn test it made):
    wherever it does, they are exactly the vertices convex_hull finds for the moved points; a move
    that changes the hull changes the path."""
    from humananim.solver.motion_control.balance_control import _hull_path, _same_path
    rng = np.random.default_rng(4)
    reused = rebuilt = 0
    for _ in range(300):
        # two feet's sole points (6 each, heel to toe), rolling and sliding a little
        pts = np.concatenate([rng.normal(c, (0.05, 0.12), (6, 2)) for c in ((0.1, 0.0), (-0.1, 0.05))])
        moved = pts + rng.normal(0.0, rng.choice([1e-4, 1e-3, 1e-2]), pts.shape)
        idx, path = _hull_path(pts.tolist())
        assert idx == _hull_indices(pts)
        if _same_path(moved.tolist(), path):
            assert _hull_indices(moved) == idx
            reused += 1
        else:
            rebuilt += 1
    assert reused > 30 and rebuilt > 30  # both paths are exercised
    # a point moved out past the hull changes both the hull and the path
    pts = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [0.5, 0.5]])
    out = pts.copy()
    out[4] = (0.5, 1.5)
    path = _hull_path(pts.tolist())[1]
    assert _hull_indices(out) != _hull_indices(pts) and not _same_path(out.tolist(), path)
    # coinciding points: no path (convex_hull merges them)
    assert _hull_path([[0.0, 0.0], [1.0, 0.0], [0.0, 0.0]]) is None
