"""Measures of a transition: how far planted feet move, and acceleration spikes compared with the
source clips' own accelerations."""

import numpy as np

from .. import rotations
from ..dynamics import spatial


def foot_points(skeleton, tr, side):
    """World positions (F, 3, 3) of the foot's ankle, ball and toe tip."""
    sk = skeleton
    world = tr.world_frames(sk)
    foot, toe = sk.role_index(f"foot.{side}"), sk.role_index(f"toe.{side}")
    pts = [world[:, foot, :3, 3], world[:, foot, :3, 3] + world[:, foot, :3, 1] * sk.lengths[foot]]
    if toe is not None:
        pts.append(world[:, toe, :3, 3] + world[:, toe, :3, 1] * sk.lengths[toe])
    return np.stack(pts, axis=1)


def planted_slide(skeleton, tr, masks, window=None, inside=False):
    """Largest distance (m) a planted foot's points move within each run of `masks` (side ->
    (F,) bool) that overlaps `window` (first, last frame index): side -> metres. inside=True
    measures only the run's frames inside the window."""
    from ..motion_control.contacts import runs
    out = {}
    for side, m in masks.items():
        pts = foot_points(skeleton, tr, side)
        worst = 0.0
        for on, a, b in runs(m):
            if not on or (window is not None and (b - 1 < window[0] or a > window[1])):
                continue
            if inside and window is not None:
                a, b = max(a, window[0]), min(b, window[1] + 1)
            seg = pts[a:b]
            worst = max(worst, float(np.linalg.norm(seg - seg[0], axis=-1).max()))
        out[side] = worst
    return out


def acceleration_profile(skeleton, tr):
    """Per frame the largest angular acceleration (rad/s^2) of any joint's local rotation, and the
    root's linear acceleration (m/s^2): (F,), (F,). Ends are padded with their neighbour."""
    q = rotations.make_continuous(tr.rotations)
    w = spatial.quat_log(rotations.multiply(rotations.conjugate(q[:-1]), q[1:])) * tr.fps  # (F-1, J, 3)
    a = np.linalg.norm(np.diff(w, axis=0), axis=-1).max(axis=1) * tr.fps  # (F-2,)
    pos, _ = tr.root_pose(skeleton)
    lin = np.linalg.norm(np.diff(pos, 2, axis=0), axis=-1) * tr.fps ** 2
    pad = lambda x: np.concatenate(([x[0]], x, [x[-1]])) if len(x) else np.zeros(tr.frame_count)
    return pad(a), pad(lin)


def spike_ratio(skeleton, joined, window, sources, margin=1):
    """Largest joint and root acceleration inside the transition window (+- margin frames) over
    the 99th percentile of the source clips' own accelerations (all their frames together):
    (angular ratio, linear ratio); at most 1 means no spike above the clips' own."""
    a, lin = acceleration_profile(skeleton, joined)
    lo, hi = max(0, window[0] - margin), min(len(a), window[1] + margin + 1)
    prof = [acceleration_profile(skeleton, s) for s in sources]
    ref_a = np.percentile(np.concatenate([p[0] for p in prof]), 99)
    ref_l = np.percentile(np.concatenate([p[1] for p in prof]), 99)
    return float(a[lo:hi].max() / max(ref_a, 1e-9)), float(lin[lo:hi].max() / max(ref_l, 1e-9))
