"""Actions across Blender 4.2 (legacy F-curves) and 4.4+ (slotted actions; 5.0 drops Action.fcurves)."""

import bpy

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
    """Creates F-curves, grouped by bone, in a new action for `obj`."""

    def __init__(self, action, obj):
        self.action = action
        self.slot = None
        self._groups = {}
        if SLOTTED:
            self.slot = action.slots.new(id_type="OBJECT", name=obj.name)
            strip = action.layers.new("Layer").strips.new(type="KEYFRAME")
            self._bag = strip.channelbag(self.slot, ensure=True)
        else:
            action.id_root = "OBJECT"

    def new_fcurve(self, data_path, index, group):
        if not SLOTTED:
            return self.action.fcurves.new(data_path, index=index, action_group=group)
        fcurve = self._bag.fcurves.new(data_path, index=index)
        if group not in self._groups:
            self._groups[group] = self._bag.groups.new(group)
        fcurve.group = self._groups[group]
        return fcurve


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
