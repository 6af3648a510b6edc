"""Motion synthesis in Blender (Oshita 2003, ch. 3): the Motion Queue (actions, or the
armature's NLA strips, each with a transition mode), per-limb constraint edits from pose markers,
and the job that synthesizes the queue, optionally under dynamic control with reactions (the
loads, pushes and collider of the Dynamic Control panel), and writes a NEW action.

Pose markers on an action edit its constraints: a marker named "foot.L=supporting" (or angular,
spatial; limbs foot.L, foot.R, hand.L, hand.R, root) sets that limb's constraint from its frame
until the limb's next marker or the action's end."""

import time

import numpy as np

from ...solver.errors import MotionError, RigError
from .. import actions
from ..armature import skeleton_from_armature
from ..rig.capability import RigView

# ---- queue editing ------------------------------------------------------------------------------

def add_entry(scene, action, mode="BLEND", frame_range=None, interrupt_frame=None):
    props = scene.humananim_synthesis
    e = props.entries.add()
    e.action, e.mode = action, mode
    if frame_range:
        e.frame_start, e.frame_end = (int(v) for v in frame_range)
    if interrupt_frame is not None:
        e.interrupt, e.interrupt_frame = True, int(interrupt_frame)
    props.entry_index = len(props.entries) - 1
    return e


def entries_from_nla(obj, scene, mode="BLEND"):
    """Queue the armature's NLA strips in the order they play (their action frame ranges)."""
    ad = obj.animation_data
    strips = [s for t in (ad.nla_tracks if ad else ()) if not t.mute for s in t.strips if s.action]
    if not strips:
        raise MotionError(f"'{obj.name}' has no NLA strips with actions")
    props = scene.humananim_synthesis
    props.entries.clear()
    for s in sorted(strips, key=lambda s: s.frame_start):
        add_entry(scene, s.action, mode, (s.action_frame_start, s.action_frame_end))
    return len(strips)


def add_marker(action, frame, limb, constraint):
    """A pose marker "limb=constraint" at `frame` (replacing one of that limb at that frame)."""
    for m in list(action.pose_markers):
        if m.frame == frame and m.name.split("=")[0] == limb:
            action.pose_markers.remove(m)
    marker = action.pose_markers.new(f"{limb}={constraint}")
    marker.frame = int(frame)
    return marker


def marker_overrides(action, frames):
    """(limb, start, end, constraint) edits from the action's pose markers within `frames`."""
    from ...solver.synthesis.action import CONSTRAINT_CODES, LIMBS
    by_limb = {}
    for m in action.pose_markers:
        if "=" not in m.name:
            continue
        limb, cons = (p.strip() for p in m.name.split("=", 1))
        if limb not in LIMBS and limb != "root":
            raise MotionError(f"pose marker '{m.name}' on '{action.name}': unknown limb '{limb}' "
                              f"(foot.L, foot.R, hand.L, hand.R, root)")
        if cons not in CONSTRAINT_CODES:
            raise MotionError(f"pose marker '{m.name}' on '{action.name}': unknown constraint '{cons}' "
                              "(supporting, angular, spatial)")
        by_limb.setdefault(limb, []).append((m.frame, cons))
    out = []
    for limb, marks in by_limb.items():
        marks.sort()
        for i, (frame, cons) in enumerate(marks):
            end = marks[i + 1][0] - 1 if i + 1 < len(marks) else frames[-1]
            out.append((limb, frame, end, cons))
    return out


# ---- the job ------------------------------------------------------------------------------------

def _entry_range(entry):
    a = entry.action
    start = entry.frame_start or a.frame_range[0]
    end = entry.frame_end or a.frame_range[1]
    if end <= start:
        raise MotionError(f"the frame range {start:g}-{end:g} of '{a.name}' is empty")
    return start, end


def read_entry(obj, scene, skeleton, entry, rig=None):
    """The queue entry as solver action data (generator: yields read progress); `rig`: a
    RigView reads it (a control rig's deform bones as Blender shows them)."""
    from ...solver.synthesis import from_trajectories
    if entry.action is None:
        raise MotionError("a Motion Queue entry has no action")
    traj = yield from (rig.iter_read(entry.action, _entry_range(entry)) if rig else
                       actions.iter_read_action(obj, scene, skeleton, entry.action, frame_range=_entry_range(entry)))
    if traj.frame_count < 3:
        raise MotionError(f"'{entry.action.name}' has {traj.frame_count} frames: at least 3 are needed")
    overrides = marker_overrides(entry.action, traj.frames)
    return from_trajectories(entry.action.name, skeleton, traj, entry.initial_duration, entry.terminal_duration,
                             overrides)


def environment_set(control):
    """Loads, pushes or a colliding character set in the Dynamic Control panel."""
    return control.load_left > 0.0 or control.load_right > 0.0 or len(control.impulses) > 0 \
        or control.collider is not None


def reaction_settings(props):
    from ...solver.synthesis.reactions import ReactionSettings
    return ReactionSettings(step_speed=(props.step_speed_min, props.step_speed_max),
                            step_acceleration=props.step_acceleration, fall_speed=props.step_speed_max,
                            fall_acceleration=props.step_acceleration, k_root=props.k_root, k_foot=props.k_foot,
                            recovery_time=props.recovery_time)


def synthesize(obj, scene, skeleton, acts, modes, interrupts):
    """The Synthesizer over solver actions: (synthesizer, requests)."""
    from ...solver.synthesis import Synthesizer
    from ...solver.synthesis.metrics import planted_slide, spike_ratio
    syn = Synthesizer(acts[0])
    for act, mode, at in zip(acts[1:], modes[1:], interrupts[1:]):
        r = syn.queue(act, mode.lower(), "now" if at is not None else "after", at)
        if r.accepted:  # measured now: a later interruption may cut this join off
            tr = syn.trajectories
            slide = planted_slide(skeleton, tr, r.held, r.window) if r.held else {}
            ang, lin = spike_ratio(skeleton, tr, r.window, [a.trajectories for a in acts])
            r.info["measured"] = dict(start_frame=float(tr.frames[r.start]),
                                      window=[float(tr.frames[r.window[0]]), float(tr.frames[r.window[1]])],
                                      max_planted_slide_mm=1000.0 * max(slide.values(), default=0.0),
                                      spike_ratio_angular=ang, spike_ratio_linear=lin)
    return syn


def run(obj, scene):
    """Synthesize the Motion Queue into a new action. Yields progress; returns a summary dict."""
    if obj is None or obj.type != "ARMATURE":
        raise RigError("select an armature object")
    props = scene.humananim_synthesis
    entries = list(props.entries)
    if not entries:
        raise MotionError("the Motion Queue is empty: add actions (or queue the NLA strips)")
    rig = RigView(obj, scene)  # a control rig: the deform bones as Blender shows them, keyed through the controls
    skeleton = rig.skeleton
    acts = []
    for i, e in enumerate(entries):
        act = yield from read_entry(obj, scene, skeleton, e, rig)
        acts.append(act)
        yield 0.3 * (i + 1) / len(entries)
    t0 = time.perf_counter()
    syn = synthesize(obj, scene, skeleton, acts, [e.mode for e in entries],
                     [e.interrupt_frame if e.interrupt and i else None for i, e in enumerate(entries)])
    yield 0.5
    traj = syn.trajectories
    support = syn.support()
    reaction = None
    if props.reactions or environment_set(scene.humananim_control):
        from ...solver.synthesis.reactions import react
        from ..motion_control import job as motion_control
        cs = motion_control.solver_settings(scene, scene.humananim_control, obj, skeleton, traj)
        falls = {}
        for key, act in (("back", props.fall_back), ("forward", props.fall_forward)):
            if act is not None:
                e = type("E", (), {"action": act, "frame_start": 0, "frame_end": 0, "initial_duration": 0.2,
                                   "terminal_duration": 0.2})
                falls[key] = yield from read_entry(obj, scene, skeleton, e, rig)
        reaction = react(syn.motion, cs, reaction_settings(props), falls or None)
        traj = reaction.trajectories
        support = reaction.support
    yield 0.9
    seconds = time.perf_counter() - t0
    first = entries[0].action
    out = yield from rig.iter_write(traj, f"{first.name}.synth", scene.humananim.output, first)
    for e in entries:
        e.action.use_fake_user = True
    requests = []
    for e, r in zip(entries, syn.requests):
        e.accepted, e.status = r.accepted, ("accepted" if r.accepted else r.reason)
        item = {"action": r.action, "mode": r.mode, "when": r.when, "accepted": r.accepted, "reason": r.reason}
        item.update(r.info.get("measured", {}))
        requests.append(item)
    summary = {"action": out.name, "source_actions": [e.action.name for e in entries], "frames": traj.frame_count,
               "fps": traj.fps, "frame_range": [float(traj.frames[0]), float(traj.frames[-1])],
               "requests": requests, "accepted": sum(r["accepted"] for r in requests),
               "rejected": sum(not r["accepted"] for r in requests), "seconds": round(seconds, 3),
               "frames_supported": {s: int(np.count_nonzero(m)) for s, m in support.items()}, **rig.summary()}
    if reaction is not None:
        summary["reaction"] = {"kind": reaction.kind,
                               "frame": float(traj.frames[reaction.frame]) if reaction.frame >= 0 else None,
                               "max_root_speed_ms": float(reaction.root_speed.max()),
                               "max_root_acceleration_ms2": float(reaction.root_acceleration.max()),
                               **{k: v for k, v in reaction.info.items() if isinstance(v, (str, int, float))}}
    props.last_summary = text_line(summary)
    return summary


def text_line(s):
    line = f"'{s['action']}': {s['accepted']} joined, {s['rejected']} rejected, {s['frames']} frames"
    if "reaction" in s:
        line += f", reaction: {s['reaction']['kind']}"
    return line
