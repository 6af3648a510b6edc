"""A path on the ground and how fast the body travels along it.

The path is a polyline (samples of a Blender curve, or the keyed root positions, Huang's
"Global_motion" of sec. 6.4.2), parameterised by arc length s. The progress s(t) comes either from
a speed (constant, keyed along the path, or one per segment), limited by an acceleration so the
walk starts from standing and stops to standing, or directly from keyed times (then the keys
carry the timing themselves)."""

from dataclasses import dataclass

import numpy as np

from ..errors import HumanAnimError

ACCELERATION = 0.8  # m/s^2: starting and stopping, and changes of keyed speed
DS = 0.005  # m: arc-length grid of the speed profile


@dataclass
class Path:
    points: np.ndarray  # (N, 3) metres, world
    s: np.ndarray  # (N,) arc length at each point (horizontal)
    corners: np.ndarray  # arc length of the user's control points / segment ends

    @classmethod
    def from_points(cls, points, corners=None):
        p = np.asarray(points, float)
        if p.ndim != 2 or p.shape[1] not in (2, 3):
            raise HumanAnimError("a path needs points with x, y (and z)")
        if p.shape[1] == 2:
            p = np.column_stack((p, np.zeros(len(p))))
        keep = np.r_[True, np.linalg.norm(np.diff(p[:, :2], axis=0), axis=1) > 1e-9]
        p = p[keep]
        if len(p) < 2:
            raise HumanAnimError("the path has fewer than two distinct points")
        s = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(p[:, :2], axis=0), axis=1))]
        if corners is None:
            corners = s[[0, -1]]
        return cls(p, s, np.asarray(corners, float))

    @property
    def length(self):
        return float(self.s[-1])

    def at(self, s):
        """Points (..., 3) at arc lengths s."""
        s = np.clip(np.asarray(s, float), 0.0, self.length)
        return np.stack([np.interp(s, self.s, self.points[:, k]) for k in range(3)], axis=-1)

    def heading(self, s, smooth=0.3):
        """Unit horizontal tangent (..., 2), averaged over +-smooth metres so corners turn gently."""
        s = np.asarray(s, float)
        a, b = self.at(s - smooth), self.at(s + smooth)
        d = (b - a)[..., :2]
        n = np.linalg.norm(d, axis=-1, keepdims=True)
        fallback = self.points[-1, :2] - self.points[0, :2]
        return np.where(n > 1e-9, d / np.maximum(n, 1e-12), fallback / np.linalg.norm(fallback))

    def _nearest(self, points):
        q = np.asarray(points, float)[:, None, :2]
        a, b = self.points[None, :-1, :2], self.points[None, 1:, :2]
        ab = b - a
        t = np.clip(np.sum((q - a) * ab, axis=-1) / np.maximum(np.sum(ab * ab, axis=-1), 1e-18), 0, 1)
        d = np.linalg.norm(a + t[..., None] * ab - q, axis=-1)
        k = d.argmin(axis=1)
        rows = np.arange(len(d))
        return d[rows, k], self.s[k] + t[rows, k] * (self.s[k + 1] - self.s[k])

    def distance_to(self, points):
        """Horizontal distance (N,) of each point to the polyline."""
        return self._nearest(points)[0]

    def project(self, points):
        """Arc length (N,) of the path point nearest to each point."""
        return self._nearest(points)[1]


@dataclass
class Progress:
    """Arc length travelled s(t) on a fine time grid (t from 0 when the body starts moving)."""

    t: np.ndarray
    s: np.ndarray

    def __call__(self, t):
        return np.interp(t, self.t, self.s)

    @property
    def duration(self):
        return float(self.t[-1])

    def speed(self, t):
        return np.interp(t, self.t, np.gradient(self.s, self.t))

    def mean_speed(self, t0, t1):
        return (self(t1) - self(t0)) / max(t1 - t0, 1e-9)


def speed_profile(path, speed=None, keys=None, segments=None, acceleration=ACCELERATION):
    """Speed (m/s) on an arc-length grid, from standing to standing.

    speed: one value; keys: (arc length m, speed) pairs interpolated linearly; segments: one speed
    per stretch between the path's corners. Changes are limited to `acceleration`, forwards and
    backwards, so the body speeds up and slows down without jumps."""
    s = np.linspace(0.0, path.length, max(2, int(np.ceil(path.length / DS)) + 1))
    if keys is not None:
        keys = np.asarray(keys, float).reshape(-1, 2)
        order = np.argsort(keys[:, 0])
        v = np.interp(s, keys[order, 0], keys[order, 1])
    elif segments is not None:
        segments = np.asarray(segments, float).ravel()
        if len(segments) != len(path.corners) - 1:
            raise HumanAnimError(f"{len(segments)} segment speeds for a path of {len(path.corners) - 1} segments")
        v = segments[np.clip(np.searchsorted(path.corners, s, side="right") - 1, 0, len(segments) - 1)]
    elif speed is not None:
        v = np.full(len(s), float(speed))
    else:
        raise HumanAnimError("give a speed, speed keys or segment speeds")
    if not np.all(np.isfinite(v)) or v.min() <= 0.0:
        raise HumanAnimError("walking speeds must be positive")
    v = v.astype(float)
    v[0] = v[-1] = 0.0
    ds = np.diff(s)
    for i in range(1, len(s)):  # speeding up at most at `acceleration`
        v[i] = min(v[i], np.sqrt(v[i - 1] ** 2 + 2 * acceleration * ds[i - 1]))
    for i in range(len(s) - 2, -1, -1):  # and slowing down in time to stop
        v[i] = min(v[i], np.sqrt(v[i + 1] ** 2 + 2 * acceleration * ds[i]))
    return s, v


def progress_from_speed(s_grid, v):
    """Integrate dt = ds / v with the mean speed of each step (the first and last steps, where v
    starts or ends at 0, take the exact time of uniform acceleration: 2 ds / v)."""
    vm = 0.5 * (v[1:] + v[:-1])
    dt = np.diff(s_grid) / np.maximum(vm, 1e-9)
    t = np.r_[0.0, np.cumsum(dt)]
    return Progress(t, np.asarray(s_grid, float))


def from_keys(times, positions):
    """Keyed root positions (Huang's Global_motion): the path through them and the progress
    along it at the keys' times (s, increasing); a root that stays put makes the body stand."""
    times = np.asarray(times, float)
    p = np.asarray(positions, float)
    if len(times) != len(p) or len(times) < 2 or np.any(np.diff(times) <= 0):
        raise HumanAnimError("keyed root positions need one increasing time per position")
    s = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(p[:, :2], axis=0), axis=1))]
    return Path.from_points(p), Progress(times - times[0], s)
