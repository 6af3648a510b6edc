"""The motion QA's bridge: a result action on an armature to the QA's arrays, its report stored
on the armature object (for the QA panel), and digests showing the source actions untouched.
One home for the CLI and the operators."""

import hashlib
import json
import logging

import bpy
import numpy as np

from ...solver import qa
from ...solver.errors import HumanAnimError
from .. import action_api

log = logging.getLogger(__name__)

PROPERTY = "humananim_qa"  # the last QA report, JSON, on the armature object


def not_measured(reason):
    """The `qa` value of a command whose result is not an armature's motion."""
    return {"passed": None, "measures": {}, "warnings": [], "note": reason}


def motion_from_action(obj, scene, action, frame_range=None, skeleton=None):
    """The QA's Motion of `action` on `obj`: bone heads and tails in the world (metres), local
    rotations, names, parents, frame rate and frame numbers; and the skeleton used."""
    from ..actions import read_action
    from ..armature import skeleton_from_armature
    skeleton = skeleton or skeleton_from_armature(obj, scene, require=False)
    traj = read_action(obj, scene, skeleton, action, frame_range)
    world = traj.world_frames(skeleton)
    heads = world[..., :3, 3]
    tails = heads + world[..., :3, 1] * skeleton.lengths[:, None]
    return qa.Motion(heads, traj.rotations, skeleton.names, traj.fps, skeleton.parents, tails, traj.frames), skeleton


def action_digest(action):
    """A digest of every key (and handle) of every F-curve in `action`, in every slot."""
    h = hashlib.sha256()
    for fc in _all_fcurves(action):
        co = np.empty(2 * len(fc.keyframe_points))
        fc.keyframe_points.foreach_get("co", co)
        h.update(f"{fc.data_path}[{fc.array_index}]".encode())
        h.update(co.tobytes())
    return h.hexdigest()[:16]


def _all_fcurves(action):
    if not action_api.SLOTTED:
        return list(action.fcurves)
    return [fc for layer in action.layers for strip in layer.strips
            for bag in getattr(strip, "channelbags", ()) for fc in bag.fcurves]


def digest_actions():
    """{action name: digest} of every action in the file: taken before a command runs."""
    return {a.name: action_digest(a) for a in bpy.data.actions}


def measure_result(obj, scene, action, sources=(), frame_range=None, ground=None, digests=None, store=True,
                   aligned=None):
    """The QA report of `action` (the result) on `obj` against the `sources` (actions), stored
    on the object. `digests` ({name: digest} taken before the work) checks the sources untouched;
    `aligned` says the result's frames are the source's (default: when their counts agree)."""
    try:
        result, skeleton = motion_from_action(obj, scene, action, frame_range)
    except HumanAnimError as error:
        report = not_measured(f"the result could not be read: {error}")
        report["passed"] = False
        report["warnings"] = [report["note"]]
        return _stored(obj, report, action) if store else report
    inputs = []
    for source in sources:
        rng = frame_range if frame_range and _covers(source, frame_range) else None
        inputs.append(motion_from_action(obj, scene, source, rng, skeleton)[0])
    checks = None
    known = [s for s in sources if digests and s.name in digests]  # a source loaded later is not checked
    if known:
        checks = ("".join(digests[s.name] for s in known), "".join(action_digest(s) for s in known))
    from ...solver.qa import feet_from_roles
    # the height is measured on the posed figure: a BVH's rest pose may lie on its side
    report = qa.measure(result, inputs, feet_from_roles(skeleton.roles, skeleton.names), ground, None, checks,
                        aligned)
    report.update(action=action.name, sources=[s.name for s in sources])
    return _stored(obj, report, action) if store else report


def _covers(action, frame_range):
    start, end = action.frame_range
    return start <= frame_range[0] and frame_range[1] <= end


def _stored(obj, report, action=None):
    store(obj, report)
    for line in report["warnings"]:
        log.warning("QA of '%s': %s", action.name if action else obj.name, line)
    return report


def measure_summary(obj, scene, summary, digests=None, ground=None, store=True):
    """The QA of a command's or operator's summary dict: its result `action`, its sources
    (`source_action`, `source_actions`, `action_b`) and `frame_range`; a source rewritten on
    request (`replaced`) is not compared."""
    action = bpy.data.actions.get(summary.get("action") or "")
    if obj is None or obj.type != "ARMATURE" or action is None:
        return not_measured("no new action on an armature")
    names = summary.get("source_actions") or [summary.get("source_action")]
    names = list(dict.fromkeys(n for n in names + [summary.get("action_b")] if n))
    sources = [] if summary.get("replaced") else [bpy.data.actions[n] for n in names if n in bpy.data.actions]
    rng = summary.get("frame_range")
    # a retimed (warp), joined (blend, synthesize) or generated result's frames are not the source's
    aligned = False if any(k in summary for k in RETIMED_KEYS) else None
    return measure_result(obj, scene, action, sources, tuple(rng) if rng else None, ground, digests, store,
                          aligned)


RETIMED_KEYS = ("constraints", "transition", "source_actions", "requests")


def store(obj, report):
    """The last QA report on the armature object (a JSON custom property the QA panel reads)."""
    obj[PROPERTY] = json.dumps(report)


def stored(obj, prop=PROPERTY):
    """The last QA report stored on `obj` (or another JSON report under `prop`), or None."""
    text = obj.get(prop) if obj is not None else None
    try:
        return json.loads(text) if text else None
    except (TypeError, ValueError):
        return None
