"""Cloth dynamics (Oshita 2003 §4.4): topology, eq. 4.1 springs, RK4 energy, pins, Provot limits,
drag and wind, the stability cap."""

import numpy as np
import pytest

from cloth_scenes import sheet
from humananim.solver.cloth import ClothDynamics, ClothError, ClothParams, ClothSimulation, build_mesh, edge_lengths

ZERO = dict(gravity=(0, 0, 0), drag=0.0, air_damping=0.0, damping=0.0)


def test_topology_of_a_quad():
    pos = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    mesh = build_mesh(pos, [(0, 1, 2), (0, 2, 3)])
    assert mesh.edges.tolist() == [[0, 1], [0, 2], [0, 3], [1, 2], [2, 3]]
    inner = np.flatnonzero(mesh.edge_faces[:, 1] >= 0)
    assert mesh.edges[inner].tolist() == [[0, 2]]
    assert sorted(mesh.bend_pairs[0].tolist()) == [1, 3]
    assert mesh.area.sum() == pytest.approx(1.0)
    assert np.allclose(mesh.rest_length, [1, np.sqrt(2), 1, 1, 1])


def test_bad_meshes_are_refused():
    pos = np.zeros((4, 3))
    pos[:, 0] = [0, 1, 0, 1]
    pos[:, 1] = [0, 0, 1, 1]
    with pytest.raises(ClothError):
        build_mesh(pos, [(0, 0, 1)])
    with pytest.raises(ClothError):  # three faces on one edge
        build_mesh(np.vstack([pos, [[0.5, 0.5, 1]]]), [(0, 1, 2), (0, 1, 3), (0, 1, 4)])


def test_spring_force_is_eq_4_1():
    pos = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
    mesh = build_mesh(pos, [(0, 1, 2)])
    dyn = ClothDynamics(mesh, ClothParams(stretch=7.0, **ZERO))
    x = pos.copy()
    x[1, 0] = 1.5  # edge 0-1 stretched from L=1 to 1.5
    f = dyn.spring_forces(x, np.zeros_like(x))
    # |f| = k |d|/L (|d| - L) = 7 * 1.5 * 0.5, pulling particle 0 towards particle 1
    assert np.allclose(f[0], [7 * 1.5 * 0.5, 0, 0])


def test_bending_springs_open_a_folded_hinge():
    """Two faces on one edge, folded to 90 degrees: the bending spring across them (between the
    opposite corners) opens the hinge; without it the fold stays."""
    pos = np.array([[0, 0, 0], [0, 1, 0], [1, 0.5, 0], [-1, 0.5, 0]], float)
    mesh = build_mesh(pos, [(0, 1, 2), (1, 0, 3)])
    assert mesh.bend_pairs.tolist() == [[2, 3]]

    def fold(x):  # the angle between the two faces' wings, degrees
        a, b = x[2] - 0.5 * (x[0] + x[1]), x[3] - 0.5 * (x[0] + x[1])
        return np.degrees(np.arccos(a @ b / np.linalg.norm(a) / np.linalg.norm(b)))

    opened = {}
    for bend in (0.0, 0.5):
        dyn = ClothDynamics(mesh, ClothParams(stretch=20.0, bend=bend, density=0.2, **ZERO))
        x, v, none = pos.copy(), np.zeros_like(pos), np.zeros((0, 3))
        x[3] = [0, 0.5, 1.0]
        for _ in range(400):  # 0.4 s
            x, v = dyn.rk4_step(x, v, 1e-3, none, none)
        opened[bend] = fold(x)
    assert opened[0.0] == pytest.approx(90.0, abs=1e-6) and opened[0.5] > 120.0


def test_rk4_keeps_the_energy_of_an_undamped_cloth():
    pos, faces = sheet(5, 5, 0.4)
    mesh = build_mesh(pos, faces)
    dyn = ClothDynamics(mesh, ClothParams(stretch=20.0, bend=0.5, density=0.2, **ZERO))
    rng = np.random.default_rng(1)
    x, v = pos + rng.normal(0, 0.01, pos.shape), rng.normal(0, 0.2, pos.shape)
    e0 = dyn.energy(x, v)
    empty = np.zeros((0, 3))
    for _ in range(2000):  # 1 s at 2 kHz
        x, v = dyn.rk4_step(x, v, 5e-4, empty, empty)
    assert abs(dyn.energy(x, v) - e0) < 1e-4 * e0
    assert e0 > 1e-3


def test_damping_and_drag_only_remove_energy():
    pos, faces = sheet(5, 5, 0.4)
    mesh = build_mesh(pos, faces)
    dyn = ClothDynamics(mesh, ClothParams(stretch=20.0, bend=0.5, density=0.2, gravity=(0, 0, 0), damping=0.01,
                                          drag=1.0, air_damping=0.5))
    rng = np.random.default_rng(2)
    x, v = pos + rng.normal(0, 0.01, pos.shape), rng.normal(0, 0.5, pos.shape)
    energies = []
    empty = np.zeros((0, 3))
    for _ in range(400):
        x, v = dyn.rk4_step(x, v, 1e-3, empty, empty)
        energies.append(dyn.energy(x, v))
    assert np.all(np.diff(energies) <= 1e-12) and energies[-1] < 0.5 * energies[0]


def test_free_fall_is_exact_and_pins_follow_their_targets():
    pos, faces = sheet(3, 3, 0.2)
    mesh = build_mesh(pos, faces)
    dyn = ClothDynamics(mesh, ClothParams(stretch=0.0, bend=0.0, drag=0.0, air_damping=0.0, damping=0.0), pinned=[0])
    x, v = pos.copy(), np.zeros_like(pos)
    t, dt = 0.0, 0.01
    for k in range(30):
        target = pos[[0]] + [0.1 * (t + dt), 0, 0]
        x, v = dyn.rk4_step(x, v, dt, pos[[0]] + [0.1 * t, 0, 0], target)
        t += dt
        assert np.allclose(x[0], target[0]) and np.allclose(v[0], [0.1, 0, 0])
    assert np.allclose(x[1:, 2], pos[1:, 2] - 0.5 * 9.81 * t * t, atol=1e-12)


def test_provot_limits_elongated_edges_and_leaves_shortened_ones():
    pos, faces = sheet(6, 6, 0.5)
    mesh = build_mesh(pos, faces)
    params = ClothParams(stretch_limit=0.01, constraint_iterations=200, compress_limit=0.0)  # the thesis
    dyn = ClothDynamics(mesh, params, pinned=[0, 5])
    x = pos.copy()
    x[:, 1] *= 1.2  # stretch along y, compress along x
    x[:, 0] *= 0.9
    v = np.zeros_like(x)
    v[:, 1] = x[:, 1]  # everything moving apart along y
    x2, v2, corrected = dyn.limit_elongation(x, v)
    ratio = edge_lengths(mesh, x2) / mesh.rest_length
    assert corrected > 0 and ratio.max() < 1.0 + 0.01 + 2e-3
    assert np.allclose(x2[[0, 5]], x[[0, 5]])  # pinned particles stay
    # a cloth with only shortened edges is left exactly as it is (the smoothing handles those)
    shrunk = 0.8 * pos
    x3, v3, none = dyn.limit_elongation(shrunk, v)
    assert none == 0 and np.array_equal(x3, shrunk) and np.array_equal(v3, v)
    def stretching(xx, vv):  # rate of lengthening of each edge
        d = xx[mesh.edges[:, 1]] - xx[mesh.edges[:, 0]]
        return np.einsum("ij,ij->i", vv[mesh.edges[:, 1]] - vv[mesh.edges[:, 0]], d) / np.linalg.norm(d, axis=1)

    before, after = stretching(x, v), stretching(x2, v2)
    assert np.maximum(after, 0).sum() < 0.8 * np.maximum(before, 0).sum()  # one sweep per substep


def test_accelerated_sweeps_reach_the_limits_sooner():
    """Chebyshev acceleration of the Provot sweeps (the frame-end pass): on a sheet stretched 20 %,
    12 accelerated sweeps leave less than half the excess beyond the limits that 12 plain ones
    leave, and less than 50 plain ones leave; run on, they converge ten times closer; pinned
    particles stay."""
    pos, faces = sheet(9, 9, 0.8)
    mesh = build_mesh(pos, faces)
    dyn = ClothDynamics(mesh, ClothParams(stretch_limit=0.01, compress_limit=0.04), pinned=[0, 8])
    x = pos * [1.0, 1.2, 1.0]
    v = np.zeros_like(x)

    def excess(sweeps, accelerate):
        out, _, _ = dyn.limit_elongation(x, v, sweeps, frame_end=accelerate)
        assert np.array_equal(out[[0, 8]], x[[0, 8]])
        length = edge_lengths(mesh, out)
        rest = mesh.rest_length
        return np.abs(length - np.clip(length, 0.96 * rest, 1.01 * rest)).sum() / rest.sum()

    plain, fast = excess(12, False), excess(12, True)
    assert fast < 0.5 * plain
    assert excess(50, False) > fast
    assert excess(400, True) < 0.1 * excess(400, False)


@pytest.mark.parametrize("compress_limit", [0.0, 0.05])
def test_stiff_material_is_capped_to_the_stable_step_and_does_not_explode(compress_limit):
    pos, faces = sheet(7, 7, 0.6)
    mesh = build_mesh(pos, faces)
    params = ClothParams(stretch=5000.0, bend=200.0, damping=5.0, substeps=2, compress_limit=compress_limit,
                         final_iterations=100)
    sim = ClothSimulation(mesh, params, pinned=[0, 6], fps=30)
    assert sim.dynamics.capped and sim.dynamics.stretch < 5000.0
    for _ in range(150):
        sim.step(None, 1 / 30)
    assert np.isfinite(sim.x).all() and np.abs(sim.v).max() < 10.0
    # hanging from two corners, the whole weight on a few edges: the averaged corrections leave
    # some over the limit, but the sheet keeps its size on average
    assert abs(sim.stretch()) < 0.03


def test_compression_limit_pushes_squeezed_edges_back_and_zero_leaves_them():
    pos, faces = sheet(6, 6, 0.5)
    mesh = build_mesh(pos, faces)
    shrunk = 0.8 * pos
    v = np.zeros_like(pos)
    thesis = ClothDynamics(mesh, ClothParams(compress_limit=0.0))
    assert np.array_equal(thesis.limit_elongation(shrunk, v)[0], shrunk)
    limited = ClothDynamics(mesh, ClothParams(compress_limit=0.05, constraint_iterations=400), pinned=[0])
    x, _, n = limited.limit_elongation(shrunk, v)
    ratio = edge_lengths(mesh, x) / mesh.rest_length
    assert n > 0 and ratio.min() > 0.92 and ratio.max() < 1.03  # from 0.8 towards [0.95, 1.01]


def test_air_drag_slows_a_falling_sheet_and_wind_carries_it():
    pos, faces = sheet(5, 5, 0.5)
    mesh = build_mesh(pos, faces)
    out = {}
    for name, kw in (("vacuum", dict(drag=0.0, air_damping=0.0)), ("air", dict(drag=1.2, air_damping=0.0)),
                     ("wind", dict(drag=1.2, air_damping=0.0, wind=(0, 0, 3.0)))):
        sim = ClothSimulation(mesh, ClothParams(density=0.1, **kw), fps=30)
        for _ in range(30):
            sim.step(None, 1 / 30)
        out[name] = sim.x[:, 2].mean() - 1.0
    assert out["vacuum"] == pytest.approx(-0.5 * 9.81, rel=0.02)
    assert out["air"] > 0.5 * out["vacuum"]  # a flat sheet falls much slower in air
    assert out["wind"] > out["air"]  # an updraft holds it up


def test_a_long_hanging_garment_keeps_its_length():
    """A 300-particle coat-like tube hanging from its top ring: the tethers to the pins stop the
    stretch that accumulates down a long garment."""
    from humananim.solver.cloth import preset, skirt_mesh
    pos, faces, pinned = skirt_mesh([0, 0, 1.3], [1, 0, 0], [0, 0, 1], np.linspace(0, -0.9, 12),
                                    np.linspace(0.17, 0.3, 12), columns=25)
    mesh = build_mesh(pos, faces)
    sim = ClothSimulation(mesh, preset("COTTON"), pinned, fps=30)
    worst = 0.0
    for _ in range(60):
        sim.step(None, 1 / 30)
        worst = max(worst, abs(sim.stretch()))
    ratio = edge_lengths(mesh, sim.x) / mesh.rest_length
    assert mesh.particle_count == 300 and worst < 0.02 and ratio.max() < 1.03
    assert sim.x[:, 2].min() < pos[:, 2].min() - 0.005  # it did hang (and fall inwards), not freeze
