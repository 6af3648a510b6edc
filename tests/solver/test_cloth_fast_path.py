"""The fast path (issue 7's speed aim): the per-frame work restructured for numpy's per-call cost
(bincount sums, precomputed smoothing map, cached capsule poses) computes what the plain formulas
compute. (The walking skirt's checks are in test_cloth_checks.py.)"""

import numpy as np

from cloth_scenes import RADII, legs, walking_skirt
from humananim.solver.cloth import Smoother
from humananim.solver.cloth.collision import closest_on_segments
from humananim.solver.cloth.smoothing import SUB_PATCHES, bernstein, pn_patch


def capsule_depth(points, a, b, r):
    q, _ = closest_on_segments(points[:, None], a[None], b[None])
    return np.maximum((r[None] - np.linalg.norm(points[:, None] - q, axis=2)).max(axis=1), 0.0)


def test_the_precomputed_surface_map_is_the_pn_triangles_of_the_sub_patches():
    """Every fine point equals the cubic Bezier (PN) patch built from its sub-patch's corners and
    normals, evaluated at its barycentric point: the map only reorders the arithmetic."""
    mesh, _, _ = walking_skirt()
    rng = np.random.default_rng(7)
    x = mesh.rest + rng.normal(0, 0.01, mesh.rest.shape)
    sm = Smoother(mesh, level=3, k_elastic=40.0)
    fine = sm.surface(x)
    last, t = sm.last, sm.tess
    pts = np.concatenate([x[mesh.faces], last["mid"][mesh.face_edges]], axis=1)
    nrm = np.concatenate([last["normals"][mesh.faces], last["mid_normals"][mesh.face_edges]], axis=1)
    cp = pn_patch(pts[:, SUB_PATCHES], nrm[:, SUB_PATCHES])  # (F, 4, 10, 3)
    direct = np.einsum("gc,fgcj->fgj", t.weights, cp[:, t.patch_of])  # (F, G, 3)
    assert np.allclose(fine[t.vertex_of], direct, atol=1e-12)
    assert np.array_equal(fine[:mesh.particle_count], x)
    # unchanged by the fast path: the weights in the tessellation are the Bernstein ones
    assert np.allclose(bernstein(np.array([[1.0, 0.0, 0.0]])), np.eye(10)[:1])


def test_pushes_out_of_overlapping_capsules_equal_the_generic_requery():
    """Against capsules alone, a pushed particle is queried again only when another capsule can
    be within the thickness after the push: the result equals querying every pushed particle
    again (the generic path, taken for a union of bodies)."""
    from humananim.solver.cloth import CapsuleBody
    from humananim.solver.cloth.collision import resolve_particles
    a, b = legs(0.3)
    near = CapsuleBody(RADII)
    near.set_motion(a, b)
    far = CapsuleBody([0.01])
    far.set_motion([[50.0, 0, 0]], [[50.0, 0, 1]])
    rng = np.random.default_rng(3)
    # points around the hips, where the hip, thigh and torso capsules overlap
    x = np.array([0.0, 0.0, 0.9]) + rng.uniform(-0.2, 0.2, (400, 3))
    v = rng.normal(0, 0.5, x.shape)
    results = []
    for bodies in ([near], [near, far]):
        xx, vv = x.copy(), v.copy()
        n, phi = resolve_particles(xx, vv, bodies, 1.0, 0.008, np.ones(len(x), bool))
        results.append((n, xx, vv, phi))
    (n1, x1, v1, phi1), (n2, x2, v2, phi2) = results
    assert n1 == n2 > 100
    assert np.allclose(x1, x2, atol=1e-12) and np.allclose(v1, v2, atol=1e-12)
    inside = phi2 < 0.15
    assert np.allclose(phi1[inside], phi2[inside], atol=1e-9)
    assert capsule_depth(x1, a, b, RADII).max() < 1e-9  # all out


def test_the_frames_last_phi_is_reused_only_while_nothing_moved():
    """The surface push and the depth reuse phi from the frame's last collision pass; once the
    body is given the next frame's motion, a fresh query answers."""
    mesh, pinned, capsules = walking_skirt()
    from humananim.solver.cloth import ClothSimulation, preset
    sim = ClothSimulation(mesh, preset("COTTON"), pinned, [capsules], level=2, fps=30)
    a0, b0 = legs(0.0)
    for f in range(1, 6):
        a1, b1 = legs(f / 30.0)
        capsules.set_motion(a0, b0, a1, b1, 1 / 30)
        sim.step(mesh.rest[pinned], 1 / 30)
        a0, b0 = a1, b1
    fresh = np.maximum(-capsules.query(sim.x, 1.0)[0], 0.0)
    assert np.allclose(sim.depth_inside(), fresh, atol=1e-12)
    a2, b2 = legs(0.6)  # the legs jump 6 cm into the skirt: the next frame's motion
    capsules.set_motion(a0, b0, a2, b2, 1 / 30)
    moved = np.maximum(-capsules.query(sim.x, 1.0)[0], 0.0)
    assert moved.max() > 0.01 and np.allclose(sim.depth_inside(), moved)


def test_kept_output_products_and_edge_differences_equal_scipys():
    """The hot loops' products into kept outputs equal scipy's, with or without the compiled
    kernel; the difference matrix gives x[second] - x[first] bit for bit (what the springs, the
    Provot sweeps and the damping took before); the clip ufunc is np.clip."""
    from scipy import sparse
    from humananim.solver.cloth import fast
    rng = np.random.default_rng(5)
    m = sparse.random(30, 20, density=0.3, random_state=4, format="csr")
    dense = rng.normal(size=(20, 4))
    first, second = rng.integers(0, 20, 50), rng.integers(0, 20, 50)
    keep = first != second
    first, second = first[keep], second[keep]
    x = rng.normal(size=(20, 3))
    product = fast.Product(m, 4)
    assert np.allclose(product(dense), m @ dense, atol=1e-14)
    assert np.allclose(product(2.0 * dense), 2.0 * (m @ dense), atol=1e-14)  # the output is reused
    target = np.full((30, 4), 7.0)
    assert product.into(dense, target) is target and np.allclose(target, m @ dense, atol=1e-14)
    diff = fast.Product(fast.difference_matrix(first, second, 20), 3)
    assert np.array_equal(diff(x), x[second] - x[first])
    assert np.allclose(fast.rowdot(dense, dense), (dense * dense).sum(axis=1))
