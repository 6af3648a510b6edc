"""Mass, centre of mass and inertia of closed triangle meshes by polyhedral integrals.

Each triangle and the origin span a signed tetrahedron; summing their exact integrals gives
the integrals over the enclosed volume (the divergence-theorem form of Mirtich 1996).
"""

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

# Canonical second moment of the tetrahedron (0, e1, e2, e3) scaled by its determinant.
_CANONICAL = np.full((3, 3), 1.0 / 120.0) + np.eye(3) / 120.0


def mesh_mass_properties(vertices, triangles, density=1.0):
    """(mass, centre of mass (3,), inertia about the centre (3, 3)) of a closed, consistently
    oriented triangle mesh. An inside-out mesh is handled by the sign of the volume."""
    v = np.asarray(vertices, dtype=float)
    t = np.asarray(triangles, dtype=int)
    a, b, c = v[t[:, 0]], v[t[:, 1]], v[t[:, 2]]
    det = np.einsum("ij,ij->i", a, np.cross(b, c))
    volume = det.sum() / 6.0
    if abs(volume) < 1e-15:
        return 0.0, np.zeros(3), np.zeros((3, 3))
    centroid = (det[:, None] * (a + b + c)).sum(axis=0) / 24.0 / volume
    # covariance about the origin: sum over tetrahedra A C A^T det, A = [a b c]
    corners = np.stack((a, b, c), axis=2)  # (T, 3, 3) columns a, b, c
    cov = np.einsum("t,tij,jk,tlk->il", det, corners, _CANONICAL, corners)
    mass = density * volume
    cov = density * cov - mass * np.outer(centroid, centroid)
    inertia = np.trace(cov) * np.eye(3) - cov
    if mass < 0.0:
        mass, inertia = -mass, -inertia
    return float(mass), centroid, inertia


def cap_holes(triangles):
    """Close the open boundary loops of a triangle set with fans to each loop's centroid.

    Returns (triangles with caps, extra vertex indices as (loop_vertex_indices) lists); the
    caller appends one vertex per loop at the centroid of that loop's vertices."""
    t = np.asarray(triangles, dtype=int)
    edges = np.concatenate((t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]))
    key = np.sort(edges, axis=1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    boundary = edges[counts[inverse.ravel()] == 1]
    if len(boundary) == 0:
        return t, []
    nodes, local = np.unique(boundary, return_inverse=True)
    local = local.reshape(-1, 2)
    graph = coo_matrix((np.ones(len(local)), (local[:, 0], local[:, 1])), shape=(len(nodes),) * 2)
    n_loops, label = connected_components(graph, directed=False)
    loops = [nodes[label == k] for k in range(n_loops)]
    edge_loop = label[local[:, 0]]
    # a boundary edge a->b of a face is capped by b->a->centre: orientation stays consistent
    centre_index = -1 - edge_loop  # placeholders resolved by the caller's vertex append
    caps = np.stack((boundary[:, 1], boundary[:, 0], centre_index), axis=1)
    return np.concatenate((t, caps)), loops


def closed_mass_properties(vertices, triangles, density=1.0):
    """Mass properties of a possibly open surface piece, its holes capped first."""
    v = np.asarray(vertices, dtype=float)
    tris, loops = cap_holes(triangles)
    if loops:
        centres = np.array([v[loop].mean(axis=0) for loop in loops])
        tris = tris.copy()
        cap = tris[:, 2] < 0
        tris[cap, 2] = len(v) + (-1 - tris[cap, 2])
        v = np.concatenate((v, centres))
    return mesh_mass_properties(v, tris, density)


def box_mesh(size, centre=(0.0, 0.0, 0.0)):
    """An outward-oriented box (vertices, triangles): a test shape with known integrals."""
    s = 0.5 * np.asarray(size, dtype=float)
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    tris = [(q[0], q[1], q[2]) for q in quads] + [(q[0], q[2], q[3]) for q in quads]
    return corners * s + np.asarray(centre, float), np.array(tris)
