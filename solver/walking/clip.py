"""Skeletons from BVH files without Blender (for the CLI, tests and benchmark), and the gait of a
motion measured the same way for a mocap clip and a generated walk: heel strikes and supports from
the contact detector (motion_control.contacts), cycle length and duration, double-support share,
pelvis oscillation."""

import numpy as np

from .. import bvh, units
from ..motion_control.contacts import runs, support_intervals
from ..role_detection import detect_roles


def load_bvh(path):
    """(skeleton, trajectories) of a BVH file, its unit guessed as the importer does, its body
    roles detected as the add-on detects them (names, hierarchy, geometry)."""
    with open(path) as f:
        text = f.read()
    scale, _ = units.guess_length_scale(units.bvh_rest_extent(text))
    clip = bvh.parse(text, scale)
    roles = detect_roles(clip.names, clip.parents, bvh.rest_heads(clip), bvh.rest_tails(clip)).roles
    sk = bvh.skeleton(clip, roles=roles)
    return sk, bvh.trajectories(clip, sk)


# The clip's floor is its lowest point (in a crouch); walking, its soles stay 5-7 cm above it
CLIP_CONTACT = {"h_on": 0.09, "h_off": 0.12}


def gait(skeleton, traj, support=None, min_speed=0.3):
    """Gait figures of the walking part of a motion (between the first and last heel strike of
    full cycles): per cycle, length (m) and duration (s); mean speed; double-support share;
    pelvis vertical and lateral oscillation (peak to peak, m, mean over cycles)."""
    support = support or support_intervals(skeleton, traj, **CLIP_CONTACT)
    w = traj.world_frames(skeleton)
    fps = traj.fps
    root = w[:, skeleton.root, :3, 3]
    cycles = []
    for side, on in support.items():
        foot = w[:, skeleton.role_index(f"foot.{side}"), :3, 3]
        stances = [(a, b) for v, a, b in runs(on) if v and a > 0 and b < len(on)]
        for (a0, b0), (a1, b1) in zip(stances[:-1], stances[1:]):
            mid0, mid1 = (a0 + b0) // 2, (a1 + b1) // 2
            length = float(np.linalg.norm(foot[mid1, :2] - foot[mid0, :2]))
            dur = (a1 - a0) / fps
            travel = float(np.linalg.norm(root[a1, :2] - root[a0, :2]))
            if length < 0.2 or travel / dur < min_speed:  # shuffles and turns on the spot are not cycles
                continue
            seg = root[a0:a1 + 1]
            heading = (seg[-1, :2] - seg[0, :2]) / max(np.linalg.norm(seg[-1, :2] - seg[0, :2]), 1e-9)
            lateral = (seg[:, :2] - seg[0, :2]) @ np.array([heading[1], -heading[0]])
            lateral -= np.linspace(lateral[0], lateral[-1], len(lateral))
            both = np.mean(support["L"][a0:a1] & support["R"][a0:a1])
            cycles.append({"side": side, "start_frame": float(traj.frames[a0]), "length_m": length,
                           "duration_s": dur, "speed_m_s": travel / dur, "double_support_share": float(both),
                           "pelvis_vertical_m": float(np.ptp(seg[:, 2])), "pelvis_lateral_m": float(np.ptp(lateral))})
    if not cycles:
        return {"cycles": 0}
    keys = ("length_m", "duration_s", "speed_m_s", "double_support_share", "pelvis_vertical_m", "pelvis_lateral_m")
    out = {k: float(np.mean([c[k] for c in cycles])) for k in keys}
    out["cycles"] = len(cycles)
    out["per_cycle"] = cycles
    return out


# ---- gait of any motion: the same measure for a capture and a generated walk --------------------

def _extrema(x, fps, window_s=0.25, prominence=0.05):
    """Frames of the local maxima of x: the largest within +-window_s, standing out by
    `prominence` (m) from the smallest within twice that."""
    h, out = max(1, int(window_s * fps)), []
    for i in range(h, len(x) - h):
        near, wide = x[i - h:i + h + 1], x[max(0, i - 2 * h):i + 2 * h + 1]
        if x[i] == near.max() and x[i] - wide.min() > prominence and (not out or i - out[-1] > h):
            out.append(i)
    return np.array(out, int)


def _toe(skeleton, side, w):
    """World (F, 3) tip of a foot: the toe bone's tail, or the foot bone's where there is no toe."""
    toe = skeleton.role_index(f"toe.{side}")
    j = toe if toe is not None and skeleton.lengths[toe] > 0.02 else skeleton.role_index(f"foot.{side}")
    return w[:, j, :3, 3] + w[:, j, :3, 1] * skeleton.lengths[j]


def gait_events(skeleton, traj, w=None):
    """Heel strikes and toe offs of each foot from the feet's motion against the pelvis along the
    walking direction, with no threshold on heights or floor (Zeni, Richards and Higginson 2008):
    a heel strikes when the ankle is farthest ahead of the pelvis, a foot leaves when its tip is
    farthest behind (both come a little early for strikes and late for toe offs, the more so the
    more slowly a foot lands and leaves: the double support they give is an upper bound). Returns {side: (strike frames, toe-off frames)} and the pelvis (F, 3) (the
    middle of the hip joints)."""
    w = traj.world_frames(skeleton) if w is None else w
    fps, n = traj.fps, len(w)
    pelvis = 0.5 * (w[:, skeleton.role_index("thigh.L"), :3, 3] + w[:, skeleton.role_index("thigh.R"), :3, 3])
    h = max(1, int(0.5 * fps))  # the walking direction: the pelvis's travel over a second
    ahead = pelvis[np.minimum(np.arange(n) + h, n - 1), :2] - pelvis[np.maximum(np.arange(n) - h, 0), :2]
    direction = ahead / np.maximum(np.linalg.norm(ahead, axis=1, keepdims=True), 1e-9)
    events = {}
    for side in "LR":
        ankle = w[:, skeleton.role_index(f"foot.{side}"), :3, 3]
        heel = np.einsum("fi,fi->f", ankle[:, :2] - pelvis[:, :2], direction)
        tip = np.einsum("fi,fi->f", _toe(skeleton, side, w)[:, :2] - pelvis[:, :2], direction)
        events[side] = (_extrema(heel, fps), _extrema(-tip, fps))
    return events, pelvis



def measure_gait(skeleton, traj, min_speed=0.3, w=None):
    """Gait figures of the walking cycles of a motion, the same for a capture and a generated walk:
    per cycle (a heel strike to the same foot's next one, at a mean speed above min_speed) its
    length and duration, speed, double-support share (both feet between a strike and their next
    toe off, gait_events) and the pelvis's lateral sway and vertical bounce (peak to peak about the
    line through its start and end); and their means."""
    w = traj.world_frames(skeleton) if w is None else w
    events, pelvis = gait_events(skeleton, traj, w)
    fps, n = traj.fps, len(w)
    down = {}
    for side, (strikes, offs) in events.items():
        down[side] = np.zeros(n, bool)
        for s in strikes:
            later = offs[offs > s]
            if len(later):
                down[side][s:later[0] + 1] = True
    cycles = []
    for side, (strikes, _) in events.items():
        for a, b in zip(strikes[:-1], strikes[1:]):
            seg = pelvis[a:b + 1]
            chord = seg[-1, :2] - seg[0, :2]
            length = float(np.linalg.norm(chord))
            dur = (b - a) / fps
            if length / dur < min_speed or not 0.4 < dur < 2.5:
                continue
            u = chord / length
            lateral = (seg[:, :2] - seg[0, :2]) @ np.array([u[1], -u[0]])
            vertical = seg[:, 2] - np.linspace(seg[0, 2], seg[-1, 2], len(seg))
            cycles.append({"side": side, "start_frame": float(traj.frames[a]), "length_m": length,
                           "duration_s": dur, "speed_m_s": length / dur,
                           "double_support_share": float(np.mean(down["L"][a:b] & down["R"][a:b])),
                           "pelvis_lateral_m": float(np.ptp(lateral)), "pelvis_vertical_m": float(np.ptp(vertical))})
    if not cycles:
        return {"cycles": 0, "per_cycle": []}
    keys = ("length_m", "duration_s", "speed_m_s", "double_support_share", "pelvis_lateral_m", "pelvis_vertical_m")
    out = {k: float(np.mean([c[k] for c in cycles])) for k in keys}
    out.update(cycles=len(cycles), per_cycle=cycles)
    return out
