"""Zero moment point, support polygon, minimum moment point, strength model."""

import numpy as np
import pytest

from humananim.solver.dynamics import (build_model, center_of_mass, convex_hull, default_contacts,
                                       default_strength, integrate, minimum_moment_point,
                                       oshita_figure, point_positions, rnea, support_polygon, zmp)
from humananim.solver.dynamics.balance import inside


@pytest.fixture(scope="module")
def fig():
    m = build_model(oshita_figure())
    return m, m.create_data()


@pytest.mark.parametrize("exact", [True, False])
@pytest.mark.parametrize("height", [0.0, 0.37])
def test_static_pose_zmp_is_com_projection(fig, exact, height):
    m, d = fig
    rng = np.random.default_rng(0)
    q = integrate(m, m.neutral(), 0.5 * rng.normal(size=m.nv))
    z = np.zeros(m.nv)
    np.testing.assert_allclose(zmp(m, d, q, z, z, ground_height=height, exact=exact),
                               center_of_mass(m, d, q)[:2], atol=1e-10)


def test_zmp_has_no_horizontal_ground_moment(fig):
    """The ground reaction wrench the motion needs has zero horizontal moment about the ZMP."""
    m, d = fig
    rng = np.random.default_rng(1)
    q = integrate(m, m.neutral(), 0.3 * rng.normal(size=m.nv))
    v, a = rng.normal(size=m.nv), rng.normal(size=m.nv)
    p = np.r_[zmp(m, d, q, v, a, ground_height=0.1), 0.1]
    _, total = rnea(m, d, q, v, a, return_wrenches=True)
    n, f = total[0, :3], total[0, 3:]
    assert np.abs((n - np.cross(p, f))[:2]).max() < 1e-9 * np.abs(n).max()


def test_oshita_zmp_equals_exact_for_point_masses():
    """Eq. 2.11-2.12 ignore the segments' own rotational inertia: with (nearly) point-mass segments
    they agree with the exact ZMP under any motion."""
    sk = oshita_figure()
    sk = sk.with_mass_model(sk.mass, sk.com, np.zeros_like(sk.inertia))
    m = build_model(sk, min_inertia=1e-12)
    d = m.create_data()
    rng = np.random.default_rng(2)
    q = integrate(m, m.neutral(), 0.3 * rng.normal(size=m.nv))
    v, a = rng.normal(size=m.nv), rng.normal(size=m.nv)
    np.testing.assert_allclose(zmp(m, d, q, v, a, exact=False), zmp(m, d, q, v, a), atol=1e-8)


def test_support_polygon_of_standing_feet_contains_com(fig):
    m, d = fig
    q = m.neutral()
    c = default_contacts(m)
    pts = point_positions(m, d, q, c.joints, c.points)
    pts[:, 2] -= c.radii
    poly = support_polygon(pts, 0.0)
    assert len(poly) == 4  # the outer corners of the two soles
    assert inside(poly, center_of_mass(m, d, q)[:2])
    area = 0.5 * np.sum(poly[:, 0] * np.roll(poly[:, 1], -1) - np.roll(poly[:, 0], -1) * poly[:, 1])
    assert area == pytest.approx(0.27 * 0.24, rel=1e-9)  # 27 cm wide, 24 cm long, counter-clockwise


def test_convex_hull_and_mmp():
    rng = np.random.default_rng(3)
    pts = rng.normal(size=(40, 2))
    hull = convex_hull(pts)
    assert all(inside(hull, p) for p in pts)
    for p in rng.normal(size=(20, 2)) * 3:
        mmp = minimum_moment_point(hull, p)
        if inside(hull, p):
            np.testing.assert_allclose(mmp, p)
        else:  # brute force: densely sampled boundary
            t = np.linspace(0, 1, 2001)[:, None]
            edges = np.concatenate([a + t * (b - a) for a, b in zip(hull, np.roll(hull, -1, axis=0))])
            assert np.linalg.norm(mmp - p) <= np.linalg.norm(edges - p, axis=1).min() + 1e-9
    assert len(convex_hull([(0, 0), (1, 1), (2, 2)])) == 2  # collinear: a segment
    np.testing.assert_allclose(minimum_moment_point(convex_hull([(0, 0), (2, 0)]), (1, 1)), (1, 0))
    np.testing.assert_allclose(minimum_moment_point([(1.0, 1.0)], (3, 3)), (1, 1))


def test_strength_model(fig):
    m, _ = fig
    st = default_strength(m)
    J = m.skeleton.joint_count
    zero = np.zeros((J, 3))
    low, high = st.limits(zero, zero)
    knee = m.skeleton.index("shin.L")
    assert high[knee, 0] == pytest.approx(190.0) and low[knee, 0] == pytest.approx(-190.0)
    w = np.zeros((J, 3))
    w[knee, 0] = 5.0  # extending quickly: less torque with the motion, more against it
    low2, high2 = st.limits(zero, w)
    assert high2[knee, 0] < high[knee, 0] and -low2[knee, 0] > high[knee, 0]
    angled = np.zeros((J, 3))
    angled[knee, 0] = 1.5
    assert st.limits(angled, zero)[1][knee, 0] < high[knee, 0]
    strong = default_strength(m, scale=2.0)
    np.testing.assert_allclose(strong.limits(zero, w)[1], 2 * high2)
    tau = np.random.default_rng(0).normal(size=(J, 3)) * 300
    clamped, usage = st.clamp(tau, zero, w)
    assert np.all(clamped <= high2 + 1e-12) and np.all(clamped >= low2 - 1e-12)
    over = (tau > high2) | (tau < low2)
    assert np.all(usage[over] > 1.0) and np.all(np.abs(usage[~over]) <= 1.0)
