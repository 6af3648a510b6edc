"""Geometric smoothing (Oshita 2003 §4.3): PN triangles, particle normal control (eq. 4.2-4.4),
edge length control (eq. 4.5-4.6, bisection), tessellation; the skirt generator; PC2 files."""

import numpy as np
import pytest

from cloth_scenes import legs, sheet, walking_skirt
from humananim.solver.cloth import (ClothSimulation, Smoother, build_mesh, controlled_normals, edge_midpoints,
                                    preset, read_pc2, skirt_mesh, tessellation, write_pc2)
from humananim.solver.cloth.smoothing import edge_controls, pn_curve_length


def polyline_length(points):
    return np.linalg.norm(np.diff(points, axis=0), axis=1).sum()


def edge_polylines(smoother, fine):
    """Every coarse edge traced on a fine surface: (E,) polyline lengths."""
    return np.array([polyline_length(fine[row]) for row in smoother.tess.edge_vertices])


def test_tessellation_counts_and_watertightness():
    pos, faces = sheet(4, 3, 0.3)
    mesh = build_mesh(pos, faces)
    for level in (1, 2, 3):
        t = tessellation(mesh, level)
        n = 2 * level
        assert len(t.faces) == len(mesh.faces) * n * n
        # every fine edge is shared by two fine triangles except along the coarse border
        sides = np.sort(np.stack([t.faces, np.roll(t.faces, -1, axis=1)], axis=-1).reshape(-1, 2), axis=1)
        _, counts = np.unique(sides, axis=0, return_counts=True)
        border = np.sum(mesh.edge_faces[:, 1] < 0) * n
        assert counts.max() == 2 and np.sum(counts == 1) == border
        assert len(np.unique(t.faces)) == t.vertex_count


def test_thesis_sized_skirt_counts():
    pos, faces, pinned = skirt_mesh([0, 0, 1], [1, 0, 0], [0, 0, 1], np.linspace(0, -0.5, 6),
                                    np.linspace(0.15, 0.3, 6), columns=11)
    mesh = build_mesh(pos, faces)
    smoother = Smoother(mesh, level=2)
    assert mesh.particle_count == 66 and len(mesh.faces) == 110 and len(pinned) == 11
    assert len(smoother.faces) == 110 * 16  # 4 sub-patches of 4 triangles per coarse face


def test_flat_cloth_stays_flat_and_passes_through_its_particles():
    pos, faces = sheet(5, 5, 0.4)
    mesh = build_mesh(pos, faces)
    rng = np.random.default_rng(5)
    x = pos.copy()
    x[:, :2] += rng.normal(0, 0.005, (len(x), 2))  # in-plane jitter: stretched and shortened edges
    fine = Smoother(mesh, level=3, k_elastic=10.0, edge_control=False).surface(x)
    assert np.allclose(fine[:, 2], 1.0, atol=1e-12)
    assert np.array_equal(fine[:len(x)], x)


def test_normal_control_weights_face_normals_by_elastic_force():
    # two faces hinged on edge 0-1; particle 0 pulled by face A's springs only
    x = np.array([[0, 0, 0], [1, 0, 0], [0.5, 1, 0.0], [0.5, -0.6, -0.8]])
    mesh = build_mesh(x, [(0, 1, 2), (1, 0, 3)])
    rest = mesh.rest.copy()
    y = rest.copy()
    y[2] = rest[2] + [0, 0.2, 0]  # stretch edges 0-2 and 1-2 (face A only)
    n = controlled_normals(mesh, y, 5.0, control=True)
    nA = np.cross(y[1] - y[0], y[2] - y[0])
    nA /= np.linalg.norm(nA)
    nB = np.cross(y[0] - y[1], y[3] - y[1])
    nB /= np.linalg.norm(nB)
    # eq. 4.4: f_0^A = f_01 + f_02, f_0^B = f_01 + f_03; eq. 4.3: weighted mean of the face normals
    def f(i, j):
        d = y[j] - y[i]
        length = np.linalg.norm(d)
        rl = np.linalg.norm(rest[j] - rest[i])
        return 5.0 * (length - rl) / rl * d
    wa, wb = np.linalg.norm(f(0, 1) + f(0, 2)), np.linalg.norm(f(0, 1) + f(0, 3))
    expected = (wa * nA + wb * nB) / (wa + wb)
    assert wb < 1e-12 < wa
    assert np.allclose(n[0], expected / np.linalg.norm(expected), atol=1e-6)
    plain = controlled_normals(mesh, y, 5.0, control=False)[0]
    assert not np.allclose(plain, n[0], atol=1e-3)  # differs from the Gouraud average


def test_edge_length_control_restores_the_rest_length_of_shortened_edges():
    p0 = np.array([[0.0, 0, 0], [0, 0, 0]])
    p1 = np.array([[0.07, 0, 0], [0.2, 0, 0]])
    n = np.array([[0.0, 0, 1], [0, 0, 1]])
    rest = np.array([0.1, 0.1])
    mid, nm, h, short = edge_midpoints(p0, n, p1, n, rest, k_guess=1.0, iterations=30)
    assert short.tolist() == [True, False] and h[1] == 0.0 and h[0] > 0.0
    from humananim.solver.cloth.smoothing import split_curve_length
    assert split_curve_length(p0[:1], n[:1], mid[:1], nm[:1], p1[:1], n[:1])[0] == pytest.approx(0.1, rel=1e-6)
    assert np.allclose(mid[0, :2], [0.035, 0]) and mid[0, 2] == pytest.approx(h[0])  # moved along the normal


def test_shortened_cloth_keeps_its_curve_lengths_within_2_percent():
    pos, faces = sheet(6, 6, 0.5)
    mesh = build_mesh(pos, faces)
    x = pos.copy()
    x[:, 0] *= 0.75  # squeeze the sheet: x edges and diagonals shortened
    x[:, 2] += 0.02 * np.sin(np.pi * x[:, 0] / 0.375)
    coarse = Smoother(mesh, level=2, k_elastic=10.0)
    coarse.surface(x)
    short = coarse.last["short"]
    assert short.sum() > 20
    ratio = coarse.edge_curve_lengths(x)[short] / mesh.rest_length[short]
    assert np.abs(ratio - 1).max() < 0.02
    # measured independently on the surface itself: a dense tessellation traced along each edge
    dense = Smoother(mesh, level=24, k_elastic=10.0)
    fine = dense.surface(x)
    traced = edge_polylines(dense, fine)[short] / mesh.rest_length[short]
    assert np.abs(traced - 1).max() < 0.02
    plain = Smoother(mesh, level=24, k_elastic=10.0, edge_control=False)
    plain_ratio = edge_polylines(plain, plain.surface(x))[short] / mesh.rest_length[short]
    assert plain_ratio.min() < 0.8 and plain_ratio.mean() < 0.95  # PN alone keeps the shortening
    assert np.array_equal(fine[:len(x)], x)  # still through the particles


def test_pn_edge_curve_depends_only_on_its_edge():
    rng = np.random.default_rng(6)
    p0, p1 = rng.normal(size=(2, 3))
    n0, n1 = rng.normal(size=(2, 3))
    n0, n1 = n0 / np.linalg.norm(n0), n1 / np.linalg.norm(n1)
    c1, c2 = edge_controls(p0, n0, p1, n1)
    d1, d2 = edge_controls(p1, n1, p0, n0)
    assert np.allclose(c1, d2) and np.allclose(c2, d1)  # the same curve from either side
    assert pn_curve_length(p0, n0, p1, n1) >= np.linalg.norm(p1 - p0)


def test_skirt_generator_fits_the_body_pins_the_waist_and_faces_out():
    mesh, pinned, body = walking_skirt(rings=6, columns=11)
    assert mesh.particle_count == 66 and len(pinned) == 11
    assert np.allclose(mesh.rest[pinned, 2], mesh.rest[pinned[0], 2])  # the top ring
    assert mesh.rest[pinned, 2].min() >= mesh.rest[:, 2].max() - 1e-9
    phi, _, _ = body.query(mesh.rest, 1.0)
    assert phi.min() >= 0.02 - 0.005  # clears the capsules by about the clearance
    n, _ = __import__("humananim.solver.cloth.mesh", fromlist=["face_normals"]).face_normals(mesh.rest, mesh.faces)
    centre = mesh.rest[pinned].mean(axis=0)
    out = mesh.rest[mesh.faces].mean(axis=1) - centre
    out[:, 2] = 0
    assert np.all(np.einsum("ij,ij->i", n, out) > 0)


def test_a_skirt_surface_on_a_walk_passes_through_particles_and_keeps_lengths():
    mesh, pinned, body = walking_skirt()
    sim = ClothSimulation(mesh, preset("DENIM"), pinned, [body], level=2, fps=30)
    a0, b0 = legs(0.0)
    shortened = 0
    for f in range(1, 46):
        a1, b1 = legs(f / 30.0)
        body.set_motion(a0, b0, a1, b1, 1 / 30)
        sim.step(mesh.rest[pinned], 1 / 30)
        fine = sim.surface()
        assert np.array_equal(fine[:mesh.particle_count], sim.x)
        short = sim.smoother.last["short"]
        shortened += short.sum()
        if short.any():
            ratio = sim.smoother.edge_curve_lengths(sim.x)[short] / mesh.rest_length[short]
            assert np.abs(ratio - 1).max() < 0.02
        a0, b0 = a1, b1
    assert shortened > 0


def test_pc2_round_trip(tmp_path):
    data = np.random.default_rng(7).normal(size=(5, 9, 3)).astype(np.float32)
    path = tmp_path / "x.pc2"
    write_pc2(path, data, start=3.0, rate=2.0)
    raw = path.read_bytes()
    assert raw[:12] == b"POINTCACHE2\0" and len(raw) == 32 + data.size * 4
    back, start, rate = read_pc2(path)
    assert np.array_equal(back, data) and (start, rate) == (3.0, 2.0)
