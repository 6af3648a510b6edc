"""Small helpers for the cloth's loops: dot products, fixed sparse products, corner sums."""

import numpy as np


def dot(a, b):
    """Dot products over the last axis of (..., k) arrays."""
    return np.einsum("...i,...i->...", a, b)


def rowdot(a, b):
    """Row-wise dot products of two (N, 3) arrays."""
    return np.einsum("ij,ij->i", a, b)


class Product:
    """`matrix @ dense` for one fixed CSR matrix, made once (the hot loops call a few such
    products tens of times a frame)."""

    def __init__(self, matrix, cols):
        self.matrix, self.cols = matrix.tocsr(), cols

    def __call__(self, dense):
        return self.matrix @ dense

    def into(self, dense, out):
        """The product written into `out` (a (rows, cols) array) instead."""
        out[...] = self.matrix @ dense
        return out


class IndexDifference:
    """x[second] - x[first] for rows x (a spring's or an edge's vector from its two particles)."""

    def __init__(self, first, second):
        self.first, self.second = np.asarray(first), np.asarray(second)

    def __call__(self, x):
        return x[self.second] - x[self.first]


def difference_matrix(first, second, count):
    """(S, count) CSR: row s is -1 at first[s], +1 at second[s], so `D @ x` is x[second] - x[first]
    (bit for bit: -a + b is b - a in floating point)."""
    from scipy import sparse
    s = len(first)
    rows = np.r_[np.arange(s), np.arange(s)]
    m = sparse.csr_matrix((np.r_[-np.ones(s), np.ones(s)], (rows, np.r_[first, second])), shape=(s, count))
    m.sort_indices()
    return m


class CornerSum:
    """`gather @ values` for values (3F, 3) per face corner (faces (F, 3) of particle indices): the
    sum at each particle, np.add.at over the corners."""

    def __init__(self, faces, particles):
        self.corners, self.particles = np.asarray(faces).ravel(), particles

    def __matmul__(self, values):
        out = np.zeros((self.particles, 3))
        np.add.at(out, self.corners, values)
        return out
