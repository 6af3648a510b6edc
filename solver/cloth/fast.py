"""Small helpers for the cloth's hot loops, where numpy's per-call cost dominates."""

import os

import numpy as np

# numpy's and scipy's compiled entry points below (c_einsum, the clip ufunc, csr_matvecs) are
# private: each has the public call as its fallback, used when the import fails or when
# HUMANANIM_PUBLIC_NUMPY=1 (tests/solver/test_cloth_public_numpy.py runs both; docs/cloth.md
# has the measurement that keeps them: the simulation and smoothing 20-30 % faster)
PUBLIC_ONLY = os.environ.get("HUMANANIM_PUBLIC_NUMPY", "") not in ("", "0")

_c_einsum = np.einsum
if not PUBLIC_ONLY:
    try:  # np.einsum's Python front end costs as much as the sum itself on a few hundred rows
        from numpy._core.multiarray import c_einsum as _c_einsum
    except ImportError:  # numpy < 2
        try:
            from numpy.core.multiarray import c_einsum as _c_einsum
        except ImportError:
            _c_einsum = np.einsum


def dot(a, b):
    """Dot products over the last axis of (..., k) arrays: np.einsum("...i,...i->...", a, b)."""
    return _c_einsum("...i,...i->...", a, b)


def rowdot(a, b):
    """Row-wise dot products of two (N, 3) arrays: np.einsum("ij,ij->i", a, b)."""
    return _c_einsum("ij,ij->i", a, b)


_csr_matvecs = None
clip = np.clip
if not PUBLIC_ONLY:
    try:  # scipy's compiled CSR times dense kernel, without the sparse matrix's Python dispatch
        from scipy.sparse._sparsetools import csr_matvecs as _csr_matvecs
    except ImportError:
        _csr_matvecs = None
    try:  # the clip ufunc itself: np.clip's Python front end costs more than the clip
        from numpy._core.umath import clip as clip
    except ImportError:  # numpy < 2
        try:
            from numpy.core.umath import clip as clip
        except ImportError:
            clip = np.clip


class Product:
    """`matrix @ dense` for one fixed CSR matrix and (N, cols) C-contiguous float64 operands, into
    an output kept between calls (overwritten by the next call: use it before calling again).
    The hot loops call a few such products tens of times a frame: what a sparse product looks
    up per call (shapes, index arrays, scipy's dispatch) is bound once here."""

    def __init__(self, matrix, cols):
        matrix = matrix.tocsr()
        m, n = matrix.shape
        self.matrix, self.cols = matrix, cols
        self.out = np.zeros((m, cols))
        self._flat = self.out.ravel()
        self._args = (m, n, cols, matrix.indptr, matrix.indices, matrix.data)

    def __call__(self, dense):
        return self._product(dense, self.out, self._flat)

    def into(self, dense, out):
        """The product written into `out` (a C-contiguous (rows, cols) array) instead."""
        return self._product(dense, out, out.reshape(-1))

    def _product(self, dense, out, flat):  # flat: out's data as one row
        if _csr_matvecs is None:
            out[...] = self.matrix @ dense
            return out
        flat.fill(0.0)
        _csr_matvecs(*self._args, dense.ravel(), flat)
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
