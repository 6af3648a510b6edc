"""The fast path (issue 7's speed aim): the per-frame work restructured for numpy's per-call cost
(bincount sums, precomputed smoothing map, cached capsule poses, one joint tree for a skinned
body's parts) gives the same cloth as the implementation before it, and nothing enters the body."""

import os

import numpy as np
import pytest

from cloth_scenes import RADII, legs, reference_walk, walking_skirt
from humananim.solver.cloth import Smoother
from humananim.solver.cloth.collision import closest_on_segments
from humananim.solver.cloth.smoothing import SUB_PATCHES, bernstein, pn_patch

REFERENCE = os.path.join(os.path.dirname(__file__), "cloth_reference.npz")


def capsule_depth(points, a, b, r):
    q, _ = closest_on_segments(points[:, None], a[None], b[None])
    return np.maximum((r[None] - np.linalg.norm(points[:, None] - q, axis=2)).max(axis=1), 0.0)


@pytest.mark.parametrize("collider", ["capsules", "mesh"])
def test_the_fast_path_gives_the_previous_cloth_and_nothing_enters_the_body(collider):
    ref = np.load(REFERENCE)
    xs, fine, sim = reference_walk(collider, frames=20)
    assert sim.contacts["particles"] + sim.contacts["faces"] > 100  # the legs pushed it all along
    # same particles on every frame (bit for bit on numpy 1.26; rounding of other numpy builds
    # stays far below this) and the same fine surface
    assert np.abs(xs - ref[f"{collider}_particles"]).max() < 1e-6
    assert np.abs(fine - ref[f"{collider}_fine"]).max() < 1e-6
    for f in range(1, len(xs)):
        a, b = legs(f / 30.0)
        # the mesh lies inside the exact capsules by its faceting (< 1.4 mm)
        assert capsule_depth(xs[f], a, b, RADII).max() < 0.002
    a, b = legs(20 / 30.0)
    assert capsule_depth(fine, a, b, RADII).max() < 0.002  # the rendered surface too


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
