"""The motion QA's measures of a result against its input (numpy only).

A motion is plain arrays: bone heads in the world (F, J, 3) metres, Z up, optionally tails
(F, J, 3), local rotations (F, J, 4) as quaternions (w, x, y, z), bone names and parents, the
frame rate and the frame numbers. `measure` returns a report dict (the `qa` key of every
command's --json, see docs/qa.md); `warnings` are its lines naming frames and bones."""

import hashlib
from dataclasses import dataclass

import numpy as np

from .. import rotations
from . import thresholds as T


@dataclass
class Motion:
    heads: np.ndarray  # (F, J, 3) world positions of bone heads, metres, Z up
    rotations: np.ndarray  # (F, J, 4) local rotations (w, x, y, z)
    names: tuple
    fps: float
    parents: np.ndarray = None  # (J,), -1 for a root; without it no bone lengths
    tails: np.ndarray = None  # (F, J, 3) world positions of bone tails
    frames: np.ndarray = None  # (F,) frame numbers; default 1..F

    def __post_init__(self):
        self.heads = np.asarray(self.heads, float)
        self.rotations = np.asarray(self.rotations, float)
        if self.frames is None:
            self.frames = np.arange(1, len(self.heads) + 1, dtype=float)
        self.frames = np.asarray(self.frames, float)
        self.names = tuple(self.names)

    @property
    def frame_count(self):
        return len(self.heads)

    def points(self):
        """Every body point (heads, then tails) (F, P, 3) and the bone of each point."""
        if self.tails is None:
            return self.heads, list(self.names)
        return np.concatenate((self.heads, self.tails), axis=1), list(self.names) * 2

    def finite_frames(self):
        ok = np.isfinite(self.heads).all(axis=(1, 2)) & np.isfinite(self.rotations).all(axis=(1, 2))
        if self.tails is not None:
            ok &= np.isfinite(self.tails).all(axis=(1, 2))
        return ok

    def subset(self, keep):
        pick = (lambda a: None if a is None else a[keep])
        return Motion(self.heads[keep], self.rotations[keep], self.names, self.fps, self.parents,
                      pick(self.tails), self.frames[keep])


def feet_from_roles(roles, names):
    """{"L": [foot, toe], "R": [...]} joint indices of the feet (toe left out where the rig has
    none), from a body_roles.RoleMap."""
    index = {n: i for i, n in enumerate(names)}
    feet = {}
    for side in ("L", "R"):
        bones = [roles.bone(f"{part}.{side}") for part in ("foot", "toe")]
        joints = [index[b] for b in bones if b in index]
        if joints:
            feet[side] = joints
    return feet


def checksum(*arrays):
    """A digest of arrays (e.g. the source action's keys), to show the source was not touched."""
    h = hashlib.sha256()
    for a in arrays:
        a = np.ascontiguousarray(np.asarray(a, float))
        h.update(str(a.shape).encode())
        h.update(a.tobytes())
    return h.hexdigest()[:16]


def measure(result, source=None, feet=None, ground=None, rest_height=None, source_checksums=None, aligned=None):
    """The QA report of `result` (a Motion) against `source` (a Motion, a list of them, or None
    for a motion made from nothing, e.g. a generated walk).

    feet: {side: [joint indices]} (feet_from_roles); ground: floor height in metres (default: a
    robust floor of the source's feet); rest_height: the figure's rest height in metres (default:
    measured on the result); source_checksums: (before, after) digests of the source; aligned:
    whether the result's frames are the source's frames (default: when the counts agree; a
    retimed or joined result is not)."""
    sources = [] if source is None else list(source) if isinstance(source, (list, tuple)) else [source]
    feet = feet or {}
    finite = result.finite_frames()
    clean = result.subset(finite)
    clean_sources = [s.subset(s.finite_frames()) for s in sources]
    if aligned is None:
        aligned = len(sources) == 1 and sources[0].frame_count == result.frame_count
    pair = clean_sources[0] if aligned and clean_sources and clean_sources[0].frame_count == clean.frame_count \
        else None
    floor = ground if ground is not None else estimate_floor(clean_sources[0] if clean_sources else clean, feet)
    measures = {
        "nonfinite": _nonfinite(result, finite),
        "slide": _slide(clean, clean_sources, feet, pair),
        "penetration": _penetration(clean, clean_sources, floor, pair),
        "pop_velocity": _pops(clean, clean_sources, "velocity"),
        "pop_acceleration": _pops(clean, clean_sources, "acceleration"),
        "bone_length": _bone_lengths(clean, clean_sources),
        "figure_height": _figure_height(clean, floor, rest_height),
        "source_untouched": _source(source_checksums),
    }
    report = {"passed": all(m["passed"] is not False for m in measures.values()),
              "frames": [_frame(result.frames, 0), _frame(result.frames, -1)] if len(result.frames) else [],
              "fps": round(float(result.fps), 4), "ground_m": None if floor is None else round(float(floor), 4),
              "measures": measures, "thresholds": T.as_dict(result.fps)}
    report["warnings"] = warnings(report)
    return report


def _frame(frames, i):
    return float(frames[i])


def _item(value, unit, limit, passed, bone=None, frames=(), **extra):
    return {"value": None if value is None else round(float(value), 3), "unit": unit, "limit": limit,
            "passed": passed, "bone": bone, "frames": [float(f) for f in frames], **extra}


def _nonfinite(m, finite):
    bad = m.frames[~finite]
    count = int((~finite).sum())
    return _item(count, "frames", 0, count == 0, frames=bad[:10])


# --- planted-contact slide -------------------------------------------------------------------

def foot_points(m, feet):
    """{side: [(points (F, 3), bone name)]}: the points of each foot that can be planted: the
    foot's tail (the ball) and the toe's tail (the tip), or the heads where there are no tails."""
    out = {}
    for side, joints in feet.items():
        # the ankle (the foot's head) stands high above the floor: used only without a toe
        ends = m.heads if m.tails is None else m.tails
        pts = [(ends[:, j], m.names[j]) for j in joints]
        if m.tails is not None and len(joints) == 1:
            pts.append((m.heads[:, joints[0]], m.names[joints[0]]))
        out[side] = pts
    return out


def planted_runs(p, fps):
    """[(first, last)] frame indices of the contacts of one point p (F, 3)."""
    if len(p) < 2:
        return []
    h = p[:, 2]
    speed = np.linalg.norm(np.gradient(p[:, :2], axis=0), axis=1) * fps
    planted = (h < np.percentile(h, 5) + T.CONTACT_HEIGHT_M) & (speed < T.CONTACT_SPEED_M_S)
    shortest = max(2, int(np.ceil(T.CONTACT_MIN_SECONDS * fps)))
    edges = np.flatnonzero(np.diff(np.concatenate(([0], planted.astype(int), [0]))))
    return [(a, b - 1) for a, b in zip(edges[::2], edges[1::2]) if b - a >= shortest]


def contact_slides(m, feet):
    """{side: (worst slide m, bone, first frame, last frame)} of planted contacts: the farthest a
    planted point gets over the ground from where it was planted."""
    out = {}
    for side, pts in foot_points(m, feet).items():
        worst = (0.0, pts[0][1] if pts else None, None, None)
        for p, bone in pts:
            for a, b in planted_runs(p, m.fps):
                d = np.linalg.norm(p[a:b + 1, :2] - p[a, :2], axis=1).max()
                if d > worst[0]:
                    worst = (float(d), bone, m.frames[a], m.frames[b])
        out[side] = worst
    return out


def _slide(m, sources, feet, pair=None):
    """The worst planted-foot slide against what it may be: SLIDE_MM, or the input's own slide
    plus a margin. With a frame-aligned input (`pair`) the contacts are the input's and each is
    held to the input's own slide in it; otherwise contacts are found on the result and held to
    the input's worst."""
    if not feet:
        return _item(None, "mm", T.SLIDE_MM, None, note="no feet named by the body roles")
    if pair is not None:
        return _aligned_slide(m, pair, feet)
    slides = contact_slides(m, feet)
    own = max([s[0] for src in sources for s in contact_slides(src, feet).values()] or [0.0]) * 1000
    limit = max(T.SLIDE_MM, own + T.SLIDE_MARGIN_MM) if sources else T.SLIDE_MM
    side = max(slides, key=lambda s: slides[s][0])
    value, bone, a, b = slides[side]
    value *= 1000
    return _item(value, "mm", round(limit, 3), bool(value <= limit), bone,
                 [a, b] if a is not None else [], foot=side,
                 per_foot={s: round(v[0] * 1000, 3) for s, v in slides.items()},
                 input=round(own, 3) if sources else None)


def _aligned_slide(m, src, feet):
    worst = None  # (over the allowance, slide, allowed, own, side, bone, a, b)
    per_foot = {}
    mine, theirs = foot_points(m, feet), foot_points(src, feet)
    for side in feet:
        per_foot[side] = 0.0
        for (p, bone), (q, _) in zip(mine[side], theirs[side]):
            for a, b in planted_runs(q, src.fps):
                slide = np.linalg.norm(p[a:b + 1, :2] - p[a, :2], axis=1).max() * 1000
                own = np.linalg.norm(q[a:b + 1, :2] - q[a, :2], axis=1).max() * 1000
                allowed = max(T.SLIDE_MM, own + T.SLIDE_MARGIN_MM)
                per_foot[side] = max(per_foot[side], slide)
                if worst is None or slide - allowed > worst[0]:
                    worst = (slide - allowed, slide, allowed, own, side, bone, m.frames[a], m.frames[b])
    if worst is None:
        return _item(0.0, "mm", T.SLIDE_MM, True, per_foot={s: 0.0 for s in feet}, input=0.0)
    _, slide, allowed, own, side, bone, a, b = worst
    return _item(slide, "mm", round(allowed, 3), bool(slide <= allowed), bone, [a, b], foot=side,
                 per_foot={s: round(v, 3) for s, v in per_foot.items()}, input=round(own, 3))


# --- below the ground -------------------------------------------------------------------------

def estimate_floor(m, feet):
    """The floor under a motion: a low percentile of the lowest foot point per frame (all points
    without feet), so a few toe dips do not lower it."""
    if m.frame_count == 0:
        return None
    pts = [p for side in foot_points(m, feet).values() for p, _ in side]
    lowest = np.min([p[:, 2] for p in pts], axis=0) if pts else m.points()[0][..., 2].min(axis=1)
    return float(np.percentile(lowest, T.FLOOR_PERCENTILE))


def depths(m, floor):
    """Per frame, how far the lowest body point is below the floor (m, positive below), and which."""
    pts, bones = m.points()
    z = pts[..., 2]
    low = z.argmin(axis=1)
    return floor - z[np.arange(len(z)), low], [bones[i] for i in low]


def _penetration(m, sources, floor, pair=None):
    """Depth below the floor against what each frame may have: the threshold, or the input's own
    depth on that frame plus a margin (on every frame the input's deepest where the result's
    frames are not the input's: a retimed or joined clip)."""
    if floor is None or m.frame_count == 0:
        return _item(None, "cm", T.PENETRATION_CM, None)
    depth, bones = depths(m, floor)
    depth = depth * 100
    own = np.zeros(m.frame_count)
    for s in sources:
        if s.frame_count:
            d = depths(s, floor)[0] * 100
            own = np.maximum(own, d if s is pair else d.max())
    allowed = np.maximum(T.PENETRATION_CM, own + T.PENETRATION_MARGIN_CM) if sources else \
        np.full(m.frame_count, T.PENETRATION_CM)
    over = depth - allowed
    i = int(over.argmax()) if over.max() > 0 else int(depth.argmax())
    value = max(0.0, float(depth[i]))
    below = m.frames[depth > T.PENETRATION_FRAME_CM]
    return _item(value, "cm", round(float(allowed[i]), 3), bool(over.max() <= 0), bones[i] if value > 0 else None,
                 [m.frames[i]] if value > 0 else [], frames_below=int(len(below)),
                 first_frames_below=[float(f) for f in below[:10]],
                 input=round(float(own[i]), 3) if sources else None)


# --- pops -------------------------------------------------------------------------------------

def angular_rates(q):
    """Joint angular velocity (F-1, J) deg per frame and acceleration (F-2, J) deg per frame per
    frame of local rotations q (F, J, 4): the rotation between frames, and its change."""
    step = rotations.multiply(rotations.conjugate(q[:-1]), q[1:])
    step *= np.where(step[..., :1] < 0.0, -1.0, 1.0)  # the short way round
    sin_half = np.linalg.norm(step[..., 1:], axis=-1)
    angle = 2.0 * np.arctan2(sin_half, step[..., 0])
    axis = step[..., 1:] / np.maximum(sin_half, 1e-12)[..., None]
    rotvec = np.degrees(axis * angle[..., None])
    return np.linalg.norm(rotvec, axis=-1), np.linalg.norm(np.diff(rotvec, axis=0), axis=-1)


def _pops(m, sources, kind):
    which = 0 if kind == "velocity" else 1
    rates = T.per_frame(m.fps)
    margin, cap = rates[f"pop_{kind}_margin_deg"], rates[f"pop_{kind}_cap_deg"]
    unit = "deg/frame" if kind == "velocity" else "deg/frame^2"
    res = angular_rates(m.rotations)[which] if m.frame_count > 2 else np.zeros((0, len(m.names)))
    if len(res) == 0:
        return _item(0.0, unit, round(margin, 3), True)
    refs = [angular_rates(s.rotations)[which] for s in sources
            if s.frame_count > 2 and s.rotations.shape[1] == m.rotations.shape[1]]
    if refs:
        own = np.max([r.max(axis=0) for r in refs], axis=0)
        allowed = T.POP_RATIO * own + margin  # a retimed motion may be a little faster
        excess, limit = res - allowed, None
    else:
        own, excess, limit = None, res, cap
    worst = excess if excess.max() > 0.0 else res  # the worst pop, else the fastest joint
    t, j = np.unravel_index(int(worst.argmax()), worst.shape)
    frame = m.frames[t + 1]  # the frame that arrives with the jump
    if own is None:
        value = float(res[t, j])
        return _item(value, unit, round(cap, 3), bool(value <= cap), m.names[j], [frame], result=round(value, 3),
                     input=None)
    value = float(res[t, j])
    return _item(value, unit, round(float(allowed[j]), 3), bool(excess[t, j] <= 0.0), m.names[j], [frame],
                 result=round(value, 3), input=round(float(own[j]), 3))


# --- bone lengths and height ------------------------------------------------------------------

def bone_lengths(m):
    """Head-to-parent-head distances (F, J), NaN for roots."""
    parents = np.asarray(m.parents)
    d = np.linalg.norm(m.heads - m.heads[:, np.maximum(parents, 0)], axis=-1)
    d[:, parents < 0] = np.nan
    return d


def _bone_lengths(m, sources):
    """The largest change of a bone's length against the input's first frame (the result's own
    without an input). The root's children (root motion lives there) and joints that move against
    their parent in the input (position channels) are no bones and are left out."""
    if m.parents is None or m.frame_count == 0:
        return _item(None, "%", T.BONE_LENGTH_PCT, None)
    lengths = bone_lengths(m)
    parents = np.asarray(m.parents)
    ref_motion = next((s for s in sources if s.frame_count and s.heads.shape[1] == m.heads.shape[1]), None)
    if ref_motion is not None:
        own = bone_lengths(ref_motion)
        ref = own[0]
        dev = np.abs(own / np.where(ref > 0, ref, 1.0) - 1.0)
        rigid = np.where(np.isfinite(dev), dev, 0.0).max(axis=0) * 100 < T.BONE_LENGTH_PCT / 2
    else:
        ref = lengths[0]
        rigid = np.ones(len(parents), bool)
    use = np.isfinite(ref) & (ref > T.BONE_MIN_LENGTH_M) & rigid & (parents >= 0) & (parents[np.maximum(parents, 0)] >= 0)
    if not use.any():
        return _item(0.0, "%", T.BONE_LENGTH_PCT, True)
    change = np.where(use, np.abs(lengths / np.where(use, ref, 1.0) - 1.0) * 100, 0.0)
    t, j = np.unravel_index(int(np.nan_to_num(change).argmax()), change.shape)
    value = float(change[t, j])
    return _item(value, "%", T.BONE_LENGTH_PCT, bool(value <= T.BONE_LENGTH_PCT),
                 m.names[j] if value > 0 else None, [m.frames[t]] if value > 0 else [])


def _figure_height(m, floor, rest_height):
    if rest_height is None:
        if m.frame_count == 0:
            return _item(None, "m", list(T.FIGURE_HEIGHT_M), None)
        z = m.points()[0][..., 2]
        rest_height = float(np.percentile(z.max(axis=1) - (z.min(axis=1) if floor is None else floor), 95))
    lo, hi = T.FIGURE_HEIGHT_M
    return _item(rest_height, "m", [lo, hi], bool(lo <= rest_height <= hi))


def _source(checksums):
    if checksums is None:
        return _item(None, "", None, None)
    before, after = checksums
    return {**_item(None, "", None, before == after), "value": before == after}


from .report import warnings  # noqa: E402  (the report reads the measures above)
