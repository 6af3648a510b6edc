"""Writing results: keys, copies of untouched curves, and the new action."""

import bpy
import numpy as np

from ...solver import rotations
from ...solver.sequence import key_reduction
from .. import action_api
from .channels import _enum_value, bone_of


def set_samples(fc, frames, values):
    """Linear keys on every frame."""
    kp = fc.keyframe_points
    kp.clear()
    kp.add(len(frames))
    kp.foreach_set("co", np.column_stack((frames, values)).ravel())
    kp.foreach_set("interpolation", np.full(len(frames), _enum_value("interpolation", "LINEAR"), np.int32))
    fc.update()


def set_keys(fc, keys):
    """Bezier keys from key_reduction.Keys with FREE handles (so update() keeps them)."""
    kp = fc.keyframe_points
    kp.clear()
    n = len(keys)
    kp.add(n)
    kp.foreach_set("co", np.column_stack((keys.times, keys.values)).ravel())
    free = np.full(n, _enum_value("handle_left_type", "FREE"), np.int32)
    kp.foreach_set("handle_left_type", free)
    kp.foreach_set("handle_right_type", free)
    kp.foreach_set("handle_left", np.asarray(keys.left, float).ravel())
    kp.foreach_set("handle_right", np.asarray(keys.right, float).ravel())
    interp = {name: _enum_value("interpolation", name) for name in ("BEZIER", "LINEAR", "CONSTANT")}
    kp.foreach_set("interpolation", np.array([interp.get(str(i), interp["BEZIER"]) for i in keys.interpolation],
                                             np.int32))
    fc.update()


def read_keys(fc):
    """Keys of an F-curve (times, values, handles, interpolation names)."""
    n = len(fc.keyframe_points)
    co, left, right = np.empty(2 * n), np.empty(2 * n), np.empty(2 * n)
    fc.keyframe_points.foreach_get("co", co)
    fc.keyframe_points.foreach_get("handle_left", left)
    fc.keyframe_points.foreach_get("handle_right", right)
    co = co.reshape(n, 2)
    interp = np.array([k.interpolation for k in fc.keyframe_points], dtype=object)
    return key_reduction.Keys(co[:, 0].copy(), co[:, 1].copy(), left.reshape(n, 2), right.reshape(n, 2), interp)


class Output:
    """Where results go: a new action (other curves copied) or the source action in place."""

    def __init__(self, obj, source, name, replace=False):
        self.obj, self.source, self.replace = obj, source, replace
        self._curves = {}
        if replace:
            self.action = source
            self._curves = {(fc.data_path, fc.array_index): fc for fc in action_api.fcurves_of(source, obj)}
            self.writer = None
        else:
            self.action = bpy.data.actions.new(name)
            self.writer = action_api.ChannelWriter(self.action, obj)

    def fcurve(self, data_path, index, group_name):
        key = (data_path, index)
        fc = self._curves.get(key)
        if fc is None:
            if self.replace:
                fc = self._new_in_source(data_path, index, group_name)
            else:
                fc = self.writer.new_fcurve(data_path, index, group_name)
            self._curves[key] = fc
        return fc

    def _new_in_source(self, data_path, index, group_name):
        if not action_api.SLOTTED:
            return self.source.fcurves.new(data_path, index=index, action_group=group_name)
        slot = action_api.object_slot(self.source, self.obj)
        bag = self.source.layers[0].strips[0].channelbag(slot, ensure=True)
        return bag.fcurves.new(data_path, index=index)

    def copy_unprocessed(self, fcurves):
        if self.replace:
            return
        for fc in fcurves:
            group = fc.group.name if fc.group else (bone_of(fc.data_path) or "Object Transforms")
            action_api.copy_keys(fc, self.fcurve(fc.data_path, fc.array_index, group))

    def finish(self, pose_marker_map=None):
        """Pose markers copied (moved through `pose_marker_map`, or dropped where it gives None),
        the new action assigned, the source protected by a fake user."""
        if self.replace:
            return self.action
        for marker in self.source.pose_markers:
            frame = marker.frame if pose_marker_map is None else pose_marker_map(marker)
            if frame is not None:
                self.action.pose_markers.new(marker.name).frame = int(round(frame))
        self.source.use_fake_user = True
        action_api.assign_action(self.obj, self.action, self.writer.slot)
        return self.action


def write_groups(out, groups, frames, values):
    for g, v in zip(groups, values):
        if g.kind == "quaternion":
            v = rotations.make_continuous(v)
        for i, fc in enumerate(g.fcurves):
            set_samples(out.fcurve(g.data_path, i, g.group_name), frames, v[:, i])
