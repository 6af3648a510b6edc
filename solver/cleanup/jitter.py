"""Jitter removal that leaves fast intended motion alone.

A zero-phase low-pass (Butterworth, forward and back) at `cutoff_hz` gives the smooth motion; the
residual (what the low-pass took away, per joint a rotation vector, per point a displacement) is
jitter where it is small and motion where it is large: a kick's snap leaves a residual many times
the noise. So the residual is shrunk with a non-negative garrote, r * max(0, 1 - (t/|r|)^2), at
t = 3 sigma, sigma the jitter's size estimated from the residual's second differences: noise is
removed, a large residual (fast intended motion) is kept almost whole. The cut-off is in Hz, so it means the same at any
frame rate; it is capped below the clip's Nyquist frequency.
"""

import numpy as np
from scipy.signal import butter, filtfilt

from .. import rotations
from ..dynamics.spatial import quat_exp, quat_log

DEFAULT_CUTOFF_HZ = 6.0
NOISE_SIGMAS = 3.0
NOISE_WINDOW_SECONDS = 1.0
NOISE_PERCENTILE = 25.0


def low_pass(x, fps, cutoff_hz, axis=0):
    nyquist = 0.5 * fps
    wn = min(cutoff_hz / nyquist, 0.9)
    b, a = butter(2, wn)
    if x.shape[axis] <= 3 * max(len(a), len(b)):
        return np.array(x, float)
    return filtfilt(b, a, x, axis=axis)


def noise_scale(residual, fps=None):
    """Per channel (1, K, 1) the jitter's size, from the residual's second differences (white
    noise of size s has second differences of size s * sqrt(6); smooth motion has almost none).
    Jitter is there all the time, fast motion only at times: with `fps`, the size is the 25th
    percentile over the clip of its median over windows of NOISE_WINDOW_SECONDS, so a clean clip's
    fast moments are not taken for noise."""
    second = np.linalg.norm(np.diff(residual, 2, axis=0), axis=-1)  # (F - 2, K)
    w = 0 if fps is None else int(round(NOISE_WINDOW_SECONDS * fps))
    if w < 3 or len(second) < 2 * w:
        size = np.median(second, axis=0) / np.sqrt(6.0)
    else:
        windows = np.lib.stride_tricks.sliding_window_view(second, w, axis=0)[::max(1, w // 2)]  # (n, K, w)
        size = np.percentile(np.median(windows, axis=-1), NOISE_PERCENTILE, axis=0) / np.sqrt(6.0)
    # jitter is white: it fills the top of the spectrum as much as the rest, where a body's
    # motion (even a walk's heel strike at 30 fps) has next to nothing. Its size there, scaled
    # to the whole band, caps the estimate: motion that never rests is not taken for noise
    top = top_band_size(residual)
    if top is not None:
        size = np.minimum(size, top)
    # jitter is also uncorrelated from frame to frame, while motion, however fast, carries on:
    # the part of the residual that alternates (the lag-1 autocovariance of its second
    # differences, negative for white noise, positive for motion) is a third cap
    if fps is not None:
        alternating = alternating_size(residual)
        if alternating is not None:
            size = np.minimum(size, alternating)
    # and a capture's jitter is spread over the whole body, while fast motion (a wave, a kick) is
    # in a few joints: no joint's noise is taken to be more than BODY_SPREAD times the body's median
    if size.size >= 5:
        size = np.minimum(size, BODY_SPREAD * np.median(size))
    return size[None, :, None]


BODY_SPREAD = 1.5


TOP_BAND = 0.75  # the top of the spectrum: above this share of the Nyquist frequency


def _top_pass(x):
    b, a = butter(4, TOP_BAND, btype="high")
    return filtfilt(b, a, x, axis=0)


def _top_gain():
    """The top-band statistic of white noise of size 1 (the size unit of noise_scale: the median
    length of a 3-vector of unit normal components), from a fixed sample."""
    noise = np.random.default_rng(0).standard_normal((20000, 1, 3))
    return np.median(np.linalg.norm(_top_pass(noise), axis=-1)) / np.median(np.linalg.norm(noise, axis=-1))


_TOP_GAIN = _top_gain()


def top_band_size(residual):
    """(K,) the residual's size as white noise, from the top of its spectrum; None if too short."""
    if len(residual) < 40:
        return None
    return np.median(np.linalg.norm(_top_pass(residual), axis=-1), axis=0) / _TOP_GAIN


def _alternating(residual):
    """(K,) minus the lag-1 autocovariance of the second differences of residual (F, K, d), per
    channel, summed over the components: 4 d s^2 for white noise of size s per component, less
    for motion (whose second differences change slowly)."""
    second = np.diff(residual, 2, axis=0)
    return -np.mean(np.sum(second[1:] * second[:-1], axis=-1), axis=0)


def _alternating_gain():
    """_alternating of unit white noise, in the size unit of noise_scale (the median length of a
    3-vector of unit normal components), from a fixed sample."""
    noise = np.random.default_rng(1).standard_normal((20000, 1, 3))
    return float(_alternating(noise)[0]) / np.median(np.linalg.norm(noise, axis=-1)) ** 2


_ALT_GAIN = _alternating_gain()


def alternating_size(residual):
    """(K,) the residual's size as white noise from its frame-to-frame alternation (0 where it
    does not alternate at all); None if too short."""
    if len(residual) < 40:
        return None
    return np.sqrt(np.maximum(_alternating(residual), 0.0) / _ALT_GAIN)


def garrote(residual, sigmas=None, fps=None):
    """Shrink residual vectors (F, K, d): small ones (noise) to zero, large ones kept."""
    size = np.linalg.norm(residual, axis=-1, keepdims=True)
    t = (NOISE_SIGMAS if sigmas is None else sigmas) * noise_scale(residual, fps)
    keep = np.clip(1.0 - (t / np.maximum(size, 1e-12)) ** 2, 0.0, 1.0)
    return residual * keep


def smooth_rotations(quats, fps, cutoff_hz=DEFAULT_CUTOFF_HZ, strength=1.0):
    """Quaternions (F, J, 4) with their jitter removed; `strength` 0..1 blends."""
    q = rotations.make_continuous(rotations.normalize(np.asarray(quats, float)))
    smooth = rotations.normalize(low_pass(q, fps, cutoff_hz))
    residual = quat_log(rotations.multiply(rotations.conjugate(smooth), q))  # smooth * exp(r) = q
    kept = residual - strength * (residual - garrote(residual, fps=fps))
    return rotations.make_continuous(rotations.multiply(smooth, quat_exp(kept)))


def smooth_positions(positions, fps, cutoff_hz=DEFAULT_CUTOFF_HZ, strength=1.0):
    p = np.asarray(positions, float)
    smooth = low_pass(p, fps, cutoff_hz)
    residual = p - smooth
    return smooth + residual - strength * (residual - garrote(residual, fps=fps))
