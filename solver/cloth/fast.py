"""Small helpers for the cloth's hot loops: dot products, fixed sparse products, corner sums."""

import numpy as np


def dot(a, b):
    """Dot products over the last axis of (..., k) arrays."""
    return np.einsum("...i,...i->...", a, b)


def rowdot(a, b):
    """Row-wise dot products of two (N, 3) arrays."""
    return np.einsum("ij,ij->i", a, b)


class Product:
    """`matrix @ dense` for one fixed CSR matrix and (N, cols) C-contiguous float64 operands, into
    an output kept between calls (overwritten by the next call: use it before calling again).
    The hot loops call a few such products tens of times a frame, into outputs they keep."""

    def __init__(self, matrix, cols):
        matrix = matrix.tocsr()
        self.matrix, self.cols = matrix, cols
        self.out = np.zeros((matrix.shape[0], cols))

    def __call__(self, dense):
        return self.into(dense, self.out)

    def into(self, dense, out):
        """The product written into `out` (a C-contiguous (rows, cols) array) instead."""
        out[...] = self.matrix @ dense
        return out


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
    sum at each particle, as one np.bincount (corners in ascending order per particle, as the
    sparse product it replaces)."""

    def __init__(self, faces, particles):
        self.idx = (3 * faces.ravel()[:, None] + np.arange(3)).ravel()
        self.size = 3 * particles

    def __matmul__(self, values):
        return np.bincount(self.idx, values.ravel(), minlength=self.size).reshape(-1, 3)
