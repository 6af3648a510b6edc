"""Small helpers for the cloth's hot loops, where numpy's per-call cost dominates."""

import numpy as np

try:  # np.einsum's Python front end costs as much as the sum itself on a few hundred rows
    from numpy._core.multiarray import c_einsum as _c_einsum
except ImportError:  # numpy < 1.26
    try:
        from numpy.core.multiarray import c_einsum as _c_einsum
    except ImportError:
        _c_einsum = np.einsum


def rowdot(a, b):
    """Row-wise dot products of two (N, 3) arrays: np.einsum("ij,ij->i", a, b)."""
    return _c_einsum("ij,ij->i", a, b)


try:  # scipy's compiled CSR times dense kernel, without the sparse matrix's Python dispatch
    from scipy.sparse._sparsetools import csr_matvecs as _csr_matvecs
except ImportError:
    _csr_matvecs = None


def sparse_product(matrix, dense):
    """matrix (CSR, float64) @ dense (C-contiguous (N, K) float64): (M, K)."""
    if _csr_matvecs is None:
        return matrix @ dense
    m, n = matrix.shape
    out = np.zeros((m, dense.shape[1]))
    _csr_matvecs(m, n, dense.shape[1], matrix.indptr, matrix.indices, matrix.data, dense.ravel(), out.ravel())
    return out
