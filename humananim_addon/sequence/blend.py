"""Multiresolution blending of two actions, or of an NLA strip pair (Huang 1996 §5.3)."""

import time

import numpy as np

from ...solver.errors import MotionError
from ...solver.sequence import multiresolution_blend, planted_feet
from .. import action_api
from .channels import (Group, Selection, action_frames, as_quaternions, from_quaternions, groups_of,
                       sample_group, select_channels)
from .measures import _base_summary, _ms
from .writing import Output, set_samples, write_groups


def nla_pair(obj):
    """The two NLA strips to blend: the two selected ones, else the first two in time."""
    ad = obj.animation_data
    strips = [s for t in (ad.nla_tracks if ad else ()) for s in t.strips if s.action is not None]
    chosen = [s for s in strips if s.select]
    chosen = chosen if len(chosen) == 2 else strips
    if len(chosen) < 2:
        raise MotionError(f"'{obj.name}' needs two NLA strips with actions to blend")
    a, b = sorted(chosen, key=lambda s: s.frame_start)[:2]
    start = a.action_frame_start + (b.frame_start - a.frame_start) * (a.action_frame_end - a.action_frame_start) / max(
        a.frame_end - a.frame_start, 1e-9)
    return a.action, (a.action_frame_start, a.action_frame_end), b.action, (b.action_frame_start, b.action_frame_end), start


def blend(obj, scene, action_a, action_b, start, window=0, method="MULTIRESOLUTION", mask="WINDOW",
          levels=None, sel=None, range_a=None, range_b=None, replace=False):
    """A then B, B's first frame placed at frame `start` of A; across the transition (the
    overlap, or `window` frames from `start`) A's weight eases from 1 to 0. B inside A: A
    eases out to B's middle and back. Channels of either action (all of them unless `sel`)."""
    t0 = time.perf_counter()
    fa = _frames_in(action_a, range_a)
    fb = _frames_in(action_b, range_b)
    s = int(round(start - fa[0]))
    if not 0 <= s <= len(fa) - 1:
        raise MotionError(f"B must start inside A (frames {fa[0]:g}-{fa[-1]:g}), not at {start:g}")
    transition = None
    if window and s + len(fb) - 1 >= len(fa) - 1:
        transition = (s, min(s + int(window), len(fa) - 1))
    sel = sel or select_channels(obj, scene, action_a)
    curves_a = {(fc.data_path, fc.array_index): fc for fc in action_api.fcurves_of(action_a, obj)}
    curves_b = {(fc.data_path, fc.array_index): fc for fc in action_api.fcurves_of(action_b, obj)}
    layout = list(sel.groups)
    if not sel.others:  # everything selected: the curves only B keys are blended too
        paths = {g.data_path for g in layout}
        layout += groups_of(obj, scene, [fc for (path, _), fc in curves_b.items() if path not in paths])

    def on(curves, g):
        return Group(g.data_path, g.kind, [curves.get((g.data_path, i)) for i in g.indices], g.defaults,
                     g.bone, g.order, g.scale, g.group_name)
    groups_a = [on(curves_a, g) for g in layout]
    groups_b = [on(curves_b, g) for g in layout]
    kw = {"transition": transition, "levels": levels, "mask": mask.lower()}
    if method != "MULTIRESOLUTION":
        kw = {"transition": transition}
    how = "multiresolution" if method == "MULTIRESOLUTION" else "weighted"
    values, plain_a, plain_b, plain_idx = [None] * len(groups_a), [], [], []
    for k, (ga, gb) in enumerate(zip(groups_a, groups_b)):
        xa, xb = sample_group(ga, fa), sample_group(gb, fb)
        if ga.kind in ("quaternion", "axis_angle"):
            q = multiresolution_blend.blend_quaternions(as_quaternions(ga, xa), as_quaternions(gb, xb), s,
                                                        method=how, **kw)
            values[k] = from_quaternions(ga, q)
        elif ga.kind == "euler":
            values[k] = multiresolution_blend.blend_euler(xa[:, None], xb[:, None], s, ga.order,
                                                          method=how, **kw)[:, 0]
        else:
            plain_a.append(xa), plain_b.append(xb), plain_idx.append(k)
    if plain_idx:
        fn = (multiresolution_blend.multiresolution_blend if how == "multiresolution"
              else multiresolution_blend.weighted_sum_blend)
        widths = [x.shape[1] for x in plain_a]
        res = fn(np.concatenate(plain_a, axis=1), np.concatenate(plain_b, axis=1), s, **kw)
        at = 0
        for k, w in zip(plain_idx, widths):
            values[k], at = res[:, at:at + w], at + w
    frames = fa[0] + np.arange(len(values[0]), dtype=float)
    out = Output(obj, action_a, f"{action_a.name}.blend", replace)
    write_groups(out, groups_a, frames, values)
    out.copy_unprocessed(sel.others)
    out.finish()
    w = multiresolution_blend.blend_weights(len(fa), s, len(fb), transition)
    moving = np.flatnonzero((w > 0.0) & (w < 1.0))
    # the frames the blend changes: where B's weight in the result (the blend of a channel that
    # is 0 in A and 1 in B: the pyramid's coarse bands spread the window) is neither 0 nor 1
    share = (multiresolution_blend.multiresolution_blend if how == "multiresolution"
             else multiresolution_blend.weighted_sum_blend)(np.zeros((len(fa), 1)), np.ones((len(fb), 1)), s, **kw)[:, 0]
    near = (share > 1e-3) & (share < 1.0 - 1e-3)
    held = _hold_feet(obj, scene, out, layout, frames, near)
    summary = _base_summary(obj, action_a, Selection(action_a, groups_a, sel.note, sel.others), out)
    summary.update(command="blend", action_b=action_b.name, start=float(fa[0] + s), method=how, mask=mask.lower(),
                   frames=[float(frames[0]), float(frames[-1])],
                   transition=[float(fa[0] + moving[0]), float(fa[0] + moving[-1])] if len(moving) else None,
                   ms=_ms(t0))
    if held is not None:
        summary["feet"] = held
    return summary


def _hold_feet(obj, scene, out, layout, frames, transition):
    """The planted feet held through the transition (solver.sequence.planted_feet) and the legs'
    channels of the result rewritten, on the contacts of the result. Only when the
    blend covered every bone the legs' IK moves (else None, nothing changed)."""
    from ..actions import bone_path, read_action, rotation_channels
    from ..armature import skeleton_from_armature
    if obj.type != "ARMATURE" or not transition.any():
        return None
    skeleton = skeleton_from_armature(obj, scene, require=False)
    if not any(skeleton.role_index(f"foot.{side}") is not None for side in ("L", "R")):
        return None
    span = (float(frames[0]), float(frames[-1]))
    traj = read_action(obj, scene, skeleton, out.action, frame_range=span)
    if len(traj.frames) != len(frames):
        return None
    # contacts found on the result (low and slow in it); where the inputs plant a foot in
    # different places the blend carries it fast, not planted, and it is left as blended
    held, report = planted_feet.hold_planted_feet(skeleton, traj, transition)
    paths = {g.data_path for g in layout}
    changed = [j for j in range(len(skeleton.names))
               if not np.allclose(np.abs(np.einsum("fi,fi->f", held.rotations[:, j], traj.rotations[:, j])), 1.0,
                                  atol=1e-9)]
    root = skeleton.root
    lowered = report["pelvis_lowered_cm"] > 0.0
    if any(bone_path(skeleton.names[j]) + ".rotation_quaternion" not in paths
           and bone_path(skeleton.names[j]) + ".rotation_euler" not in paths
           and bone_path(skeleton.names[j]) + ".rotation_axis_angle" not in paths for j in changed):
        return None  # a leg bone was not blended (channels selected): left as blended
    for j in changed:
        bone = skeleton.names[j]
        prop, values = rotation_channels(held.rotations[:, j], obj.pose.bones[bone].rotation_mode)
        for i in range(values.shape[1]):
            set_samples(out.fcurve(f"{bone_path(bone)}.{prop}", i, bone), frames, values[:, i])
    if lowered and f"{bone_path(skeleton.names[root])}.location" in paths:
        bone = skeleton.names[root]
        loc = held.translations[:, root] / skeleton.unit_scale
        for i in range(3):
            set_samples(out.fcurve(f"{bone_path(bone)}.location", i, bone), frames, loc[:, i])
    report["bones"] = [skeleton.names[j] for j in changed]
    return report


def _frames_in(action, frame_range):
    if frame_range is None:
        return action_frames(action)
    return np.arange(int(np.floor(frame_range[0])), int(np.ceil(frame_range[1])) + 1, dtype=float)
