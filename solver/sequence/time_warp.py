"""Time warping (Huang 1996 section 5.6): a monotone cubic Hermite warp through constraints, and
squeeze-and-stretch of keys between two limiting keys.

A constraint (t'_j, t_j) says that what happened at original time t_j now happens at t'_j.
The warp t' = f(t) is a monotone cubic Hermite through the pairs (t_j, t'_j) whose slopes are one
plus the slopes of the shape-preserving (Fritsch-Carlson, scipy's PCHIP) interpolant of the
constraints' shifts t'_j - t_j, limited so that f stays monotone (Fritsch-Carlson's circle);
outside the first and last constraint it continues with slope one (the motion keeps its speed
there, and f's slope is continuous at the ends). A cubic through the pairs themselves (PCHIP on
f) turns a small change of speed next to a short interval into a bulge along a long one: moving
frame 61 of 1,900 three frames later shifted frame 1,150 by 20 frames and jerked the dance's hips;
with the shifts interpolated, no frame moves further than the constraints move theirs. Warped channels are sampled at new times t' from the original curve at
f^-1(t') (the original samples joined by cubic Hermite segments with central-difference slopes);
keys are moved to f(t) with their handles scaled by the warp's local slope f'(t).
"""

import numpy as np
from scipy.interpolate import CubicHermiteSpline, PchipInterpolator

from . import channels as _channels
from .key_reduction import Keys


class TimeWarp:
    """The monotone warp t' = f(t) through constraints [(t'_j, t_j), ...] (new time, old time)."""

    def __init__(self, constraints):
        c = np.asarray(constraints, dtype=float).reshape(-1, 2)
        c = c[np.argsort(c[:, 1])]
        self.new, self.old = c[:, 0], c[:, 1]
        if len(c) < 2:
            raise ValueError("a time warp needs at least two constraints")
        if np.any(np.diff(self.old) <= 0.0) or np.any(np.diff(self.new) <= 0.0):
            raise ValueError("time warp constraints must keep their order (strictly increasing in both times)")
        self._f = CubicHermiteSpline(self.old, self.new, self._slopes(), extrapolate=False)
        self._df = self._f.derivative()

    def _slopes(self):
        """f' at the constraints: 1 + the shifts' shape-preserving slopes (1 at the ends), within
        Fritsch-Carlson's monotonicity circle (alpha^2 + beta^2 <= 9) on every interval."""
        old, shift = self.old, self.new - self.old
        m = np.ones(len(old))
        if len(old) > 2:
            m[1:-1] += PchipInterpolator(old, shift).derivative()(old[1:-1])
        delta = np.diff(self.new) / np.diff(old)
        for i, d in enumerate(delta):  # d > 0: the constraints keep their order
            alpha, beta = m[i] / d, m[i + 1] / d
            m[i], m[i + 1] = max(m[i], 0.0), max(m[i + 1], 0.0)
            r = np.hypot(max(alpha, 0.0), max(beta, 0.0))
            if r > 3.0:
                m[i], m[i + 1] = m[i] * 3.0 / r, m[i + 1] * 3.0 / r
        return m

    def __call__(self, t):
        """New times f(t) of original times t."""
        t = np.asarray(t, dtype=float)
        inside = np.clip(t, self.old[0], self.old[-1])
        out = self._f(inside)
        out = np.where(t < self.old[0], self.new[0] + (t - self.old[0]), out)
        return np.where(t > self.old[-1], self.new[-1] + (t - self.old[-1]), out)

    def slope(self, t):
        t = np.asarray(t, dtype=float)
        inside = (t >= self.old[0]) & (t <= self.old[-1])
        return np.where(inside, self._df(np.clip(t, self.old[0], self.old[-1])), 1.0)

    def inverse(self, tn, iterations=80):
        """Original times f^-1(t') by bisection (f is monotone), to rounding error."""
        tn = np.asarray(tn, dtype=float)
        lo = np.minimum(self.old[0] + (tn - self.new[0]), self.old[0])
        hi = np.maximum(self.old[-1] + (tn - self.new[-1]), self.old[-1])
        for _ in range(iterations):
            mid = 0.5 * (lo + hi)
            below = self(mid) < tn
            lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
        return 0.5 * (lo + hi)


def resample(times, values, at):
    """Values (F, ...) sampled at `times`, read at times `at` through cubic Hermite segments with
    central-difference slopes; held constant beyond the ends."""
    times = np.asarray(times, dtype=float)
    values = np.asarray(values, dtype=float)
    spline = CubicHermiteSpline(times, values, np.gradient(values, times, axis=0), axis=0)
    return spline(np.clip(at, times[0], times[-1]))


def warp_channels(times, values, warp: TimeWarp, new_times=None):
    """Channels (F, ...) warped: sampled at `new_times` (default: the original times, i.e. the
    same frames) from the original curve at warp.inverse(new_times)."""
    new_times = np.asarray(times if new_times is None else new_times, dtype=float)
    return resample(times, values, warp.inverse(new_times))


def warp_quaternions(times, q, warp: TimeWarp, new_times=None):
    """Quaternion curves (F, ..., 4) warped through the tangent space (unit, same hemisphere)."""
    return _channels.filter_quaternions(q, lambda v: warp_channels(times, v, warp, new_times))


def warp_keys(keys: Keys, warp: TimeWarp):
    """Keys moved to f(t); handle time offsets scaled by f'(t) so each key keeps its slope in
    value per unit of original time divided by the local speed-up."""
    t = warp(keys.times)
    scale = np.column_stack((warp.slope(keys.times), np.ones(len(t))))
    key = np.column_stack((keys.times, keys.values))
    moved = np.column_stack((t, keys.values))
    left = moved + (keys.left - key) * scale
    right = moved + (keys.right - key) * scale
    return Keys(t, keys.values.copy(), left, right, keys.interpolation.copy())


def squeeze_stretch(key_times, current, new_time, left_limit, right_limit):
    """Move the key at time `current` (T) to `new_time` between the limiting keys TL < T < TR:
    keys in [TL, T] keep their ratio (T - Ti) / (T - TL), keys in [T, TR] keep (Ti - T) / (TR - T);
    keys outside [TL, TR] do not move. Key order is kept."""
    ti = np.asarray(key_times, dtype=float)
    tl, t, tr = float(left_limit), float(current), float(right_limit)
    if not (tl < t < tr and tl < new_time < tr):
        raise ValueError("need left_limit < current, new_time < right_limit")
    out = ti.copy()
    lft = (ti >= tl) & (ti <= t)
    rgt = (ti > t) & (ti <= tr)
    out[lft] = new_time - (t - ti[lft]) / (t - tl) * (new_time - tl)
    out[rgt] = new_time + (ti[rgt] - t) / (tr - t) * (tr - new_time)
    return out
