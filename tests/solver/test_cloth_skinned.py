"""SkinnedBody (issue 29): collision with a skinned mesh searched in its bones' reference frames,
checked against brute force (every triangle) and the generalized winding number on a bent,
skinned leg."""

import numpy as np

from humananim.solver.cloth import capsule_mesh
from humananim.solver.cloth.collision import closest_on_triangles
from humananim.solver.cloth.skinned import DEEP, NEAR, SkinnedBody


# where skinning blends two bones the point carried into a bone's frame is a little off, and its
# cell's candidates can miss the nearest triangle (a neighbour's distance is taken): rarely, and
# by a few millimetres at most on this leg bent at the knee
MISS = 1e-6


def rotation_x(angle):
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def bones(knee_angle, hip_angle=0.0, shift=(0.0, 0.0, 0.0)):
    """Two bones' world matrices: a thigh from (0, 0, 1) down to a knee at (0, 0, 0.55), a shin
    below it; the thigh turned by hip_angle, the shin by knee_angle more (about x)."""
    thigh = np.eye(4)
    thigh[:3, :3] = rotation_x(hip_angle)
    thigh[:3, 3] = np.array([0.0, 0.0, 1.0]) + shift
    shin = np.eye(4)
    shin[:3, :3] = rotation_x(hip_angle + knee_angle)
    shin[:3, 3] = thigh[:3, 3] + thigh[:3, :3] @ [0.0, 0.0, -0.45]
    return np.array([thigh, shin])


def skinned_leg():
    """A capsule mesh from the hip to the ankle (the reference pose, straight), weights blending
    over 8 cm at the knee."""
    verts, tris = capsule_mesh([0.0, 0.0, 1.0], [0.0, 0.0, 0.1], 0.06, segments=24, spacing=0.015)
    t = np.clip((0.55 - verts[:, 2]) / 0.08 + 0.5, 0.0, 1.0)
    weights = np.column_stack([1.0 - t, t])
    return verts, tris, weights


def pose(verts, weights, reference, posed):
    """Linear blend skinning of the reference vertices to the posed bones."""
    h = np.c_[verts, np.ones(len(verts))]
    out = np.zeros_like(verts)
    for j in range(len(posed)):
        m = posed[j] @ np.linalg.inv(reference[j])
        out += weights[:, j:j + 1] * (h @ m.T)[:, :3]
    return out


def brute_force(points, verts, tris):
    """Unsigned distance to every triangle, and the generalized winding number (1 inside)."""
    a, b, c = verts[tris[:, 0]], verts[tris[:, 1]], verts[tris[:, 2]]
    dist = np.empty(len(points))
    wind = np.empty(len(points))
    for i, p in enumerate(points):
        q, _ = closest_on_triangles(p[None], a, b, c)
        dist[i] = np.sqrt(((p - q) ** 2).sum(axis=1)).min()
        x, y, z = a - p, b - p, c - p
        lx, ly, lz = (np.linalg.norm(v, axis=1) for v in (x, y, z))
        num = np.einsum("ij,ij->i", x, np.cross(y, z))
        den = (lx * ly * lz + np.einsum("ij,ij->i", x, y) * lz + np.einsum("ij,ij->i", y, z) * lx
               + np.einsum("ij,ij->i", z, x) * ly)
        wind[i] = 2.0 * np.arctan2(num, den).sum() / (4.0 * np.pi)
    return dist, wind


def near_surface_points(verts, rng, count, spread):
    """Points scattered around the skin's vertices (within `spread` metres)."""
    base = verts[rng.integers(0, len(verts), count)]
    return base + rng.normal(0.0, spread / 2.0, (count, 3))


def test_skinned_body_matches_brute_force_on_a_bent_leg():
    verts, tris, weights = skinned_leg()
    reference = bones(0.0)
    body = SkinnedBody(tris, verts, reference, weights)
    rng = np.random.default_rng(3)
    for knee, hip, shift in ((0.0, 0.0, (0, 0, 0)), (0.6, 0.3, (0.2, 0.1, 0.0)), (0.9, -0.4, (0.0, 0.5, 0.1))):
        posed = bones(knee, hip, np.array(shift))
        v = pose(verts, weights, reference, posed)
        body.set_motion(v, posed)
        points = near_surface_points(v, rng, 300, 0.03)
        phi, normal, velocity = body.query(points, 1.0)
        dist, wind = brute_force(points, v, tris)
        inside = wind > 0.5
        exact = dist < NEAR
        truth = np.where(inside, -dist, dist)
        # near the surface: the exact signed distance, the normal a unit vector
        error = np.abs(phi[exact] - truth[exact])
        assert np.mean(error < 1e-9) > 0.98 and error.max() < MISS, (knee, hip)
        assert np.allclose(np.linalg.norm(normal, axis=1), 1.0)
        # farther: a lower bound of the distance outside, never "outside" for a point inside
        assert (phi[~exact & ~inside] <= truth[~exact & ~inside] + 1e-9).all()
        assert (phi[inside & (dist < DEEP)] < 0.0).all()
        assert np.allclose(velocity, 0.0)  # (no motion within the frame)


def test_skinned_body_velocity_and_interpolation_within_the_frame():
    verts, tris, weights = skinned_leg()
    reference = bones(0.0)
    body = SkinnedBody(tris, verts, reference, weights)
    start, end = bones(0.2), bones(0.2, shift=np.array([0.03, 0.0, 0.0]))  # the leg slides 3 cm in x
    v0, v1 = pose(verts, weights, reference, start), pose(verts, weights, reference, end)
    body.set_motion(v0, start, v1, end, dt=0.1)
    rng = np.random.default_rng(5)
    points = near_surface_points(v0, rng, 200, 0.02)
    phi, _, velocity = body.query(points, 0.5)
    dist, wind = brute_force(points, 0.5 * (v0 + v1), tris)
    exact = dist < NEAR
    truth = np.where(wind > 0.5, -dist, dist)
    error = np.abs(phi[exact] - truth[exact])
    assert np.mean(error < 1e-9) > 0.98 and error.max() < MISS
    touching = exact & (np.abs(phi) < 0.01)
    assert touching.sum() > 10 and np.allclose(velocity[touching], [0.3, 0.0, 0.0], atol=1e-9)


def test_far_points_and_points_outside_every_grid():
    verts, tris, weights = skinned_leg()
    reference = bones(0.0)
    body = SkinnedBody(tris, verts, reference, weights)
    body.set_motion(verts, reference)
    far = np.array([[0.0, 0.0, 3.0], [1.0, 1.0, 0.5], [0.0, 0.3, 0.5]])
    phi, normal, _ = body.query(far, 1.0, max_distance=0.05)
    assert np.all(phi == 0.05) and np.allclose(normal, [0.0, 0.0, 1.0])
    assert len(body.query(np.zeros((0, 3)), 1.0)[0]) == 0


def test_the_sphere_stage_keeps_what_evaluating_every_candidate_finds():
    """The bounding spheres only drop candidates that cannot hold the nearest point: the same
    distances, normals and velocities as the exact stage over every candidate of every row."""
    verts, tris, weights = skinned_leg()
    reference = bones(0.0)
    rng = np.random.default_rng(11)
    start, end = bones(0.7, 0.2), bones(0.8, 0.25, np.array([0.02, 0.0, 0.0]))
    v0, v1 = pose(verts, weights, reference, start), pose(verts, weights, reference, end)
    points = near_surface_points(v1, rng, 400, 0.04)
    out = []
    for prune in (True, False):
        body = SkinnedBody(tris, verts, reference, weights)
        if not prune:
            body._spheres = lambda points, rows, ids, valid, s: (rows, ids, valid, np.zeros(len(rows)))
        body.set_motion(v0, start, v1, end, dt=1 / 30)
        out.append(body.query(points, 0.5))
    (phi, normal, velocity), (phi_all, normal_all, velocity_all) = out
    exact = phi_all < NEAR
    assert exact.sum() > 100
    assert np.allclose(phi[exact], phi_all[exact], atol=1e-12)
    assert np.allclose(normal[exact], normal_all[exact], atol=1e-9)
    assert np.allclose(velocity[exact], velocity_all[exact], atol=1e-9)
    assert (phi[~exact] <= phi_all[~exact] + 1e-12).all()  # farther: a lower bound, as before


def test_the_fold_check_keeps_the_inside_of_a_sharply_bent_knee():
    """Points found inside are checked in the unfolded reference pose, carried there by their
    triangle's bones (a fold at a bent joint can make the nearest face face away from a point
    that is outside: on the Bandai Namco dance, tests/addon/test_cloth_skinned_body.py). Bent
    far (2.4 rad), the blended skin behind the knee is where that check could lose real
    penetrations: no point outside is reported inside, and the points inside still are (brute
    force and the generalized winding number as the independent reference)."""
    verts, tris, weights = skinned_leg()
    reference = bones(0.0)
    posed = bones(2.4)
    v = pose(verts, weights, reference, posed)
    rng = np.random.default_rng(17)
    knee = v[np.abs(verts[:, 2] - 0.55) < 0.08]  # the skin around the knee
    points = near_surface_points(knee, rng, 600, 0.03)
    dist, wind = brute_force(points, v, tris)
    inside = wind > 0.5
    from humananim.solver.cloth import skinned
    found = []
    for check in (False, True):
        body = SkinnedBody(tris, verts, reference, weights)
        body.set_motion(v, posed)
        skinned.FOLD_CHECK = check
        try:
            phi = body.query(points, 1.0)[0]
        finally:
            skinned.FOLD_CHECK = True
        assert not ((phi < 0.0) & ~inside).any()
        found.append((phi < 0.0)[inside & (dist < DEEP)])
    # (bent this far, a third of the points inside within DEEP are missed with or without the
    # check: the candidates carried from the straight leg miss the folded skin; docs/cloth.md)
    assert len(found[1]) > 100 and found[1].mean() >= found[0].mean() - 0.01 and found[1].mean() > 0.6
