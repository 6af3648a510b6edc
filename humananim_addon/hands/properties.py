"""The Hands panel's settings on the scene (scene.humananim_hands)."""

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty, StringProperty

from ..properties import settings_registration


TYPE_ITEMS = (("AUTO", "Automatic", "From the object's primitive and the hand's size (the thesis's table)"),
              ("LATERAL", "Lateral", "Thumb against the side of the index (a card)"),
              ("PINCH", "Pinch", "Thumb and index tips"),
              ("TRIPOD", "Tripod", "Thumb, index and middle tips (a small ball)"),
              ("WRAP", "Wrap", "The whole hand around it"),
              ("DISK", "Disk", "Fingers spread over a flat round object (a lid)"))


class HumanAnimHands(bpy.types.PropertyGroup):
    side: EnumProperty(name="Hand", items=(("AUTO", "Nearest", "The hand nearer the object"),
                                           ("L", "Left", ""), ("R", "Right", "")))
    grasp_type: EnumProperty(name="Type", items=TYPE_ITEMS)
    pattern: PointerProperty(name="Pattern", type=bpy.types.Action,
                             description="A hand pose from the pose library the fingers close toward "
                                         "(its first frame); empty: the built-in pattern of the type")
    duration: FloatProperty(name="Reach", default=1.0, min=0.1, soft_max=5.0, unit="TIME_ABSOLUTE",
                            description="Seconds the arm takes to reach the object")
    close_duration: FloatProperty(name="Close", default=0.5, min=0.05, soft_max=3.0, unit="TIME_ABSOLUTE",
                                  description="Seconds the fingers take to close")
    start_frame: IntProperty(name="Start", default=1, description="Frame the reach starts")
    release_frame: IntProperty(name="Release", default=0,
                               description="Frame the object is let go (0: held to the end)")
    with_spine: BoolProperty(name="Use Spine", description="The spine bends to help the reach")
    other: PointerProperty(name="Other Character", type=bpy.types.Object,
                           description="The armature whose bone is held")
    other_bone: StringProperty(name="Bone", description="The other character's bone to hold (hand, arm, shoulder)")
    frame_start: IntProperty(name="From", default=1, description="First frame to follow or correct")
    frame_end: IntProperty(name="To", default=100, description="Last frame to follow or correct")


register, unregister = settings_registration((HumanAnimHands,), bpy.types.Scene, "humananim_hands", HumanAnimHands)
