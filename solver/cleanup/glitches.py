"""Glitch repair on plain arrays: dropouts (held or zero frames), single- and few-frame rotation
flips and spikes, rotation steps (a joint that jumps and stays), position spikes, and the sign
continuity of every quaternion channel.

A glitch is told from fast intended motion by speed: no human joint turns faster than about
1800 deg/s (a pitcher's elbow; a kick's knee stays near 1500), and no root moves faster than
about 5 g. A burst of steps above that speed that comes back (the rotation after it is close
to the one before) is a spike: its frames are refilled from their neighbours by a cubic spline
through the good frames. A burst that does not come back is a step: the frames after it are
turned back by the jump (less the motion the neighbours predict), so the joint stays continuous.

Arrays: local quaternions (F, J, 4) (w, x, y, z); positions (F, K, 3) in metres; fps.
"""

import numpy as np
from scipy.interpolate import CubicSpline

from .. import rotations
from ..dynamics.spatial import quat_exp, quat_log

MAX_JOINT_SPEED_DEG_S = 1800.0
MAX_ROOT_ACCEL_M_S2 = 50.0  # a hard landing; a spike is a jump out and back at once
MAX_GLITCH_SECONDS = 0.2  # longer runs are motion, not a glitch
MIN_GLITCH_FRAMES = 10
# a burst that does not come back is repaired only if one of its steps is this large (and twice
# the speed limit): a fast turn that stays is more likely motion than a glitch
STEP_MIN_DEG = 30.0


def max_run(fps):
    return max(MIN_GLITCH_FRAMES, int(round(MAX_GLITCH_SECONDS * fps)))


def dropouts(quats, positions, fps, tolerance=1e-9):
    """Bool (F,): frames of short dropouts, frames that repeat the frame before exactly (held) or
    whose every rotation is the identity and every position zero (zeroed), in runs of at most
    max_run(fps) frames inside moving motion."""
    F = len(quats)
    flat = np.concatenate((quats.reshape(F, -1), positions.reshape(F, -1)), axis=1)
    held = np.zeros(F, bool)
    held[1:] = np.all(np.abs(np.diff(flat, axis=0)) <= tolerance, axis=1)
    zero = np.all(np.abs(np.abs(quats[..., 0]) - 1.0) <= tolerance, axis=1) & np.all(
        np.abs(positions) <= tolerance, axis=(1, 2))
    bad = held | zero
    out = np.zeros(F, bool)
    for a, b in _runs(bad):
        if b - a <= max_run(fps) and a > 0 and b < F:  # a run reaching a clip end is no dropout
            out[a:b] = True
    return out


def _runs(mask):
    edges = np.flatnonzero(np.diff(np.concatenate(([0], np.asarray(mask, int), [0]))))
    return list(zip(edges[::2], edges[1::2]))


def fill(values, bad, kind="rotation"):
    """Frames `bad` of values (F, K, 4 or 3) refilled from their neighbours, per channel and per
    run of bad frames by whichever of two fillers predicts that channel's own known frames better
    (cross-validated on runs of the same length beside the gap): a cubic spline through the good
    frames (smooth motion), or the best-matching stretch of the channel elsewhere in the clip,
    warped onto the gap's ends (repeated motion: a wave, a gait cycle). Quaternions are filled on
    the hemisphere of their good neighbours and normalised."""
    out = np.array(values, float)
    bad = np.asarray(bad, bool)
    good = np.flatnonzero(~bad)
    if len(good) < 2 or not bad.any():
        return out
    if kind == "rotation":
        out[good] = rotations.make_continuous(out[good])
    out = _spline_fill(out, bad)
    channels = out if out.ndim == 3 else out[:, None]  # a view: one channel (F, d) as (F, 1, d)
    for a, b in _runs(bad):
        for k in range(channels.shape[1]):
            patch = _best_fill(channels[:, k], bad, a, b, kind == "rotation")
            if patch is not None:
                channels[a:b, k] = patch
    if kind == "rotation":
        out = rotations.make_continuous(rotations.normalize(out))
    return out


def _spline_fill(values, bad):
    """Bad frames of values (F, ...) from a cubic spline through the others (held at the ends)."""
    out = values.copy()
    good = np.flatnonzero(~bad)
    if len(good) < 2:
        return out
    spline = CubicSpline(good, values[good], axis=0)
    idx = np.flatnonzero(bad)
    inside = (idx > good[0]) & (idx < good[-1])
    out[idx[inside]] = spline(idx[inside])
    out[idx[~inside]] = values[good[np.abs(good[:, None] - idx[~inside][None]).argmin(axis=0)]]
    return out


def _context(n):
    return max(3, min(n, 10))


def _exemplar(v, usable, a, b, rotation):
    """Frames a..b-1 of one channel v (F, d) from the stretch elsewhere (all `usable`) whose
    context (the frames just before and after) best matches the gap's, offset by the mismatch at
    the gap's two ends, blended linearly across it (motion warping); None if none fits."""
    F, n, c = len(v), b - a, _context(b - a)
    if a - c < 0 or b + c > F:
        return None
    span = n + 2 * c
    starts = np.arange(0, F - span + 1)
    ok = np.array([usable[s:s + span].all() for s in starts]) & ((starts + span <= a - c) | (starts >= b + c))
    if not ok.any():
        return None
    starts = starts[ok]
    ctx = np.r_[np.arange(c), np.arange(c + n, span)]
    windows = v[starts[:, None] + np.arange(span)]  # (S, span, d)
    target = np.concatenate((v[a - c:a], v[b:b + c]))
    if rotation:  # a quaternion stretch on the far hemisphere is the same rotation
        windows = windows * np.sign(np.sum(windows[:, c - 1] * v[a - 1], axis=-1) + 1e-12)[:, None, None]
    diff = target[None] - windows[:, ctx]
    if not rotation:  # a position stretch may be anywhere: compare its shape
        diff -= diff.mean(axis=1, keepdims=True)
    cost = np.sum(diff ** 2, axis=(1, 2))
    # a stretch with a jump far beyond the steps around the gap (another glitch) is no model
    calm = 3 * max(np.linalg.norm(np.diff(target[:c], axis=0), axis=-1).max(initial=0.0),
                   np.linalg.norm(np.diff(target[c:], axis=0), axis=-1).max(initial=0.0)) + 1e-9
    cost[np.linalg.norm(np.diff(windows, axis=1), axis=-1).max(axis=1) > calm] = np.inf
    if not np.isfinite(cost).any():
        return None
    best = np.argmin(cost)
    window = windows[best]
    w = (np.arange(1, n + 1) / (n + 1))[:, None]
    left, right = v[a - 1] - window[c - 1], v[b] - window[c + n]
    return window[c:c + n] + (1 - w) * left + w * right


def _best_fill(v, bad, a, b, rotation):
    """The exemplar filling of gap a..b-1 of channel v (F, d) if it predicts known runs of the same
    length beside the gap better than the spline does (None: keep the spline)."""
    n, F = b - a, len(v)
    errors = np.zeros(2)
    tested = 0
    for shift in (-(n + _context(n)), n + _context(n), -2 * (n + _context(n)), 2 * (n + _context(n))):
        ta, tb = a + shift, b + shift
        if ta - 1 < 0 or tb + 1 > F or bad[max(ta - 1, 0):tb + 1].any():
            continue
        hidden = bad.copy()
        hidden[ta:tb] = True
        ex = _exemplar(v, ~hidden, ta, tb, rotation)
        if ex is None:
            continue
        sp = _spline_fill(v, hidden)[ta:tb]
        errors += [np.sum((sp - v[ta:tb]) ** 2), np.sum((ex - v[ta:tb]) ** 2)]
        tested += 1
        if tested == 2:
            break
    if not tested or errors[1] >= 0.5 * errors[0]:  # clearly better, or the spline
        return None
    return _exemplar(v, ~bad, a, b, rotation)


def _bursts(step, limit, low):
    """Runs (first step, last step) of steps above `low` that contain one above `limit`."""
    out = []
    for a, b in _runs(step > low):
        if (step[a:b] > limit).any():
            out.append((a, b - 1))
    return out


def rotation_glitches(q, fps, strength=1.0):
    """One joint's quaternions (F, 4): the repaired copy and the events [(kind, first, last
    frame index)]. Step i is the rotation from frame i to i + 1."""
    q = rotations.make_continuous(rotations.normalize(np.asarray(q, float)))
    F = len(q)
    if F < 3:
        return q, []
    limit = np.radians(MAX_JOINT_SPEED_DEG_S) / fps / max(strength, 1e-3)
    hard = max(2 * limit, np.radians(STEP_MIN_DEG))
    events, passed = [], set()
    for _ in range(64):  # each pass repairs the first glitch; a step changes the frames after it
        step = rotations.angle_between(q[:-1], q[1:])
        bursts = [(a, b) for a, b in _bursts(step, limit, limit / 3) if a not in passed]
        if not bursts:
            break
        a, b = bursts[0]  # frames a .. b + 1 take part; a is the last good frame before
        end = _return(q, step, bursts, a, fps)
        if end is not None:  # a spike: frames a+1 .. end-1 are wrong
            bad = np.zeros(F, bool)
            bad[a + 1:end] = True
            q = fill(q, bad)
            events.append(("spike", a + 1, end - 1))
        elif step[a:b + 1].max() >= hard:  # a jump no joint makes, and it stays
            q = _remove_step(q, a, b + 1)
            events.append(("step", a + 1, b + 1))
        passed.add(a)
    return q, events


def _return(q, step, bursts, a, fps):
    """The first frame after a burst starting at step a where the rotation is back near frame a's
    (within max_run frames): that frame, or None."""
    span = max_run(fps)
    path = 0.0
    for a2, b2 in bursts:
        if a2 > a + span:
            break
        path += step[a2:b2 + 1].sum()
        end = b2 + 1
        if end < len(q) and rotations.angle_between(q[a], q[end]) < 0.25 * path \
                and end - a - 1 <= span:
            return end
    return None


def _remove_step(q, a, e):
    """Frames e.. turned so frame e follows frame a by the motion its neighbours predict."""
    v_in = quat_log(rotations.multiply(rotations.conjugate(q[max(a - 1, 0)]), q[a]))
    v_out = quat_log(rotations.multiply(rotations.conjugate(q[e]), q[min(e + 1, len(q) - 1)]))
    predicted = rotations.multiply(q[a], quat_exp(0.5 * (v_in + v_out) * (e - a)))
    offset = rotations.multiply(rotations.conjugate(q[e]), predicted)
    out = q.copy()
    out[e:] = rotations.multiply(q[e:], offset)
    bad = np.zeros(len(q), bool)
    bad[a + 1:e] = True
    return fill(out, bad)


def position_spikes(p, fps, strength=1.0):
    """One point's positions (F, 3): the repaired copy and its spikes [("spike", first, last)]:
    runs entered and left with a change of velocity no body makes (beyond MAX_ROOT_ACCEL_M_S2,
    and 1 cm) that come back near where they started."""
    p = np.array(p, float)
    if len(p) < 5:
        return p, []
    steps = np.diff(p, axis=0)
    # each step against the local velocity (the median of its neighbours'): a jump out and back
    # stands out however fast the body travels
    pad = np.pad(steps, ((3, 3), (0, 0)), mode="edge")
    around = np.stack([pad[k:k + len(steps)] for k in (0, 1, 2, 4, 5, 6)])
    departure = steps - np.median(around, axis=0)
    step = np.linalg.norm(departure, axis=1)
    limit = max(MAX_ROOT_ACCEL_M_S2 / fps ** 2, 0.01) / max(strength, 1e-3)
    events, bad = [], np.zeros(len(p), bool)
    # the change of velocity from one step to the next: a jump out and straight back changes it
    # by twice the jump
    change = np.zeros(len(step) + 1)
    change[1:-1] = np.linalg.norm(np.diff(departure, axis=0), axis=1)
    bursts = [(a, b) for a, b in _runs(step > limit / 3)
              if (step[a:b] > limit).any() or (change[a:b + 1] > limit).any()]
    bursts = [(a, b - 1) for a, b in bursts]
    for i, (a, b) in enumerate(bursts):
        if bad[a + 1]:
            continue
        path = 0.0
        for a2, b2 in bursts[i:]:
            if a2 > a + max_run(fps):
                break
            path += step[a2:b2 + 1].sum()
            end = b2 + 1
            if end < len(p) and np.linalg.norm(p[end] - p[a] - (end - a) * np.median(around[:, a], axis=0)) \
                    < 0.25 * path:
                bad[a + 1:end] = True
                events.append(("spike", a + 1, end - 1))
                break
    return fill(p, bad, "position"), events


def repair(quats, positions, fps, strength=1.0):
    """Every glitch of a motion: quats (F, J, 4), positions (F, K, 3) (the root's and any other
    translating joint's). Returns repaired copies and events [(kind, channel, first, last)],
    channel a joint index ('rotation'), a point index ('position') or None (the whole pose)."""
    quats = rotations.make_continuous(rotations.normalize(np.asarray(quats, float)))
    positions = np.array(positions, float)
    events = []
    gone = dropouts(quats, positions, fps)
    if gone.any():
        quats, positions = fill(quats, gone), fill(positions, gone, "position")
        events += [("dropout", None, int(a), int(b - 1)) for a, b in _runs(gone)]
    for j in range(quats.shape[1]):
        quats[:, j], found = rotation_glitches(quats[:, j], fps, strength)
        events += [(kind, ("rotation", j), a, b) for kind, a, b in found]
    for k in range(positions.shape[1]):
        positions[:, k], found = position_spikes(positions[:, k], fps, strength)
        events += [(kind, ("position", k), a, b) for kind, a, b in found]
    return rotations.make_continuous(quats), positions, events
