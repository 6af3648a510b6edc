"""Compression by keeping only the coarser levels of the pyramid (Huang 1996 section 5.5).

Dropping the d finest bands leaves G_d, one sample every 2^d frames; the curve it stands for is
EXPAND^d(G_d), the reconstruction with zero gains on L_0..L_{d-1}. As keys, that curve is written
at its own samples on the level-d grid (values and slopes of the reconstruction there) joined
by cubic Hermite segments; `pyramid_keys` picks, per channel, the coarsest level whose keyed
curve stays within the tolerance on every frame.
"""

import numpy as np
from scipy.interpolate import CubicHermiteSpline

from .key_reduction import hermite_keys
from .pyramid import DEFAULT_A, expand, gaussian_pyramid, max_levels


def coarse_curve(x, drop, a=DEFAULT_A):
    """(G_drop, EXPAND^drop(G_drop)) of x (F, ...): the kept coarse samples and the full-rate
    curve they reconstruct on the extended grid (cut [:F] for the clip's frames)."""
    g = gaussian_pyramid(x, drop, a)
    dense = g[-1]
    for _ in range(drop):
        dense = expand(dense, a)
    return g[-1], dense


def compress(x, drop, a=DEFAULT_A):
    """The thesis' compression: x with its `drop` finest bands removed, (F, ...)."""
    return coarse_curve(np.asarray(x, dtype=float), drop, a)[1][:len(x)]


def _grid_keys(times, dense, drop):
    step = 2 ** drop
    n = len(times)
    last = -(-(n - 1) // step) * step  # first grid sample at or after the clip's last frame
    idx = np.arange(0, last + 1, step)
    dt = times[1] - times[0] if n > 1 else 1.0
    t_ext = times[0] + dt * np.arange(len(dense))
    slopes = np.gradient(dense, t_ext, axis=0)
    return idx, t_ext, slopes


def pyramid_keys(times, x, tolerance, a=DEFAULT_A, max_drop=None):
    """Per channel of x (F, C), Keys on the coarsest pyramid grid whose Hermite curve is within
    `tolerance` (scalar or (C,)) of every sample, and the number of bands dropped (C,)."""
    times = np.asarray(times, dtype=float)
    x = np.asarray(x, dtype=float)
    tol = np.broadcast_to(np.asarray(tolerance, dtype=float), x.shape[1:])
    max_drop = max_levels(len(x)) if max_drop is None else max_drop
    best = np.zeros(x.shape[1], dtype=int)
    for drop in range(1, max_drop + 1):
        _, dense = coarse_curve(x, drop, a)
        idx, t_ext, slopes = _grid_keys(times, dense, drop)
        curve = CubicHermiteSpline(t_ext[idx], dense[idx], slopes[idx], axis=0)(times)
        ok = np.abs(curve - x).max(axis=0) <= tol
        best[ok] = drop
    keys = []
    for c in range(x.shape[1]):
        if best[c] == 0:
            keys.append(hermite_keys(times, x[:, c]))
            continue
        _, dense = coarse_curve(x[:, c], best[c], a)
        idx, t_ext, slopes = _grid_keys(times, dense, best[c])
        keys.append(hermite_keys(t_ext[idx], dense[idx], slopes[idx]))
    return keys, best
