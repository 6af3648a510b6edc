"""Actions across Blender 4.2 (legacy F-curves) and 4.4+ (slotted actions; 5.0 drops Action.fcurves)."""

import bpy
import numpy as np

SLOTTED = bpy.app.version >= (4, 4, 0)


def object_slot(action, obj):
    """The slot of `action` that animates `obj` (None before 4.4, or when there is none)."""
    if not SLOTTED:
        return None
    ad = obj.animation_data
    if ad and ad.action == action and ad.action_slot:
        return ad.action_slot
    slots = [s for s in action.slots
             if getattr(s, "target_id_type", getattr(s, "id_root", "OBJECT")) in {"OBJECT", "UNSPECIFIED"}]
    for slot in slots:
        if slot.name_display == obj.name:
            return slot
    return slots[0] if slots else None


def fcurves_of(action, obj):
    """Every F-curve that `action` applies to `obj`."""
    if not SLOTTED:
        return list(action.fcurves)
    slot = object_slot(action, obj)
    if slot is None:
        return []
    curves = []
    for layer in action.layers:
        for strip in layer.strips:
            bag = strip.channelbag(slot)
            if bag is not None:
                curves.extend(bag.fcurves)
    return curves


class ChannelWriter:
    """The one F-curve writer: F-curves of one ID's channels in an action, grouped (by bone),
    across the action APIs (4.2 legacy, 4.4 slotted, 5.0 without Action.fcurves).

    By default it fills a NEW action with a new slot for `owner` (an object, or a shape-key
    datablock with id_type 'KEY'); with `existing`, it adds to an action that already animates
    `owner` (its slot, its first layer and strip) and finds the F-curves the action has."""

    def __init__(self, action, owner, id_type="OBJECT", existing=False):
        self.action = action
        self.slot = None
        self._groups = {}
        self._curves = {}
        if existing:
            self._curves = {(fc.data_path, fc.array_index): fc for fc in fcurves_of(action, owner)}
            if SLOTTED:
                self.slot = object_slot(action, owner)
                layer = action.layers[0] if len(action.layers) else action.layers.new("Layer")
                strip = layer.strips[0] if len(layer.strips) else layer.strips.new(type="KEYFRAME")
                self._bag = strip.channelbag(self.slot, ensure=True)
        elif SLOTTED:
            self.slot = action.slots.new(id_type=id_type, name=owner.name)
            strip = action.layers.new("Layer").strips.new(type="KEYFRAME")
            self._bag = strip.channelbag(self.slot, ensure=True)
        else:
            action.id_root = id_type

    def has(self, data_path, index):
        return (data_path, index) in self._curves

    def fcurve(self, data_path, index, group):
        """The F-curve of (data_path, index): the action's own, else a new one in `group`."""
        fc = self._curves.get((data_path, index))
        if fc is None:
            fc = self.new_fcurve(data_path, index, group)
        return fc

    def new_fcurve(self, data_path, index, group):
        if not SLOTTED:
            fc = self.action.fcurves.new(data_path, index=index, action_group=group)
        else:
            fc = self._bag.fcurves.new(data_path, index=index)
            if group not in self._groups:
                found = self._bag.groups.get(group)
                self._groups[group] = found if found is not None else self._bag.groups.new(group)
            fc.group = self._groups[group]
        self._curves[(data_path, index)] = fc
        return fc

    def key_columns(self, data_path, group, frames, values, interpolation="LINEAR"):
        """New F-curves data_path[0..k-1] keyed with the columns of `values` (F, k) on `frames`
        (F,), all at once (keyframe_points.foreach_set, then update() for the handles)."""
        code = bpy.types.Keyframe.bl_rna.properties["interpolation"].enum_items[interpolation].value
        frames = np.asarray(frames, float)
        values = np.asarray(values, float).reshape(len(frames), -1)
        for i in range(values.shape[1]):
            fc = self.new_fcurve(data_path, i, group)
            fc.keyframe_points.add(len(frames))
            fc.keyframe_points.foreach_set("co", np.column_stack((frames, values[:, i])).ravel())
            fc.keyframe_points.foreach_set("interpolation", np.full(len(frames), code, dtype=np.int32))
            fc.update()

    def replace_keys(self, data_path, index, group, frames, values, interpolation="LINEAR"):
        """Keys `values` on `frames` in the F-curve (found or made), its keys inside the frames'
        range replaced; keys outside the range stay."""
        fc = self.fcurve(data_path, index, group)
        lo, hi = frames[0] - 0.5, frames[-1] + 0.5
        points = fc.keyframe_points
        for i in range(len(points) - 1, -1, -1):
            if lo <= points[i].co[0] <= hi:
                points.remove(points[i], fast=True)
        for f, v in zip(frames, values):
            kp = points.insert(float(f), float(v), options={"FAST"})
            kp.interpolation = interpolation
        fc.update()
        return fc


def assign_action(obj, action, slot):
    ad = obj.animation_data or obj.animation_data_create()
    ad.action = action  # before the slot: 5.0 refuses a slot of an unassigned action
    if SLOTTED and slot is not None:
        ad.action_slot = slot


def push_to_nla(obj, action, slot, track_name, start_frame, mute=False):
    ad = obj.animation_data or obj.animation_data_create()
    track = ad.nla_tracks.new()
    track.name = track_name
    strip = track.strips.new(action.name, int(round(start_frame)), action)
    if SLOTTED and slot is not None and hasattr(strip, "action_slot"):
        strip.action_slot = slot
    track.mute = mute
    return track, strip


_KEY_FLOATS = ("co", "handle_left", "handle_right")
_KEY_INTS = ("interpolation", "handle_left_type", "handle_right_type", "easing", "type")
_KEY_SCALARS = ("back", "amplitude", "period")


def copy_keys(src, dst):
    """Every key of `src` into `dst` as it is."""
    n = len(src.keyframe_points)
    dst.keyframe_points.clear()
    dst.keyframe_points.add(n)
    for name in _KEY_FLOATS + _KEY_INTS + _KEY_SCALARS:
        size = 2 if name in _KEY_FLOATS else 1
        buf = np.empty(n * size, dtype=np.int32 if name in _KEY_INTS else np.float64)
        src.keyframe_points.foreach_get(name, buf)
        dst.keyframe_points.foreach_set(name, buf)
    dst.extrapolation = src.extrapolation
    dst.mute, dst.lock, dst.hide = src.mute, src.lock, src.hide
    dst.select = src.select
    dst.update()
