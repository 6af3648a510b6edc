"""Cloth against the body (Oshita 2003 §4.4.4): capsules and skinned triangle meshes, the vertex
and the face case, tangential velocity only; a skirt on a walking body stays outside."""

import numpy as np

from cloth_scenes import RADII, SkinnedLegs, walk, walking_skirt
from humananim.solver.cloth import (CapsuleBody, ClothSimulation, MeshBody, capsule_mesh, preset,
                                    resolve_contacts)
from humananim.solver.cloth.collision import closest_on_segments, closest_on_triangles


def capsule_depth(points, a, b, r):
    """Exact depth inside a union of capsules (0 outside)."""
    q, _ = closest_on_segments(points[:, None], a[None], b[None])
    return np.maximum((r[None] - np.linalg.norm(points[:, None] - q, axis=2)).max(axis=1), 0.0)


def test_closest_points_on_triangles_match_a_dense_sampling():
    rng = np.random.default_rng(3)
    a, b, c = rng.normal(size=(3, 50, 3))
    p = rng.normal(size=(50, 3)) * 2
    q, bary = closest_on_triangles(p, a, b, c)
    assert np.allclose(bary.sum(axis=1), 1) and (bary >= -1e-12).all()
    assert np.allclose(q, bary[:, :1] * a + bary[:, 1:2] * b + bary[:, 2:] * c)
    s = np.linspace(0, 1, 60)
    u, v = np.meshgrid(s, s)
    keep = u + v <= 1
    u, v = u[keep], v[keep]
    for i in range(50):
        pts = a[i] + u[:, None] * (b[i] - a[i]) + v[:, None] * (c[i] - a[i])
        assert np.linalg.norm(p[i] - q[i]) <= np.linalg.norm(pts - p[i], axis=1).min() + 1e-12


def test_a_particle_inside_a_capsule_moves_out_with_only_tangential_relative_velocity():
    body = CapsuleBody([0.1])
    body.set_motion([[0, 0, 0]], [[0, 0, 1]], [[0.1, 0, 0]], [[0.1, 0, 1]], dt=1.0)  # moving +x at 0.1 m/s
    x = np.array([[0.12, 0.0, 0.5], [0.5, 0, 0.5], [0.5, 0.3, 0.5]])
    v = np.array([[-1.0, 0.3, 0.2], [0, 0, 0], [0, 0, 0]])
    x0, v0 = x.copy(), v.copy()
    resolve_contacts(x, v, np.array([[0, 1, 2]]), [body], 1.0, 0.005, np.array([True, False, False]))
    assert np.allclose(x[0], [0.1 + 0.1 + 0.005, 0, 0.5])  # at the surface plus the thickness
    assert np.allclose(v[0], [0.1, 0.3, 0.2])  # normal relative velocity gone, tangential kept
    assert np.array_equal(x[1:], x0[1:]) and np.array_equal(v[1:], v0[1:])  # not movable


def test_a_face_cut_by_a_capsule_moves_out_whole_though_its_corners_are_outside():
    body = CapsuleBody([0.05])
    body.set_motion([[0.0, -1.0, 0.0]], [[0.0, 1.0, 0.0]])  # a thin bar along y under the face
    x = np.array([[-0.5, -0.3, 0.02], [0.5, -0.3, 0.02], [0.3, 0.6, 0.02]])
    v = np.zeros_like(x)
    faces = np.array([[0, 1, 2]])
    before = x.copy()
    n_p, n_f = resolve_contacts(x, v, faces, [body], 1.0, 0.0, np.ones(3, bool))
    assert n_p == 0 and n_f == 1
    shift = x - before
    assert np.allclose(shift, shift[0]) and shift[0, 2] > 0.029  # moved up together
    samples = np.einsum("sk,kj->sj", np.random.default_rng(0).dirichlet([1, 1, 1], 500), x)
    assert capsule_depth(samples, body.a0, body.b0, body.radius).max() < 2e-3
    # without faces (a simulation's earlier substeps), the vertex case alone: the face stays cut
    x = before.copy()
    assert resolve_contacts(x, v, None, [body], 1.0, 0.0, np.ones(3, bool)) == (0, 0)
    assert np.array_equal(x, before)


def test_a_face_push_into_another_capsule_is_undone_unless_a_particle_pass_follows():
    """A face pushed up off a bar whose corner lands in a second capsule above it: the vertex
    case runs again on the corners the face moved; with again=False (the simulation, whose
    frame-end particle passes follow) that corner is left inside."""
    body = CapsuleBody([0.05, 0.05])
    # the bar under the face, and a second bar just above the corner 0 the push will carry up
    body.set_motion([[0.0, -1.0, 0.0], [-0.5, -1.0, 0.09]], [[0.0, 1.0, 0.0], [-0.5, 1.0, 0.09]])
    start = np.array([[-0.5, -0.3, 0.02], [0.5, -0.3, 0.02], [0.3, 0.6, 0.02]])  # 2 cm out of the upper bar
    moved = {}
    for again in (True, False):
        x, v = start.copy(), np.zeros_like(start)
        n_p, n_f = resolve_contacts(x, v, np.array([[0, 1, 2]]), [body], 1.0, 0.0, np.ones(3, bool), again=again)
        moved[again] = (n_p, n_f, capsule_depth(x, body.a0, body.b0, body.radius).max())
    assert moved[True][1] == moved[False][1] == 1
    assert moved[False][0] == 0 and moved[False][2] > 0.005  # the corner left inside the upper bar
    assert moved[True][0] == 1 and moved[True][2] < 1e-9  # pushed out again


def test_mesh_body_inside_outside_matches_the_capsules_it_tessellates():
    a = np.array([[0, 0, 0], [0.05, 0, 0.3]])
    b = np.array([[0, 0, 0.5], [0.4, 0, 0.3]])  # two overlapping capsules: a union of closed parts
    r = np.array([0.08, 0.06])
    verts, tris = [], []
    for k in range(2):
        v, t = capsule_mesh(a[k], b[k], r[k], segments=24, spacing=0.02)
        tris.append(t + sum(len(x) for x in verts))
        verts.append(v)
    verts, tris = np.vstack(verts), np.vstack(tris)
    body = MeshBody(tris, len(verts))
    body.set_motion(verts)
    rng = np.random.default_rng(4)
    pts = rng.uniform([-0.15, -0.15, -0.1], [0.5, 0.15, 0.6], size=(4000, 3))
    phi, normal, _ = body.query(pts, 1.0, max_distance=0.2)
    exact = capsule_depth(pts, a, b, r)
    inside_exact = exact > 0.004  # faceting: the mesh lies up to r(1 - cos(pi/24)) inside
    outside_exact = capsule_depth(pts, a, b, r + 0.004) == 0
    assert np.all(phi[inside_exact] < 0) and np.all(phi[outside_exact] > 0)
    deep = exact > 0.01
    assert np.allclose(-phi[deep], exact[deep], atol=0.004)


def test_mesh_body_batched_query_is_the_union_of_its_parts_queried_alone():
    """All parts are queried in one batch: the result is each point's smallest signed distance
    over the parts, with that part's normal and surface velocity."""
    a = np.array([[0, 0, 0], [0.05, 0, 0.3], [-0.05, 0.02, 0.1]])
    b = np.array([[0, 0, 0.5], [0.4, 0, 0.3], [-0.3, 0.02, -0.1]])
    r = np.array([0.08, 0.06, 0.05])
    parts = [capsule_mesh(a[k], b[k], r[k], segments=16, spacing=0.03) for k in range(3)]
    offsets = np.cumsum([0] + [len(v) for v, _ in parts])
    verts = np.vstack([v for v, _ in parts])
    tris = np.vstack([t + o for (_, t), o in zip(parts, offsets)])
    moved = verts + np.array([0.01, -0.02, 0.005])
    body = MeshBody(tris, len(verts))
    body.set_motion(verts, moved, 1 / 30)
    pts = np.random.default_rng(5).uniform([-0.35, -0.15, -0.2], [0.5, 0.15, 0.6], size=(3000, 3))
    phi, normal, vel = body.query(pts, 0.5)
    alone = []
    for k, (v, t) in enumerate(parts):
        part = MeshBody(t, len(v))
        part.set_motion(verts[offsets[k]:offsets[k + 1]], moved[offsets[k]:offsets[k + 1]], 1 / 30)
        alone.append(part.query(pts, 0.5))
    phis = np.array([q[0] for q in alone])
    best = np.argmin(phis, axis=0)
    cols = np.arange(len(pts))
    assert np.array_equal(phi, phis[best, cols])
    hit = phi < 0.05
    assert hit.sum() > 500
    assert np.allclose(normal[hit], np.array([q[1] for q in alone])[best, cols][hit])
    assert np.allclose(vel[hit], np.array([q[2] for q in alone])[best, cols][hit])


def _run_skirt(bodies_for, frames=60, **param_changes):
    mesh, pinned, capsules = walking_skirt()
    bodies = bodies_for(capsules)
    sim = ClothSimulation(mesh, preset("COTTON", **param_changes), pinned, bodies, level=2, fps=30)
    pin0 = mesh.rest[pinned]
    worst, stretch = 0.0, []
    for a1, b1 in walk(sim, pin0, capsules, bodies, frames):
        worst = max(worst, capsule_depth(sim.x, a1, b1, RADII).max())
        stretch.append(sim.stretch())
    return sim, worst, np.array(stretch)


def test_a_skirt_on_walking_capsules_stays_outside_and_keeps_its_size():
    sim, worst, stretch = _run_skirt(lambda caps: [caps])
    assert worst < 0.002  # no particle more than 2 mm inside the body on any frame
    assert np.abs(stretch).max() < 0.02  # mean edge length within 2 % of rest on every frame
    assert sim.contacts["particles"] + sim.contacts["faces"] > 0  # the legs did push it
    assert np.isfinite(sim.x).all() and np.abs(sim.v).max() < 20.0


def test_a_skirt_on_a_skinned_mesh_body_stays_outside():
    sim, worst, stretch = _run_skirt(lambda caps: [SkinnedLegs()], frames=45)
    # the mesh lies inside the exact capsules by its faceting (r (1 - cos(pi/20)) < 1.4 mm)
    assert worst < 0.002
    assert np.abs(stretch).max() < 0.02
    assert sim.contacts["particles"] + sim.contacts["faces"] > 0


def test_the_frame_end_pass_gets_particles_out_of_a_wedge_between_capsules(monkeypatch):
    """Where two capsules meet at a narrow angle (the thighs below the hips), a particle pushed
    out of one lands in the other. Pushed again along the crease (keeping out of the first to
    first order), two passes get every such particle out of both; pushed along each normal in
    turn, they zigzag down the crease: after 4 passes some are still centimetres deep, and it
    took FRAME_END_PASSES (16)."""
    from humananim.solver.cloth import collision
    from humananim.solver.cloth.collision import resolve_particles
    from humananim.solver.cloth.simulation import FRAME_END_PASSES
    rng = np.random.default_rng(0)
    spread = 0.25
    a = np.zeros((2, 3))
    b = 0.4 * np.array([[np.sin(spread), 0, -np.cos(spread)], [-np.sin(spread), 0, -np.cos(spread)]])
    body = CapsuleBody([0.07, 0.07])
    body.set_motion(a, b)
    pts = np.column_stack([rng.uniform(-0.05, 0.05, 2000), rng.uniform(-0.08, 0.08, 2000),
                           rng.uniform(-0.4, 0.0, 2000)])

    def deepest(passes):
        x, v = pts.copy(), np.zeros_like(pts)
        moved, phi = resolve_particles(x, v, [body], 1.0, 0.008, np.ones(len(x), bool), passes=passes)
        exact = capsule_depth(x, a, b, np.array([0.07, 0.07]))
        assert moved > 1000 and np.allclose(np.maximum(-phi, 0.0), exact, atol=1e-9)
        return exact.max()

    assert deepest(1) > 0.05 and deepest(2) == 0.0
    monkeypatch.setattr(collision, "CREASE_COSINE", 1.0)  # no crease: each normal in turn
    assert deepest(4) > 0.01 and deepest(FRAME_END_PASSES) == 0.0


def test_capsule_queries_match_the_direct_distances_near_and_on_the_axes():
    """phi, normals and surface velocities from the expanded (one product) distances equal the
    direct point-segment ones, for points far out, near the axes (where the expanded form loses
    digits: the direct length is used) and on them (any unit direction across)."""
    a0, b0 = np.array([[0.0, 0, 0], [0.2, 0, 0]]), np.array([[0.0, 0, 0.4], [0.2, 0.3, 0]])
    a1, b1 = a0 + [0.01, 0, 0], b0 + [0, 0.02, 0]
    body = CapsuleBody([0.05, 0.07])
    body.set_motion(a0, b0, a1, b1, 0.1)
    rng = np.random.default_rng(2)
    s = 0.5
    a, b = a0 + s * (a1 - a0), b0 + s * (b1 - b0)
    on_axis = a[0] + np.array([[0.0, 0, 0.1], [0, 0, 0.2]]) * [1, 1, 1]
    near_axis = on_axis + rng.normal(0, 1e-6, on_axis.shape)
    pts = np.vstack([rng.uniform(-0.2, 0.4, (200, 3)), on_axis, near_axis])
    phi, normal, velocity = body.query(pts, s, max_distance=10.0)
    q, t = closest_on_segments(pts[:, None], a[None], b[None])
    gaps = np.linalg.norm(pts[:, None] - q, axis=2) - body.radius
    k = gaps.argmin(axis=1)
    rows = np.arange(len(pts))
    assert np.allclose(phi, gaps[rows, k], atol=1e-9)
    assert np.allclose(np.linalg.norm(normal, axis=1), 1.0, atol=1e-12)
    off = np.linalg.norm(pts - q[rows, k], axis=1) > 1e-9
    direct = (pts - q[rows, k])[off] / np.linalg.norm(pts - q[rows, k], axis=1)[off, None]
    assert np.allclose(normal[off], direct, atol=1e-6)
    va, vb = (a1 - a0) / 0.1, (b1 - b0) / 0.1
    tk = t[rows, k]
    assert np.allclose(velocity, va[k] + tk[:, None] * (vb[k] - va[k]), atol=1e-12)
