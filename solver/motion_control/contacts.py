"""Foot support intervals from a motion (Oshita 2003, sec. 2.3.2 and 3.3: the frames when each foot
lands and leaves must be known to hold a supporting foot in place).

A foot is on the ground while any of its contact points (the four sole points of the foot bone and
the two under the toe tip, dynamics.default_contacts) is low and slow. Hysteresis keeps a point
down until it clearly rises (above h_off) or slides (faster than v_off), so noise near the
thresholds does not flicker; intervals (on and off) shorter than `min_duration` inside the clip
are then merged into their neighbours. Heights are measured from the motion's floor
(contact_floor: where the soles rest while they support the body, a robust statistic of the
heights at contact frames, so that one toe dipping through a capture's floor does not lower it).
"""

from dataclasses import dataclass

import numpy as np

from ..body_roles import SIDES
from ..dynamics import build_model, default_contacts, kinematics, motion_floor
from ..dynamics.closed_loop import desired_motion


@dataclass(frozen=True)
class Contact:
    """An animator's override: foot `side` ("L" or "R") is on (True) or off the ground from
    `start_frame` to `end_frame` inclusive (Blender frame numbers)."""

    side: str
    start_frame: float
    end_frame: float
    on: bool = True


def support_intervals(skeleton, trajectories, overrides=(), h_on=0.05, h_off=0.07, v_on=0.4,
                      v_off=1.0, min_duration=0.08, floor=None):
    """Per side ("L", "R") a bool array (F,): the foot supports the body at that frame.

    h_on/h_off in metres above the floor, v_on/v_off horizontal speeds in m/s, min_duration in
    seconds; overrides (Contact, or (side, start, end, on) tuples) are applied last."""
    heights, speeds = foot_point_tracks(skeleton, trajectories, floor)
    min_frames = max(1, int(round(min_duration * trajectories.fps)))
    out = {}
    for side in SIDES:
        if side not in heights:
            continue
        down = hysteresis(heights[side] < h_on, speeds[side] < v_on,
                          (heights[side] > h_off) | (speeds[side] > v_off))
        out[side] = remove_short_runs(down.any(axis=1), min_frames)
    return apply_overrides(out, trajectories.frames, overrides)


def foot_point_tracks(skeleton, trajectories, floor=None):
    """Per side, heights above the floor (F, k) and horizontal speeds (F, k) of the foot's and
    toe's contact points."""
    tr = trajectories
    model = build_model(skeleton, reference_basis=tr.basis()[0])
    contacts = default_contacts(model)
    if floor is None:
        floor = contact_floor(skeleton, tr)
    world = tr.world_frames(skeleton)[:, contacts.joints]  # (F, k, 4, 4)
    points = np.einsum("fkij,kj->fki", world[..., :3, :3], contacts.points) + world[..., :3, 3]
    speed = np.linalg.norm(np.gradient(points[..., :2], axis=0), axis=-1) * tr.fps if tr.frame_count > 1 \
        else np.zeros(points.shape[:2])
    heights, speeds = {}, {}
    for side in SIDES:
        bones = [skeleton.role_index(f"{r}.{side}") for r in ("foot", "toe")]
        sel = np.isin(contacts.joints, [b for b in bones if b is not None])
        if sel.any():
            heights[side] = points[:, sel, 2] - contacts.radii[sel] - floor
            speeds[side] = speed[:, sel]
    return heights, speeds


def contact_floor(skeleton, trajectories, h_on=0.05, v_on=0.4, spread=3.0, min_tolerance=0.01):
    """Height (m) of the floor the motion stands on: the lowest point the body reaches (any
    contact sphere, dynamics.default_contacts) over the frames where it rests on the floor (a foot
    is slow, and the body within h_on of the median such height), leaving out outliers: heights
    more than `spread` robust deviations (1.4826 MAD), and at least `min_tolerance`, below that
    median. A capture's floor shows where the body rests, frame after frame; a few frames of a
    toe dipping below it (marker noise, a bad solve) or of a made-up bone tail reaching through it
    are outliers, and taking the lowest point of the whole motion instead
    (closed_loop.motion_floor) lifted every other frame's soles off the ground, so that no
    standing foot was found and held. On a clip without outliers both are the same point. A
    motion with no foot roles, or whose feet are never slow, falls back to motion_floor."""
    _, speeds = foot_point_tracks(skeleton, trajectories, floor=0.0)
    slow = np.any([s.min(axis=1) < v_on for s in speeds.values()], axis=0) if speeds else None
    if slow is None or not slow.any():
        return motion_floor(skeleton, trajectories)
    low = body_lowest_points(skeleton, trajectories)
    resting = low[slow]
    for _ in range(2):  # the resting frames around the median, then their median again
        middle = float(np.median(resting))
        resting = low[slow & (low < middle + h_on)]
    middle = float(np.median(resting))
    tolerance = max(spread * 1.4826 * float(np.median(np.abs(resting - middle))), min_tolerance)
    return float(resting[resting >= middle - tolerance].min())


def body_lowest_points(skeleton, trajectories):
    """(F,) the height of the lowest contact sphere's bottom at each frame."""
    model = build_model(skeleton, reference_basis=trajectories.basis()[0])
    contacts = default_contacts(model)
    qs = desired_motion(model, skeleton, trajectories)[0]
    heights = kinematics.batch_point_positions(model, qs, contacts.joints, contacts.points)[..., 2]
    return (heights - contacts.radii).min(axis=1)


def hysteresis(low, slow, leave):
    """(F, k) state of a Schmitt trigger per point: on when low and slow, off when `leave`."""
    state = np.zeros(low.shape, bool)
    cur = low[0] & slow[0]
    for f in range(len(low)):
        cur = np.where(cur, ~leave[f], low[f] & slow[f])
        state[f] = cur
    return state


def runs(mask):
    """(value, start, stop) of the constant runs of a bool array, stop exclusive."""
    mask = np.asarray(mask, bool)
    edges = np.flatnonzero(np.diff(mask.astype(int))) + 1
    starts = np.concatenate(([0], edges))
    stops = np.concatenate((edges, [len(mask)]))
    return [(bool(mask[a]), int(a), int(b)) for a, b in zip(starts, stops)]


def remove_short_runs(mask, min_frames):
    """Flip runs shorter than min_frames that lie inside the clip (a run touching either end is
    cut by the clip, not short), shortest first, so a flicker merges into its surroundings."""
    mask = np.array(mask, bool)
    while True:
        inner = [r for r in runs(mask)[1:-1] if r[2] - r[1] < min_frames]
        if not inner:
            return mask
        value, a, b = min(inner, key=lambda r: r[2] - r[1])
        mask[a:b] = not value


def apply_overrides(support, frames, overrides):
    out = {k: v.copy() for k, v in support.items()}
    for o in overrides:
        o = o if isinstance(o, Contact) else Contact(*o)
        if o.side not in SIDES:
            raise ValueError(f"contact side must be 'L' or 'R', not {o.side!r}")
        sel = (frames >= o.start_frame) & (frames <= o.end_frame)
        out.setdefault(o.side, np.zeros(len(frames), bool))[sel] = bool(o.on)
    return out


def support_phases(support):
    """Per frame: 0 flight, 1 single support, 2 double support."""
    return sum(np.asarray(v, int) for v in support.values())
