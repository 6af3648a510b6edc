"""Simulate's settings on the scene (scene.humananim_simulation): the source, loads and ground it
shares with Dynamic Control (forces.LoadsAndPushes), how the body follows its motion, the pushes."""

import bpy
from bpy.props import CollectionProperty, EnumProperty, FloatProperty, IntProperty

from ..forces import ArrowForce, LoadsAndPushes
from ..properties import settings_registration


class HumanAnimPush(ArrowForce, bpy.types.PropertyGroup):
    duration: FloatProperty(name="Duration", default=0.1, min=0.001, soft_max=2.0, unit="TIME_ABSOLUTE")
    magnitude: FloatProperty(name="Force", default=300.0, min=0.0, soft_max=3000.0,
                             description="Newtons")


class HumanAnimSimulation(LoadsAndPushes, bpy.types.PropertyGroup):
    """The source, loads and ground (forces.LoadsAndPushes), how the body follows its motion, the pushes."""

    tracking: FloatProperty(name="Tracking", default=1.0, min=0.0, max=1.0, subtype="FACTOR",
                            description="0: a ragdoll that just falls, 1: the muscles follow the motion")
    controller: EnumProperty(name="Controller", items=(
        ("INVERSE_DYNAMICS", "Inverse Dynamics", "Torques that realise the motion, clamped by strength (Huang)"),
        ("PD", "PD Servo", "A proportional-derivative servo on every joint"),
    ))
    balance_assist: FloatProperty(
        name="Balance Assist", default=1.0, min=0.0, max=1.0, subtype="FACTOR",
        description="Share of the pelvis force the feet can't provide that is applied anyway "
                    "(0: fully physical, the body must balance on its feet)")
    pushes: CollectionProperty(type=HumanAnimPush)
    push_index: IntProperty()


CLASSES = (HumanAnimPush, HumanAnimSimulation)


register, unregister = settings_registration(CLASSES, bpy.types.Scene, "humananim_simulation", HumanAnimSimulation)
