"""A motion equalizer: reconstruction from the Laplacian pyramid with a gain per band (Huang eq. 5-9).

G_0' = w_L G_L + sum_l w_l L_l. Gains of one give the input back; gains of zero on the finest
bands remove capture jitter (a low-pass filter whose corner halves with each band); gains above
one on the middle bands exaggerate the motion while its mean pose (the top) is kept.
"""

import numpy as np

from . import channels as _channels
from .pyramid import DEFAULT_A, band_limits_hz, laplacian_pyramid, max_levels, reconstruct


def equalize(x, gains, levels=None, a=DEFAULT_A):
    """x (F, ...) reconstructed with `gains`: a sequence of L + 1 (finest band first, top last,
    each a scalar or per channel), or a dict {band index: gain} (missing bands 1, the top is
    index L or -1). `levels` default len(gains) - 1 for a sequence, a full pyramid for a dict."""
    x = np.asarray(x, dtype=float)
    if isinstance(gains, dict):
        levels = max_levels(len(x)) if levels is None else levels
        full = [1.0] * (levels + 1)
        for band, gain in gains.items():
            full[band] = gain
        gains = full
    levels = len(gains) - 1 if levels is None else levels
    return reconstruct(laplacian_pyramid(x, levels, a), gains)


def low_pass_gains(fps, cutoff_hz, levels):
    """Gains that remove every band lying wholly above `cutoff_hz` (0) and keep the rest (1)."""
    return [0.0 if low >= cutoff_hz else 1.0 for low, _ in band_limits_hz(fps, levels)]


def denoise(x, fps, cutoff_hz=10.0, levels=None, a=DEFAULT_A):
    """Remove capture jitter: drop the bands above `cutoff_hz` (default 10 Hz)."""
    levels = max_levels(len(x)) if levels is None else levels
    return equalize(x, low_pass_gains(fps, cutoff_hz, levels), levels, a)


def equalize_quaternions(q, gains, levels=None, a=DEFAULT_A, reference=None):
    """Band gains on quaternion curves (F, ..., 4) in the tangent space; unit, same hemisphere."""
    return _channels.filter_quaternions(q, lambda v: equalize(v, gains, levels, a), reference)


def equalize_euler(angles, gains, orders="XYZ", levels=None, a=DEFAULT_A):
    """Band gains on Euler curves (F, J, 3) after unrolling them."""
    return _channels.filter_euler(angles, lambda v: equalize(v, gains, levels, a), orders)
