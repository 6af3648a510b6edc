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


def _tail_measure(motion, groups, frames):
    """keys per group -> largest error (cm) at any bone's tail and 10 cm beyond, against the
    source `motion` (from source_motion), evaluated in numpy (no action is written)."""
    skeleton, base = motion

    def measure(results):
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
        played = Trajectories(base.frames, base.fps, rot, trans, base.armature_to_world)
        error = error_measures.tail_error(skeleton, base, played)
        return max(error.tail_cm, error.point_cm)
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
