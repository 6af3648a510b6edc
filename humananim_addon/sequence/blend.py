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
    w = multiresolution_blend.blend_weights(len(fa), s, len(fb), transition)
    moving = np.flatnonzero((w > 0.0) & (w < 1.0))
    # the frames the blend changes: where B's weight in the result (the blend of a channel that
    # is 0 in A and 1 in B: the pyramid's coarse bands spread the window) is neither 0 nor 1
    share = (multiresolution_blend.multiresolution_blend if how == "multiresolution"
             else multiresolution_blend.weighted_sum_blend)(np.zeros((len(fa), 1)), np.ones((len(fb), 1)), s, **kw)[:, 0]
    near = (share > 1e-3) & (share < 1.0 - 1e-3)
    feet = _FeetHold.of(obj, scene, layout, near)
    held = feet.on_blend(layout, values, sel.others, frames) if feet and not feet.exact else None
    out = Output(obj, action_a, f"{action_a.name}.blend", replace)
    write_groups(out, groups_a, frames, values)
    out.copy_unprocessed(sel.others)
    out.finish()
    if feet and feet.exact:  # constraints or drivers: the pose is Blender's to evaluate
        held = feet.on_action(out, frames)
    if feet:
        feet.write_extra(out, frames)
    summary = _base_summary(obj, action_a, Selection(action_a, groups_a, sel.note, sel.others), out)
    summary.update(command="blend", action_b=action_b.name, start=float(fa[0] + s), method=how, mask=mask.lower(),
                   frames=[float(frames[0]), float(frames[-1])],
                   transition=[float(fa[0] + moving[0]), float(fa[0] + moving[-1])] if len(moving) else None,
                   ms=_ms(t0))
    if held is not None:
        summary["feet"] = held
    return summary


class _FeetHold:
    """The planted feet held through the transition (solver.sequence.planted_feet) and the legs'
    channels of the result rewritten, on the contacts of the result. Only when the blend covered
    every bone the legs' IK moves (else nothing is changed).

    On a plain FK rig the result's poses are the blended channels themselves: the feet are held
    on them before anything is written (on_blend). Where constraints or drivers make Blender's
    pose differ from the channels (actions.needs_evaluation), the result is written first and
    read back through Blender's evaluation (on_action)."""

    @classmethod
    def of(cls, obj, scene, layout, transition):
        """The hold for a blend of `layout`'s channels, or None (no feet, nothing changes)."""
        from ..actions import needs_evaluation
        from ..armature import skeleton_from_armature
        if obj.type != "ARMATURE" or not transition.any():
            return None
        skeleton = skeleton_from_armature(obj, scene, require=False)
        if not any(skeleton.role_index(f"foot.{side}") is not None for side in ("L", "R")):
            return None
        hold = cls()
        hold.obj, hold.scene, hold.skeleton, hold.transition = obj, scene, skeleton, transition
        hold.paths = {g.data_path for g in layout}
        hold.exact = needs_evaluation(obj)
        hold._extra = {}  # (data path, index) -> (bone, samples) to key after the blend's curves
        return hold

    def on_blend(self, layout, values, others, frames):
        """Holds the feet on the blended `values` (per layout group) and the curves copied as
        they are (`others`), changing `values` in place; the report, or None."""
        traj = self._trajectories(layout, values, others, frames)
        changes = self._changes(traj)
        if changes is None:
            return None
        at = {(g.data_path, i): (k, i) for k, g in enumerate(layout) for i in g.indices}
        for key, (bone, samples) in list(changes.items()):
            if key in at:
                k, i = at.pop(key)
                values[k] = values[k].copy()
                values[k][:, i] = samples
                del changes[key]
        self._extra = changes  # a held bone's rotation mode keys a property the blend left alone
        return self.report

    def on_action(self, out, frames):
        """Holds the feet on the written result as Blender evaluates it and rewrites the legs'
        curves; the report, or None."""
        from ..actions import read_action
        traj = read_action(self.obj, self.scene, self.skeleton, out.action, frame_range=(frames[0], frames[-1]))
        if len(traj.frames) != len(frames):
            return None
        changes = self._changes(traj)
        if changes is None:
            return None
        self._extra = changes
        return self.report

    def write_extra(self, out, frames):
        """The held curves not written with the blend's own (all of them after on_action)."""
        for (path, i), (bone, samples) in self._extra.items():
            set_samples(out.fcurve(path, i, bone), frames, samples)
        self._extra = {}

    def _changes(self, traj):
        """{(data path, index): (bone, samples)} of the held legs, or None when a bone the hold
        turns was not blended (channels selected: the result is left as blended)."""
        from ..actions import bone_path, rotation_channels
        sk, obj = self.skeleton, self.obj
        # contacts found on the result (low and slow in it); where the inputs plant a foot in
        # different places the blend carries it fast, not planted, and it is left as blended
        held, report = planted_feet.hold_planted_feet(sk, traj, self.transition)
        changed = [j for j in range(len(sk.names))
                   if not np.allclose(np.abs(np.einsum("fi,fi->f", held.rotations[:, j], traj.rotations[:, j])), 1.0,
                                      atol=1e-9)]
        if any(all(f"{bone_path(sk.names[j])}.{prop}" not in self.paths
                   for prop in ("rotation_quaternion", "rotation_euler", "rotation_axis_angle")) for j in changed):
            return None
        out = {}
        for j in changed:
            bone = sk.names[j]
            prop, samples = rotation_channels(held.rotations[:, j], obj.pose.bones[bone].rotation_mode)
            out.update({(f"{bone_path(bone)}.{prop}", i): (bone, samples[:, i]) for i in range(samples.shape[1])})
        root = sk.names[sk.root]
        if report["pelvis_lowered_cm"] > 0.0 and f"{bone_path(root)}.location" in self.paths:
            loc = held.translations[:, sk.root] / sk.unit_scale
            out.update({(f"{bone_path(root)}.location", i): (root, loc[:, i]) for i in range(3)})
        report["bones"] = [sk.names[j] for j in changed]
        self.report = report
        return out

    def _trajectories(self, layout, values, others, frames):
        """The result's Trajectories from its channels as they will be written (the blended
        values, then the curves copied as they are), the bones' current values where nothing is
        keyed: what actions.read_action samples from the written action on a plain FK rig."""
        from ...solver import rotations
        from ...solver.trajectories import Trajectories
        from ..actions import bone_channel, scene_fps
        from ..armature import armature_to_world
        channels = {}
        for g, v in zip(layout, values):
            channel = bone_channel(g.data_path)
            if channel:
                channels.update({(*channel, i): v[:, i] for i in g.indices})
        for fc in others:
            channel = bone_channel(fc.data_path)
            if channel and not fc.mute:
                channels[(*channel, fc.array_index)] = np.array([fc.evaluate(f) for f in frames])
        sk, n = self.skeleton, len(frames)

        def sample(bone, prop, current):
            return np.column_stack([channels.get((bone, prop, i), np.full(n, value)) for i, value in enumerate(current)])
        trans, quats = np.zeros((n, sk.joint_count, 3)), np.zeros((n, sk.joint_count, 4))
        for j, name in enumerate(sk.names):
            pb = self.obj.pose.bones[name]
            if not sk.connected[j]:  # Blender ignores a connected bone's location
                trans[:, j] = sample(name, "location", pb.location)
            if pb.rotation_mode == "QUATERNION":
                quats[:, j] = rotations.normalize(sample(name, "rotation_quaternion", pb.rotation_quaternion))
            elif pb.rotation_mode == "AXIS_ANGLE":
                quats[:, j] = rotations.from_axis_angle(sample(name, "rotation_axis_angle", pb.rotation_axis_angle))
            else:
                quats[:, j] = rotations.from_euler(sample(name, "rotation_euler", pb.rotation_euler), pb.rotation_mode)
        return Trajectories(frames, scene_fps(self.scene), rotations.make_continuous(quats), trans * sk.unit_scale,
                            armature_to_world(self.obj, self.scene))


def _frames_in(action, frame_range):
    if frame_range is None:
        return action_frames(action)
    return np.arange(int(np.floor(frame_range[0])), int(np.ceil(frame_range[1])) + 1, dtype=float)
