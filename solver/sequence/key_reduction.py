"""Key reduction by cubic Hermite splines (Huang 1996 section 5.8, after Boulic et al.), emitted as
Blender F-curve keyframes, and a numpy evaluator of such F-curves to check them.

The sampled curve is scanned into linear runs (kept as straight segments between their end keys)
and non-linear runs, which are approximated by cubic Hermite segments between keys placed on
samples (key values are sample values). A segment is accepted when the area between it and the
samples (Simpson's rule) divided by its duration is at most `tolerance` and, unless max_error is
None, no sample is further than `max_error` (default: the tolerance, so the result is within the
tolerance on every frame).

Two choices, each with the thesis' way and a better one (the default):
- search: 'recursive' (thesis) accepts a run or splits it at its worst sample and recurses;
  'greedy' takes from each key the longest acceptable segment (doubling, then bisection).
- tangents: 'samples' (thesis) uses the samples' slopes (central differences, the curve is C1);
  'fitted' gives each segment the end slopes that fit its samples best (least squares), so a key
  may have different slopes either side (Blender FREE handles): a small velocity kink at keys,
  bounded by the tolerance, for about half the keys on noisy capture.

A sample is linear (thesis: "its slope, the slope of the previous key point and the slope of the
cord ... are within a normalized neighbourhood") when both slopes differ from the chord slope to
its predecessor by at most `linear_tolerance` times the channel's range over the clip duration.
A linear run is used when it spans at least `min_linear_run` sample steps and its chord meets the
error criteria; shorter ones cost more keys than a Hermite segment over them.

Blender keys. A cubic Hermite segment from t0 to t1 (values p0, p1, slopes m0, m1) is the Bezier
with control points (t0, p0), (t0 + d/3, p0 + m0 d/3), (t1 - d/3, p1 - m1 d/3), (t1, p1), d = t1 - t0.
Blender's F-curve Bezier is a 2-D Bezier in (time, value); with its inner control points at
exactly one and two thirds of the segment in time, its time coordinate is t0 + s d, linear in the
Bezier parameter s, so the value is a cubic polynomial in time, the Hermite segment itself. Keys
get FREE handles (a key between a linear and a curved segment has different slopes either side)
and interpolation LINEAR on linear runs, BEZIER elsewhere.
"""

from dataclasses import dataclass

import numpy as np


@dataclass
class Keys:
    """Keyframes of one channel: `times` (K,), `values` (K,), `left` and `right` handles (K, 2)
    as (time, value), and `interpolation` (K,) of the segment after each key ('BEZIER',
    'LINEAR' or 'CONSTANT'; the last key's is unused)."""

    times: np.ndarray
    values: np.ndarray
    left: np.ndarray
    right: np.ndarray
    interpolation: np.ndarray

    def __len__(self):
        return len(self.times)


def hermite(t, t0, t1, p0, p1, m0, m1):
    """Cubic Hermite segment at times t (slopes in value per unit of t)."""
    d = t1 - t0
    s = (np.asarray(t, dtype=float) - t0) / d
    s2, s3 = s * s, s * s * s
    return ((2 * s3 - 3 * s2 + 1) * p0 + (s3 - 2 * s2 + s) * d * m0
            + (-2 * s3 + 3 * s2) * p1 + (s3 - s2) * d * m1)


def simpson(e, t):
    """Composite Simpson integral of samples e at times t over pairs of steps (the non-uniform
    form), with a trapezoid for the last step of an even count; positive weights when evenly spaced."""
    e, t = np.asarray(e, dtype=float), np.asarray(t, dtype=float)
    n = len(t) - 1 if len(t) % 2 == 0 else len(t)
    h0, h1 = t[1:n:2] - t[0:n - 1:2], t[2:n:2] - t[1:n:2]
    hs = h0 + h1
    total = (hs / 6.0 * ((2.0 - h1 / h0) * e[0:n - 1:2] + hs * hs / (h0 * h1) * e[1:n:2]
                         + (2.0 - h0 / h1) * e[2:n:2])).sum()
    if n < len(t):
        total += 0.5 * (t[-1] - t[-2]) * (e[-1] + e[-2])
    return total


def sample_slopes(times, values, smoothing=0):
    """Slopes of a sampled curve (F, ...): central differences from the two neighbours (the
    thesis' default), or with smoothing = h > 0 the slope of a least-squares parabola through
    the 2h + 1 samples around each one (against capture noise)."""
    times = np.asarray(times, dtype=float)
    values = np.asarray(values, dtype=float)
    if smoothing <= 0 or len(times) < 2 * smoothing + 2:
        return np.gradient(values, times, axis=0)
    from scipy.signal import savgol_filter
    dt = (times[-1] - times[0]) / (len(times) - 1)
    return savgol_filter(values, 2 * smoothing + 1, 2, deriv=1, delta=dt, axis=0, mode="interp")


def _linear_flags(t, y, m, linear_tolerance):
    chord = np.diff(y) / np.diff(t)
    scale = max(np.ptp(y) / (t[-1] - t[0]), 1e-12)
    eps = linear_tolerance * scale
    flags = np.zeros(len(t), dtype=bool)
    flags[1:] = (np.abs(m[:-1] - chord) <= eps) & (np.abs(m[1:] - chord) <= eps)
    return flags


class _Fit:
    """Working state of one channel's reduction."""

    def __init__(self, t, y, m, tolerance, max_error, tangents="fitted", search="greedy"):
        self.t, self.y, self.m = t, y, m
        self.tolerance, self.max_error = tolerance, max_error
        self.tangents, self.search = tangents, search
        self.keys = [0]
        self.segments = []  # (i, j, slope_out_of_i, slope_into_j, interpolation)

    def _basis(self, i, j):
        """Samples' residual from the end values' Hermite terms, and the slope terms (u, v)."""
        t = self.t[i:j + 1]
        d = t[-1] - t[0]
        s = (t - t[0]) / d
        s2 = s * s
        s3 = s2 * s
        r = self.y[i:j + 1] - (1.0 - 3.0 * s2 + 2.0 * s3) * self.y[i] - (3.0 * s2 - 2.0 * s3) * self.y[j]
        return t, r, (s3 - 2.0 * s2 + s) * d, (s3 - s2) * d

    def try_segment(self, i, j, m0=None, m1=None):
        """(acceptable, |errors|, m0, m1) of the Hermite segment [i, j]. End slopes: given, the
        samples' ('samples'), or those that fit its samples best by least squares ('fitted'),
        drawn towards the samples' where under-determined (fewer than two inner samples)."""
        t, r, u, v = self._basis(i, j)
        if m0 is None and (self.tangents == "samples" or j - i < 2):
            m0, m1 = self.m[i], self.m[j]
        elif m0 is None:
            lam = 1e-9 * (t[-1] - t[0]) ** 2 * len(t)
            a, b, c = u @ u + lam, u @ v, v @ v + lam
            g0, g1 = u @ r + lam * self.m[i], v @ r + lam * self.m[j]
            det = a * c - b * b
            m0, m1 = (c * g0 - b * g1) / det, (a * g1 - b * g0) / det
        e = np.abs(r - u * m0 - v * m1)
        return self.fits(t, e), e, m0, m1

    def fits(self, t, e):
        """Every error within max_error (unless None), and the Simpson integral of the errors
        over the segment, divided by its duration, within the tolerance (implied, and skipped,
        when max_error <= tolerance: on evenly spaced samples Simpson's weights are positive,
        so that mean is at most the largest error)."""
        if self.max_error is not None:
            if e.max() > self.max_error:
                return False
            if self.max_error <= self.tolerance:
                return True
        return len(t) < 3 or simpson(e, t) / (t[-1] - t[0]) <= self.tolerance

    def chord_ok(self, i, j):
        c = (self.y[j] - self.y[i]) / (self.t[j] - self.t[i])
        return self.try_segment(i, j, c, c)[0]

    def add(self, i, j, m0, m1, kind):
        self.keys.append(j)
        self.segments.append((i, j, m0, m1, kind))

    def hermite_run(self, i, j):
        (self._greedy if self.search == "greedy" else self._recursive)(i, j)

    def _recursive(self, i, j):
        """Thesis: accept the segment or split it at its worst sample and recurse on both halves."""
        stack = [(i, j)]
        while stack:  # depth first, left half first, so keys come out in order
            i, j = stack.pop()
            ok, e, m0, m1 = self.try_segment(i, j)
            if ok or j - i < 2:
                self.add(i, j, m0, m1, "BEZIER")
                continue
            k = i + 1 + int(np.argmax(e[1:-1]))
            stack.extend(((k, j), (i, k)))

    def _greedy(self, i, end):
        """From each key, the longest segment that meets the criteria (doubling, then bisection)."""
        while i < end:
            best = (i + 1,) + self.try_segment(i, i + 1)[2:]
            length, bad = 2, None
            while bad is None:
                j = min(i + length, end)
                ok, _, m0, m1 = self.try_segment(i, j)
                if not ok:
                    bad = j
                    break
                best = (j, m0, m1)
                if j == end:
                    break
                length *= 2
            if bad is not None:
                lo, hi = best[0], bad
                while hi - lo > 1:
                    mid = (lo + hi) // 2
                    ok, _, m0, m1 = self.try_segment(i, mid)
                    if ok:
                        lo, best = mid, (mid, m0, m1)
                    else:
                        hi = mid
            j, m0, m1 = best
            self.add(i, j, m0, m1, "BEZIER")
            i = j


def _linear_run(fit, flags, i, min_run):
    """End of the linear run starting at sample i (its chord within the criteria, at least
    `min_run` steps long), or None."""
    last = len(fit.t) - 1
    j = i
    while j < last and flags[j + 1]:
        j += 1
    while j >= i + min_run and not fit.chord_ok(i, j):
        j = i + 1 + (j - i - 1) // 2  # shorten until the chord is good enough
    return j if j >= i + min_run else None


def _scan(fit, flags, min_run=2):
    """Thesis table 5-1: alternate the longest linear run and the longest non-linear run.
    Linear runs shorter than `min_run` sample steps count as non-linear."""
    last = len(fit.t) - 1
    min_run = max(2, int(min_run))
    i = 0
    while i < last:
        j = _linear_run(fit, flags, i, min_run)
        if j is not None:
            c = (fit.y[j] - fit.y[i]) / (fit.t[j] - fit.t[i])
            fit.add(i, j, c, c, "LINEAR")
            i = j
            continue
        j = i + 1
        while j + min_run <= last and not (flags[j + 1:j + 1 + min_run].all()
                                           and _linear_run(fit, flags, j, min_run) is not None):
            j += 1
        if j + min_run > last:  # no linear run fits before the end
            j = last
        fit.hermite_run(i, j)
        i = j


def reduce_keys(times, values, tolerance, max_error="tolerance", linear_tolerance=0.01,
                min_linear_run=16, tangents="fitted", search="greedy", slopes=None, smoothing=0):
    """Keys of one sampled channel (times (F,) increasing, values (F,)) within the tolerance.

    tangents: 'fitted' (each segment's end slopes by least squares: FREE handles, a key may
    have different slopes either side) or 'samples' (the thesis: the samples' slopes, `slopes`
    default sample_slopes(times, values, smoothing); the curve is C1).
    search: 'greedy' (the longest acceptable segment from each key) or 'recursive' (the thesis:
    split the run at its worst sample until every part is acceptable)."""
    t = np.asarray(times, dtype=float)
    y = np.asarray(values, dtype=float)
    m = sample_slopes(t, y, smoothing) if slopes is None else np.asarray(slopes, dtype=float)
    max_error = tolerance if isinstance(max_error, str) else max_error
    fit = _Fit(t, y, m, tolerance, max_error, tangents, search)
    if len(t) > 1:
        _scan(fit, _linear_flags(t, y, m, linear_tolerance), min_linear_run)
    return _to_keys(fit)


def _to_keys(fit):
    t, y = fit.t, fit.y
    idx = np.array(fit.keys)
    k = len(idx)
    left = np.empty((k, 2))
    right = np.empty((k, 2))
    interp = np.array(["BEZIER"] * k, dtype=object)
    for n, (i, j, m0, m1, kind) in enumerate(fit.segments):
        d = (t[j] - t[i]) / 3.0
        right[n] = (t[i] + d, y[i] + m0 * d)
        left[n + 1] = (t[j] - d, y[j] - m1 * d)
        interp[n] = kind
    if k == 1:
        left[0] = right[0] = (t[0], y[0])
    else:  # outer handles mirror the inner ones (unused by Blender's constant extrapolation)
        left[0] = 2.0 * np.array((t[0], y[0])) - right[0]
        right[-1] = 2.0 * np.array((t[idx[-1]], y[idx[-1]])) - left[-1]
    return Keys(t[idx].copy(), y[idx].copy(), left, right, interp)


def reduce_channels(times, values, tolerance, **kw):
    """reduce_keys on each channel of values (F, C); `tolerance` scalar or (C,)."""
    values = np.asarray(values, dtype=float)
    tol = np.broadcast_to(np.asarray(tolerance, dtype=float), values.shape[1:])
    slopes = sample_slopes(times, values, kw.pop("smoothing", 0))
    return [reduce_keys(times, values[:, c], tol[c], slopes=slopes[:, c], **kw)
            for c in range(values.shape[1])]


def hermite_keys(times, values, slopes=None):
    """Keys through every sample with the given (or central-difference) slopes, all BEZIER."""
    t = np.asarray(times, dtype=float)
    y = np.asarray(values, dtype=float)
    m = np.gradient(y, t) if slopes is None else np.asarray(slopes, dtype=float)
    fit = _Fit(t, y, m, np.inf, None)
    for i in range(len(t) - 1):
        fit.add(i, i + 1, m[i], m[i + 1], "BEZIER")
    return _to_keys(fit)


# -- evaluating F-curves the way Blender does ---------------------------------------------------

def _correct_handles(x0, h0, h1, x1):
    """Blender's BKE_fcurve_correct_bezpart: shorten handles that reach past the other key in time."""
    len1, len2, span = h0 - x0, x1 - h1, x1 - x0
    total = len1 + len2
    scale = np.where(total > span, span / np.where(total > 0, total, 1.0), 1.0)
    return scale


def _bezier_parameter(x0, h0, h1, x1, t, iterations=60):
    """s in [0, 1] with Bx(s) = t by bisection (Bx is monotone once the handles are corrected)."""
    lo = np.zeros_like(t)
    hi = np.ones_like(t)
    for _ in range(iterations):
        s = 0.5 * (lo + hi)
        u = 1.0 - s
        x = u ** 3 * x0 + 3 * u * u * s * h0 + 3 * u * s * s * h1 + s ** 3 * x1
        below = x < t
        lo = np.where(below, s, lo)
        hi = np.where(below, hi, s)
    return 0.5 * (lo + hi)


def evaluate(keys: Keys, t):
    """Value of the F-curve `keys` at times t, as Blender evaluates it: 2-D Bezier segments
    (handles corrected), LINEAR and CONSTANT segments, constant extrapolation."""
    t = np.asarray(t, dtype=float)
    out = np.empty_like(t)
    kt, kv = keys.times, keys.values
    if len(kt) == 1:
        out[...] = kv[0]
        return out
    seg = np.clip(np.searchsorted(kt, t, side="right") - 1, 0, len(kt) - 2)
    x0, x1, p0, p1 = kt[seg], kt[seg + 1], kv[seg], kv[seg + 1]
    kind = keys.interpolation[seg]
    out = np.where(kind == "CONSTANT", p0, p0 + (p1 - p0) * (t - x0) / (x1 - x0))
    bez = kind == "BEZIER"
    if bez.any():
        x0b, x1b, p0b, p1b, tb = x0[bez], x1[bez], p0[bez], p1[bez], t[bez]
        r, l = keys.right[seg[bez]], keys.left[seg[bez] + 1]
        scale = _correct_handles(x0b, r[:, 0], l[:, 0], x1b)
        h0x, h0y = x0b + scale * (r[:, 0] - x0b), p0b + scale * (r[:, 1] - p0b)
        h1x, h1y = x1b - scale * (x1b - l[:, 0]), p1b - scale * (p1b - l[:, 1])
        s = _bezier_parameter(x0b, h0x, h1x, x1b, tb)
        u = 1.0 - s
        out[bez] = u ** 3 * p0b + 3 * u * u * s * h0y + 3 * u * s * s * h1y + s ** 3 * p1b
    out = np.where(t <= kt[0], kv[0], out)
    return np.where(t >= kt[-1], kv[-1], out)


def evaluate_channels(keys_list, t):
    """(len(t), C) values of C F-curves."""
    return np.stack([evaluate(k, t) for k in keys_list], axis=-1)


def evaluate_hermite(keys: Keys, t):
    """The same curve evaluated directly as cubic Hermite segments (slopes read from the handles)."""
    t = np.asarray(t, dtype=float)
    kt, kv = keys.times, keys.values
    if len(kt) == 1:
        return np.full_like(t, kv[0])
    seg = np.clip(np.searchsorted(kt, t, side="right") - 1, 0, len(kt) - 2)
    r, l = keys.right[seg], keys.left[seg + 1]
    m0 = (r[:, 1] - kv[seg]) / (r[:, 0] - kt[seg])
    m1 = (kv[seg + 1] - l[:, 1]) / (kt[seg + 1] - l[:, 0])
    out = hermite(t, kt[seg], kt[seg + 1], kv[seg], kv[seg + 1], m0, m1)
    out = np.where(t <= kt[0], kv[0], out)
    return np.where(t >= kt[-1], kv[-1], out)


def scale_to_error(reduce, measure, target, tries=5, close=0.85, resolution=1.0 / 32.0):
    """Keys from `reduce(scale)` whose `measure(keys)` is at most `target`, as fit_to_error, with
    the scale found on the errors instead of by halving: an error that the channel errors add up
    to (a planted foot's, a bone tail's) grows about in proportion to the channel tolerances, so
    each try takes the scale where the line through the nearest measured (scale, error) points on
    either side of the target (at first (0, 0): keys on every sample make no error, and (1, error
    at 1)) reaches the middle of [close * target, target]. Stops at the first scale whose error is
    within that window, or once the scales that pass and fail are `resolution` apart, after at
    most `tries` reductions beyond the first. Returns (keys, scale, error); when no scale tried
    meets the target, the last one's result."""
    keys = reduce(1.0)
    error = measure(keys)
    if error <= target:
        return keys, 1.0, error
    (s0, e0), (s1, e1) = (0.0, 0.0), (1.0, error)
    aim = 0.5 * (1.0 + close) * target
    best, last = None, (keys, 1.0, error)
    for _ in range(tries):
        width = s1 - s0
        s = s0 + (aim - e0) * width / (e1 - e0) if e1 > e0 else s0 + 0.5 * width
        s = min(max(s, s0 + 0.1 * width), s1 - 0.1 * width)  # inside the bracket, never stalling at its end
        keys = reduce(s)
        error = measure(keys)
        last = (keys, s, error)
        if error <= target:
            (s0, e0), best = (s, error), last
            if error >= close * target:
                break
        else:
            s1, e1 = s, error
        if best is not None and s1 - s0 <= resolution:
            break
    return best if best is not None else last


def fit_to_error(reduce, measure, target, steps=7):
    """Keys from `reduce(scale)` (a per-channel tolerance scaled by `scale` in (0, 1]) whose
    `measure(keys)` is at most `target`, found by bisection on the scale: for errors such as a
    bone tail's that channel tolerances do not bound directly. Returns (keys, scale, error); when
    no scale tried meets the target, the smallest one's result."""
    keys = reduce(1.0)
    error = measure(keys)
    if error <= target:
        return keys, 1.0, error
    lo, hi, best = 0.0, 1.0, None
    for _ in range(steps):
        mid = 0.5 * (lo + hi)
        keys = reduce(mid)
        error = measure(keys)
        if error <= target:
            lo, best = mid, (keys, mid, error)
        else:
            hi = mid
    return best if best is not None else (keys, mid, error)
