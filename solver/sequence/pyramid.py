"""Gaussian and Laplacian pyramids of sampled curves (Burt and Adelson 1983; Huang 1996, eq. 5-3 to 5-6).

Curves are arrays (F, ...) sampled at a constant step, time on axis 0; every other axis is a
channel, so a whole sequence (F, C) is filtered at once.

Length. REDUCE halves an odd number of samples n into (n + 1) / 2, so L levels need
F = k 2^L + 1 samples (the thesis' 2^N + 1 is the case k = 1, a full pyramid down to 2 samples).
A curve of any other length is extended at its end to the next such length by point reflection
about its last sample (x[F-1+i] = 2 x[F-1] - x[F-1-i], repeated if needed), and the extension is
cut off after reconstruction. Point reflection continues the value and the slope, so a ramp stays
a ramp and no step or kink appears at the end; it is also how REDUCE and EXPAND see past both
ends of every level, which is why the first and last samples pass through unchanged (the thesis:
"the two first and final samples are copied to the next layer"). Reconstruction adds back exactly
what was subtracted, so it returns the input to rounding error whatever the extension.
"""

from dataclasses import dataclass

import numpy as np

DEFAULT_A = 0.4


def kernel(a=DEFAULT_A):
    """The 5-tap generating kernel (c, b, a, b, c): b = 1/4, c = 1/4 - a/2 (normalised, equal contribution)."""
    return np.array([0.25 - 0.5 * a, 0.25, a, 0.25, 0.25 - 0.5 * a])


def reflect(x, before, after):
    """Extend x (F, ...) by `before` and `after` samples by point reflection about its end samples."""
    x = np.asarray(x, dtype=float)
    while after > 0:
        tail = 2.0 * x[-1] - x[-2::-1][:after]
        x = np.concatenate((x, tail))
        after -= len(tail)
    while before > 0:
        head = (2.0 * x[0] - x[1:][:before])[::-1]
        x = np.concatenate((head, x))
        before -= len(head)
    return x


def dyadic_length(n, levels):
    """The smallest k 2^levels + 1 >= n (at least 2^levels + 1)."""
    step = 2 ** levels
    return max(1, -(-(n - 1) // step)) * step + 1


def max_levels(n):
    """Levels of a full pyramid of n samples: N with 2^(N-1) + 1 < n <= 2^N + 1."""
    return max(1, int(np.ceil(np.log2(max(n - 1, 1)))))


def reduce(g, a=DEFAULT_A):
    """REDUCE (eq. 5-3): G_l[i] = sum_m w(m) G_{l-1}[2i + m]; n odd samples to (n + 1) / 2."""
    g = np.asarray(g, dtype=float)
    if len(g) % 2 == 0 or len(g) < 3:
        raise ValueError(f"REDUCE needs an odd number of samples >= 3, not {len(g)}")
    gp = reflect(g, 2, 2)
    w = kernel(a)
    n = (len(g) + 1) // 2
    return sum(w[m] * gp[m:m + 2 * n - 1:2] for m in range(5))


def expand(g, a=DEFAULT_A):
    """EXPAND (eq. 5-4 in 1-D): G_{l,1}[i] = 2 sum_m w(m) G_l[(i - m) / 2] over integer (i - m) / 2;
    m samples to 2m - 1. Even outputs are (2c, 2a, 2c)-smoothed nodes, odd ones are midpoints."""
    g = np.asarray(g, dtype=float)
    w = kernel(a)
    gp = reflect(g, 1, 1)
    out = np.empty((2 * len(g) - 1,) + g.shape[1:])
    out[0::2] = 2.0 * (w[0] * gp[:-2] + w[2] * gp[1:-1] + w[4] * gp[2:])
    out[1::2] = 2.0 * w[1] * (g[:-1] + g[1:])
    return out


def gaussian_pyramid(x, levels=None, a=DEFAULT_A):
    """[G_0, ..., G_L] of x, extended to k 2^L + 1 samples; G_0 is the extended input."""
    x = np.asarray(x, dtype=float)
    levels = max_levels(len(x)) if levels is None else int(levels)
    g = [reflect(x, 0, dyadic_length(len(x), levels) - len(x))]
    for _ in range(levels):
        g.append(reduce(g[-1], a))
    return g


@dataclass
class Pyramid:
    """Laplacian pyramid: `bands` L_0 (finest, highest frequency) .. L_{L-1}, `top` G_L,
    `length` samples of the input before extension, `a` the kernel parameter."""

    bands: list
    top: np.ndarray
    length: int
    a: float = DEFAULT_A

    @property
    def levels(self):
        return len(self.bands)


def laplacian_pyramid(x, levels=None, a=DEFAULT_A):
    """L_l = G_l - EXPAND(G_{l+1}) (eq. 5-5) for l < L, and the top G_L."""
    g = gaussian_pyramid(x, levels, a)
    bands = [g[l] - expand(g[l + 1], a) for l in range(len(g) - 1)]
    return Pyramid(bands, g[-1], len(np.asarray(x)), a)


def reconstruct(pyramid, gains=None):
    """G_0 = w_L G_L + sum_l w_l L_l (eq. 5-6, with gains eq. 5-9), collapsed from the top with
    EXPAND, cut back to the input length. `gains` has L + 1 entries, finest band first and the
    top last; each entry is a scalar or one value per channel. None means all ones (exact)."""
    levels = pyramid.levels
    gains = [1.0] * (levels + 1) if gains is None else list(gains)
    if len(gains) != levels + 1:
        raise ValueError(f"{levels + 1} gains needed (one per band and the top), got {len(gains)}")
    g = np.asarray(gains[-1], dtype=float) * pyramid.top
    for l in range(levels - 1, -1, -1):
        g = expand(g, pyramid.a) + np.asarray(gains[l], dtype=float) * pyramid.bands[l]
    return g[:pyramid.length]


def band_limits_hz(fps, levels):
    """Approximate frequency range (low, high) in Hz of each band L_0..L_{L-1} and of the top."""
    edges = [fps / 2.0 ** (l + 1) for l in range(levels + 1)]
    return [(edges[l + 1], edges[l]) for l in range(levels)] + [(0.0, edges[levels])]
