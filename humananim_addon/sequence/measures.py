"""Errors of a result against its source, per channel and at the bones' tails."""

import time

import numpy as np

from ...solver import rotations
from ...solver.trajectories import Trajectories
from ...solver.sequence import error_measures, key_reduction
from .channels import as_quaternions


def group_errors(groups, a, b):
    """Largest rotation error (degrees, whole bone rotation), location error (cm) and other
    value error, between sample lists a and b, and the label where each happened."""
    out = {"deg": (0.0, ""), "cm": (0.0, ""), "value": (0.0, "")}
    for g, x, y in zip(groups, a, b):
        if g.kind in ("quaternion", "axis_angle"):
            e, key = float(error_measures.rotation_error_deg(as_quaternions(g, x), as_quaternions(g, y)).max()), "deg"
        elif g.kind == "euler":
            e, key = float(error_measures.euler_error_deg(x, y, g.order).max()), "deg"
        elif g.kind == "location":
            e, key = float(error_measures.location_error_cm(x * g.scale, y * g.scale).max()), "cm"
        else:
            e, key = float(np.abs(x - y).max()), "value"
        if e > out[key][0]:
            out[key] = (e, g.label)
    return out


def source_motion(obj, scene, source, frames):
    """(skeleton, the source action's trajectories over `frames`) of an armature, read once for the
    tail measures (None when obj is no armature)."""
    if obj.type != "ARMATURE":
        return None
    from ..actions import read_action
    from ..armature import skeleton_from_armature
    skeleton = skeleton_from_armature(obj, scene, require=False)
    return skeleton, read_action(obj, scene, skeleton, source, (frames[0], frames[-1]), exact=False)


def _played(motion, groups, frames, results):
    """The source `motion`'s trajectories with the groups' keys `results` played in place of its
    channels, evaluated in numpy (no action is written)."""
    skeleton, base = motion
    rot, trans = base.rotations.copy(), base.translations.copy()
    for g, keys in zip(groups, results):
        j = skeleton.find(g.bone) if g.bone else None
        if j is None:
            continue
        x = key_reduction.evaluate_channels(keys, frames)
        if g.kind == "location" and not skeleton.connected[j]:
            trans[:, j] = x * g.scale
        elif g.kind == "euler":
            rot[:, j] = rotations.from_euler(x, g.order)
        elif g.kind in ("quaternion", "axis_angle"):
            rot[:, j] = as_quaternions(g, x)
    return Trajectories(base.frames, base.fps, rot, trans, base.armature_to_world)


def _tail_measure(motion, groups, frames):
    """keys per group -> largest error (cm) at any bone's tail and 10 cm beyond, against the
    source `motion` (from source_motion)."""
    skeleton, base = motion

    def measure(results):
        error = error_measures.tail_error(skeleton, base, _played(motion, groups, frames, results))
        return max(error.tail_cm, error.point_cm)
    return measure


def foot_chains(skeleton):
    """Joint indices of the feet the body roles name (foot and toe) and of every bone above them
    (the root, hips and legs): the channels whose errors move a planted foot. Empty without feet."""
    from ...solver.qa import feet_from_roles
    feet = [j for joints in feet_from_roles(skeleton.roles, skeleton.names).values() for j in joints]
    chain = set()
    for j in feet:
        while j >= 0 and j not in chain:
            chain.add(int(j))
            j = skeleton.parents[j]
    return sorted(set(feet)), sorted(chain)


def foot_points(skeleton, traj, feet):
    """World heads and tails (F, 2 len(feet), 3) of the feet's bones."""
    world = traj.world_frames(skeleton)[:, feet]
    head = world[..., :3, 3]
    return np.concatenate((head, head + world[..., :3, 1] * skeleton.lengths[feet, None]), axis=1)


def planted_frames(points, fps):
    """(F, P) whether each point (F, P, 3) is planted on each frame (the motion QA's contacts)."""
    from ...solver.qa.measures import planted_runs
    planted = np.zeros(points.shape[:2], bool)
    for i in range(points.shape[1]):
        for a, b in planted_runs(points[:, i], fps):
            planted[a:b + 1, i] = True
    return planted


def planted_feet_measure(motion, groups, frames):
    """keys per group -> the largest distance over the ground (mm) between a foot point (the
    heads and tails of the feet the roles name) as played and in the source, on the frames where
    the source plants that point (the motion QA's contacts); None when the rig names no feet or
    the source plants none. Each point within e of the source keeps a contact's slide within the
    source's own plus 2 e."""
    skeleton, base = motion
    feet, chain = foot_chains(skeleton)
    if not feet or base.frame_count < 2:
        return None
    source = foot_points(skeleton, base, feet)
    planted = planted_frames(source, base.fps)
    if not planted.any():
        return None
    # only the chains' channels move the feet: the others keep the source's values
    moving = [i for i, g in enumerate(groups) if g.bone and skeleton.find(g.bone) in chain]

    def measure(results):
        played = _played(motion, [groups[i] for i in moving], frames, [results[i] for i in moving])
        played = foot_points(skeleton, played, feet)
        d = np.linalg.norm(played[..., :2] - source[..., :2], axis=-1)
        return 1000.0 * float(d[planted].max())
    return measure


def tail_errors(obj, scene, motion, result, frames, beyond=0.10):
    """The largest tail and tail+`beyond` errors (cm) of every bone between the source `motion`
    (from source_motion) and an action, as their F-curves evaluate (None without a motion)."""
    if motion is None:
        return None
    from ..actions import read_action
    skeleton, a = motion
    b = read_action(obj, scene, skeleton, result, (frames[0], frames[-1]), exact=False)
    return error_measures.tail_error(skeleton, a, b, beyond)


def _ms(t0):
    return round(1000.0 * (time.perf_counter() - t0), 1)


def _base_summary(obj, source, sel, out):
    return {"armature": obj.name, "source_action": source.name, "action": out.action.name,
            "replaced": out.replace, "curves": len(sel.fcurves), "groups": len(sel.groups),
            "bones": sel.bones, "selection_note": sel.note}
