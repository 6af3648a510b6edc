"""A motion equalizer: reconstruction from the Laplacian pyramid with a gain per band (Huang eq. 5-9).

G_0' = w_L G_L + sum_l w_l L_l. Gains of one give the input back; gains of zero on the finest
bands remove capture jitter (a low-pass filter whose corner halves with each band); gains above
one on the middle bands exaggerate the motion while its mean pose (the top) is kept.
"""

import numpy as np
from scipy import signal

from ..errors import MotionError

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


def check_cutoff(fps, cutoff_hz):
    """A cut-off the clip's own frame rate can carry: positive and below Nyquist (fps / 2)."""
    if not np.isfinite(cutoff_hz) or cutoff_hz <= 0.0:
        raise MotionError(f"the cut-off must be a positive frequency, not {cutoff_hz:g} Hz")
    if cutoff_hz >= fps / 2.0 * (1.0 - 1e-4):  # 30.00003 fps (a BVH's 0.0333333 s) is 30
        raise MotionError(f"a cut-off of {cutoff_hz:g} Hz is at or above the clip's Nyquist frequency "
                          f"({fps / 2.0:g} Hz at {fps:g} fps): nothing above it to remove; choose a "
                          f"lower frequency")


def denoise(x, fps, cutoff_hz=10.0, order=4):
    """Remove capture jitter: x (F, ...) low-passed at `cutoff_hz`, a frequency relative to the
    clip's own frame rate `fps` (Butterworth of `order`, run forward and backward: no phase lag,
    the gain at the cut-off 1/2). The pyramid's bands are octaves of the frame rate (7.5-15 Hz,
    3.75-7.5 Hz ... at 30 fps), so removing only the bands wholly above a cut-off did nothing for
    any cut-off inside the finest band (8 Hz on a 30 Hz clip). A cut-off at or above Nyquist is a
    MotionError."""
    x = np.asarray(x, dtype=float)
    check_cutoff(fps, cutoff_hz)
    if len(x) < 3:
        return x.copy()
    sos = signal.butter(order, cutoff_hz / (fps / 2.0), output="sos")
    pad = min(3 * (2 * len(sos) + 1), len(x) - 1)
    return signal.sosfiltfilt(sos, x, axis=0, padlen=pad)


def equalize_quaternions(q, gains, levels=None, a=DEFAULT_A, reference=None):
    """Band gains on quaternion curves (F, ..., 4) in the tangent space; unit, same hemisphere."""
    return _channels.filter_quaternions(q, lambda v: equalize(v, gains, levels, a), reference)


def equalize_euler(angles, gains, orders="XYZ", levels=None, a=DEFAULT_A):
    """Band gains on Euler curves (F, J, 3) after unrolling them."""
    return _channels.filter_euler(angles, lambda v: equalize(v, gains, levels, a), orders)
