"""The coarse cloth mesh: particles grouped into triangles, with the topology the simulation and
the smoothing share (edges, the faces on each side of an edge, bending pairs, particle areas)."""

from dataclasses import dataclass

import numpy as np
from scipy import sparse

from ..errors import HumanAnimError
from .fast import dot


class ClothError(HumanAnimError):
    """The garment or the cloth settings cannot be used."""


@dataclass
class ClothMesh:
    rest: np.ndarray  # (P, 3) rest positions, metres
    faces: np.ndarray  # (F, 3) particle indices, consistently wound
    edges: np.ndarray  # (E, 2) particle indices, i < j
    rest_length: np.ndarray  # (E,)
    edge_faces: np.ndarray  # (E, 2) the faces on each side, -1 on a border
    face_edges: np.ndarray  # (F, 3) edge of the face's sides (a,b), (b,c), (c,a)
    bend_pairs: np.ndarray  # (B, 2) particles opposite an inner edge, one spring per adjacent face pair
    bend_rest: np.ndarray  # (B,)
    area: np.ndarray  # (P,) a third of the area of each adjacent face
    incidence: sparse.csr_matrix  # (P, E): +1 at the first particle, -1 at the second

    @property
    def particle_count(self):
        return len(self.rest)


def build_mesh(rest, faces):
    """Topology of a triangle mesh; refuses non-manifold edges and degenerate faces."""
    rest = np.asarray(rest, float)
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    p = len(rest)
    if p < 3 or len(faces) == 0:
        raise ClothError("the garment needs at least one triangle")
    if faces.min() < 0 or faces.max() >= p:
        raise ClothError("a face refers to a vertex that does not exist")
    sides = np.stack([faces, np.roll(faces, -1, axis=1)], axis=-1).reshape(-1, 2)  # (3F, 2): (a,b),(b,c),(c,a)
    lo, hi = sides.min(axis=1), sides.max(axis=1)
    if np.any(lo == hi):
        raise ClothError("the garment has a degenerate face (a repeated vertex)")
    keys, edge_of_side, counts = np.unique(lo * p + hi, return_inverse=True, return_counts=True)
    edge_of_side = edge_of_side.ravel()
    if counts.max() > 2:
        raise ClothError("the garment has an edge shared by more than two faces: use a manifold mesh")
    edges = np.column_stack([keys // p, keys % p])
    face_of_side = np.repeat(np.arange(len(faces)), 3)
    order = np.argsort(edge_of_side, kind="stable")
    edge_faces = np.full((len(edges), 2), -1, dtype=np.int64)
    first = np.ones(len(order), dtype=bool)
    first[1:] = edge_of_side[order][1:] != edge_of_side[order][:-1]
    edge_faces[edge_of_side[order][first], 0] = face_of_side[order][first]
    edge_faces[edge_of_side[order][~first], 1] = face_of_side[order][~first]
    face_edges = edge_of_side.reshape(-1, 3)
    rest_length = np.linalg.norm(rest[edges[:, 1]] - rest[edges[:, 0]], axis=1)
    if np.any(rest_length <= 1e-9):
        raise ClothError("the garment has a zero-length edge: merge the doubled vertices")
    # the particle of each face that is not on the shared edge
    inner = np.flatnonzero(edge_faces[:, 1] >= 0)
    opposite = np.empty((len(inner), 2), dtype=np.int64)
    for side in range(2):
        f = faces[edge_faces[inner, side]]
        on_edge = (f == edges[inner, 0:1]) | (f == edges[inner, 1:2])
        opposite[:, side] = f[~on_edge]
    bend_rest = np.linalg.norm(rest[opposite[:, 1]] - rest[opposite[:, 0]], axis=1)
    keep = bend_rest > 1e-9
    a, b, c = rest[faces[:, 0]], rest[faces[:, 1]], rest[faces[:, 2]]
    face_area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    if np.any(face_area <= 1e-12):
        raise ClothError("the garment has a face with no area")
    area = np.bincount(faces.ravel(), np.repeat(face_area / 3.0, 3), minlength=p)
    e = len(edges)
    incidence = sparse.csr_matrix((np.r_[np.ones(e), -np.ones(e)], (edges.T.ravel(), np.r_[np.arange(e), np.arange(e)])),
                                  shape=(p, e))
    return ClothMesh(rest, faces, edges, rest_length, edge_faces, face_edges, opposite[keep], bend_rest[keep],
                     area, incidence)


def face_cross(x, faces):
    """Per face (F, 3) the cross product of its two sides from its first corner: the normal times
    twice the area."""
    tri = x[faces]  # (F, 3 corners, 3)
    return np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])


def face_normals(x, faces):
    """Unit normals (F, 3) and areas (F,) of the flat faces."""
    n = face_cross(x, faces)
    length = np.sqrt(dot(n, n))
    return n / np.maximum(length, 1e-12)[:, None], 0.5 * length


def edge_lengths(mesh, x):
    return np.linalg.norm(x[mesh.edges[:, 1]] - x[mesh.edges[:, 0]], axis=1)
