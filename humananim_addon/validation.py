"""Checks of a job's settings shared by the command line and the operators: one message for a
frame range outside the source clip, pushes or impulses outside the range, loads that are not
finite and non-negative. Each raises a HumanAnimError (MotionError) the caller reports."""

import math

from ..solver.errors import MotionError


def source_action(obj, props, what="use"):
    """The settings' source action, else the armature's active one."""
    action = getattr(props, "action", None) or (obj.animation_data.action if obj.animation_data else None)
    if action is None:
        raise MotionError(f"'{obj.name}' has no action to {what}: choose a source action")
    return action


def frame_range(props, action):
    """The job's frames (0 means the action's own first or last frame), inside the action."""
    first, last = action.frame_range
    if len({round(k.co[0], 6) for fc in _fcurves(action) for k in fc.keyframe_points}) < 2:
        raise MotionError(f"'{action.name}' has a single keyed frame: at least 3 are needed")
    start = props.frame_start or first
    end = props.frame_end or last
    if end <= start:
        raise MotionError(f"the frame range {start:g}-{end:g} is empty: the end must be after the start")
    if start < first or end > last:
        raise MotionError(f"the frame range {start:g}-{end:g} is outside '{action.name}' (frames "
                          f"{first:g}-{last:g}): frames beyond the keys would be frozen copies")
    return start, end


def events_in_range(items, start, end, what):
    """Every push or impulse (items with .frame and .bone) inside the frame range."""
    for item in items:
        if not start <= item.frame <= end:
            raise MotionError(f"the {what} on '{item.bone}' at frame {item.frame} is outside the frame range "
                              f"{start:g}-{end:g}")


def loads(props):
    for side in ("left", "right"):
        kg = getattr(props, f"load_{side}", 0.0)
        if not math.isfinite(kg) or kg < 0.0:
            raise MotionError(f"the {side} hand's load must be a finite number of kg >= 0, not {kg:g}")


def check_job(obj, props, events="pushes"):
    """All of the above for a simulation or control job: (action, start, end)."""
    action = source_action(obj, props, {"pushes": "simulate", "impulses": "control"}[events])
    start, end = frame_range(props, action)
    what = {"pushes": "push", "impulses": "impulse"}[events]
    events_in_range(getattr(props, events), start, end, what)
    loads(props)
    load_frame = getattr(props, "load_frame", 0)
    if load_frame and not start <= load_frame <= end:
        raise MotionError(f"the loads' pick-up frame {load_frame} is outside the frame range {start:g}-{end:g}")
    return action, start, end


def _fcurves(action):
    from .qa.job import _all_fcurves
    return _all_fcurves(action)
