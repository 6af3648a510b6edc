"""The Walk panel's settings on the scene (scene.humananim_walk): the path, the speeds, the style
and the generator stack's options."""

import bpy
from bpy.props import EnumProperty, FloatProperty, IntProperty, PointerProperty, StringProperty

from ...solver.walking import PRESETS, SCOPES, Style
from ..properties import settings_registration

STYLE_FIELDS = ("stride", "pelvis_rotation", "pelvis_tilt", "arm_swing", "knee_flexion", "heel_strike",
                "torso_lean")


def apply_preset(props, name):
    """Copy a preset's values into the custom style fields and switch to Custom (a plain function:
    an update callback on the enum crashes the bpy 4.2 module at exit)."""
    style = PRESETS[name.lower()]
    for field_name in STYLE_FIELDS:
        setattr(props, field_name, getattr(style, field_name))
    props.preset = "CUSTOM"


def _style_property(name, label, description, soft_max=3.0, unit="NONE"):
    return FloatProperty(name=label, default=getattr(Style(), name), min=0.0, soft_max=soft_max,
                         description=description, unit=unit)


class HumanAnimWalk(bpy.types.PropertyGroup):
    armature: PointerProperty(name="Armature", type=bpy.types.Object,
                              description="The rig that walks; empty: the active armature")
    path: PointerProperty(name="Path", type=bpy.types.Object,
                          description="A curve object drawn on the ground, or an object whose keyed location "
                                      "the root follows (Keyed Root)")
    path_mode: EnumProperty(name="Path From", items=(
        ("CURVE", "Curve", "Walk along the curve at the speed below"),
        ("KEYED", "Keyed Root", "Follow the keyed location of the path object at its keys' times "
                                "(the speed comes from the keys)"),
    ), default="CURVE")
    speed_mode: EnumProperty(name="Speed", items=(
        ("CONSTANT", "Constant", "One speed all along"),
        ("KEYED", "Keyed", "Speeds at distances along the path, interpolated"),
        ("SEGMENTS", "Per Segment", "One speed per stretch between the curve's control points"),
    ), default="CONSTANT")
    speed: FloatProperty(name="Speed", default=1.3, min=0.05, soft_max=4.0, unit="VELOCITY",
                         description="Walking speed (m/s); above a Froude number of 0.6 the walk becomes a run")
    speed_keys: StringProperty(name="Speed Keys", default="0:1.0",
                               description="DISTANCE:SPEED pairs (m, m/s) along the path, comma-separated")
    segment_speeds: StringProperty(name="Segment Speeds", default="1.0",
                                   description="One speed (m/s) per segment between control points, comma-separated")
    preset: EnumProperty(name="Style", items=[(k.upper(), k.title(), f"The {k} walk") for k in PRESETS]
                         + [("CUSTOM", "Custom", "The values below")], default="NEUTRAL")
    stride: _style_property("stride", "Stride", "Cycle length as a multiple of the model's (1: normal)")
    pelvis_rotation: _style_property("pelvis_rotation", "Pelvis Rotation", "Pelvic turning amplitude (1: normal)")
    pelvis_tilt: _style_property("pelvis_tilt", "Pelvis Tilt", "Pelvic list and bounce amplitude (1: normal)")
    arm_swing: _style_property("arm_swing", "Arm Swing", "Arm swing amplitude (1: normal)")
    knee_flexion: _style_property("knee_flexion", "Knee Flexion", "Knee flexion in stance (1: normal)", 5.0)
    heel_strike: _style_property("heel_strike", "Heel Strike", "Toe-up angle as the heel lands (1: normal)")
    torso_lean: FloatProperty(name="Torso Lean", default=0.0, min=-20.0, max=45.0,
                              description="Forward lean of the torso, degrees")
    ground: PointerProperty(name="Ground", type=bpy.types.Object,
                            description="A mesh the feet stand on (ray cast under the path); empty: a flat ground")
    ground_height: FloatProperty(name="Ground Height", default=0.0, unit="LENGTH",
                                 description="Height of the flat ground when no ground object is set")
    frame_start: IntProperty(name="Start Frame", default=0,
                             description="First frame (standing) of a walk along a curve; 0: the scene's start")
    # a generator strip to add
    gen_action: PointerProperty(name="Motion", type=bpy.types.Action,
                                description="The action the generator plays (only its scope's bones are used)")
    gen_scope: EnumProperty(name="Scope", items=[(s, s.replace(".", " ").title(), f"Bones of the {s} scope")
                                                 for s in SCOPES], default="arm.R")
    gen_priority: EnumProperty(name="Priority", items=(
        ("default", "Default", "Starts once the previous generators on its scope have stopped"),
        ("weighted", "Weighted", "Mixes with the others on its scope with its weight"),
        ("exclusive", "Exclusive", "Starts at its time and stops the others on its scope"),
        ("clearing", "Clearing", "Starts at its time and stops all the others"),
    ), default="weighted")
    gen_weight: FloatProperty(name="Weight", default=1.0, min=0.0, max=1.0)
    gen_start: IntProperty(name="Start", default=1, description="Frame the generator is planned to start at")


CLASSES = (HumanAnimWalk,)

register, unregister = settings_registration(CLASSES, bpy.types.Scene, "humananim_walk", HumanAnimWalk)
