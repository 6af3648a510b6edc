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
