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
