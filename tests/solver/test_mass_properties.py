import numpy as np
import pytest

from humananim.solver import rotations
from humananim.solver.mass_properties import box_mesh, closed_mass_properties, mesh_mass_properties


def test_box_matches_closed_form():
    v, t = box_mesh((0.3, 0.5, 1.2), centre=(1.0, -2.0, 0.5))
    m, c, inertia = mesh_mass_properties(v, t, density=1000.0)
    assert m == pytest.approx(1000 * 0.3 * 0.5 * 1.2)
    assert np.allclose(c, (1.0, -2.0, 0.5))
    a, b, h = 0.3, 0.5, 1.2
    assert np.allclose(inertia, np.diag([m * (b * b + h * h), m * (a * a + h * h), m * (a * a + b * b)]) / 12)


def test_rotated_box_inertia_rotates():
    v, t = box_mesh((0.2, 0.4, 0.9))
    q = rotations.normalize([0.9, 0.2, -0.3, 0.1])
    r = rotations.to_matrix(q)
    m0, _, i0 = mesh_mass_properties(v, t)
    m1, c1, i1 = mesh_mass_properties(v @ r.T + [3, 4, 5], t)
    assert m1 == pytest.approx(m0)
    assert np.allclose(c1, [3, 4, 5])
    assert np.allclose(i1, r @ i0 @ r.T)


def test_inside_out_mesh_gives_the_same_positive_mass():
    v, t = box_mesh((1, 1, 1))
    m, _, inertia = mesh_mass_properties(v, t[:, ::-1])
    assert m == pytest.approx(1.0)
    assert np.all(np.linalg.eigvalsh(inertia) > 0)


def test_open_piece_is_capped_like_a_closed_one():
    # a cylinder side without its end caps: capping must give the closed prism's integrals
    n = 64
    ang = np.linspace(0, 2 * np.pi, n, endpoint=False)
    ring = np.column_stack((np.cos(ang), np.sin(ang)))
    v = np.vstack((np.column_stack((ring, np.zeros(n))), np.column_stack((ring, np.full(n, 2.0)))))
    i = np.arange(n)
    j = (i + 1) % n
    side = np.vstack((np.column_stack((i, j, j + n)), np.column_stack((i, j + n, i + n))))
    m, c, inertia = closed_mass_properties(v, side)
    area = 0.5 * n * np.sin(2 * np.pi / n)  # the inscribed polygon
    assert m == pytest.approx(area * 2.0, rel=1e-9)
    assert np.allclose(c, [0, 0, 1.0])
    assert inertia[2, 2] == pytest.approx(m * 0.5, rel=2e-3)  # a solid cylinder, r = 1
