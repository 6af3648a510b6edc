"""The Motion Queue's settings on the scene (scene.humananim_synthesis): its entries and the
reaction settings."""

import bpy
from bpy.props import (BoolProperty, CollectionProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty,
                       StringProperty)

from ..properties import settings_registration


MODES = (("BLEND", "Blend", "Overlap the end of the previous action with the start of this one (constraints "
                            "at the join must agree)"),
         ("CONNECT", "Connect", "Insert a generated step: base foot fixed, flying foot through keyframes"),
         ("INERTIALIZE", "Inertialize", "Start this action at once; the offset from the previous pose and "
                                        "velocity decays over the blend time"))
LIMB_ITEMS = tuple((k, k, "") for k in ("foot.L", "foot.R", "hand.L", "hand.R", "root"))
CONSTRAINT_ITEMS = (("supporting", "Supporting", "Planted on the ground"),
                    ("angular", "Angular", "Joint angles are kept or blended"),
                    ("spatial", "Spatial", "End-effector position and orientation are kept or blended"))


class HumanAnimQueueEntry(bpy.types.PropertyGroup):
    action: PointerProperty(name="Action", type=bpy.types.Action)
    frame_start: IntProperty(name="Start", default=0, description="0: the action's first frame")
    frame_end: IntProperty(name="End", default=0, description="0: the action's last frame")
    mode: EnumProperty(name="Transition", items=MODES, description="How this action joins the previous one")
    interrupt: BoolProperty(name="Interrupt", description="Start it at the frame below, interrupting the "
                                                          "previous action, instead of after it")
    interrupt_frame: IntProperty(name="At Frame", default=0,
                                 description="Frame of the motion so far (counted from its first frame) to "
                                             "interrupt at")
    initial_duration: FloatProperty(name="Initial", default=0.25, min=0.02, soft_max=2.0, unit="TIME_ABSOLUTE",
                                    description="Length of the initial phase used for transitions")
    terminal_duration: FloatProperty(name="Terminal", default=0.25, min=0.02, soft_max=2.0,
                                     unit="TIME_ABSOLUTE", description="Length of the terminal phase")
    status: StringProperty(name="Status", description="Accepted, or why the request was rejected")
    accepted: BoolProperty(name="Accepted", default=True)


class HumanAnimSynthesis(bpy.types.PropertyGroup):
    entries: CollectionProperty(type=HumanAnimQueueEntry)
    entry_index: IntProperty()
    reactions: BoolProperty(name="Dynamic Control and Reactions", default=False,
                            description="Run the synthesized motion through dynamic control with protective "
                                        "steps, falls and recovery (always on when the Dynamic Control panel "
                                        "has loads, pushes or a collider)")
    step_speed_min: FloatProperty(name="Step Speed Min", default=0.5, min=0.0, unit="VELOCITY",
                                  description="Eq. 3.6: a protective step above this root speed (m/s)")
    step_speed_max: FloatProperty(name="Step Speed Max", default=1.0, min=0.0, unit="VELOCITY",
                                  description="Eq. 3.6/3.9: above this root speed the character falls (m/s)")
    step_acceleration: FloatProperty(name="Acceleration", default=10.0, min=0.0, unit="ACCELERATION",
                                     description="Eq. 3.6/3.9: root acceleration a reaction needs (m/s^2)")
    k_root: FloatProperty(name="k root", default=0.4, min=0.0, soft_max=2.0,
                          description="Eq. 3.7: terminal root = k root * velocity + initial root (s)")
    k_foot: FloatProperty(name="k foot", default=1.0, min=0.0, soft_max=3.0,
                          description="Eq. 3.8: flying foot = k foot * (root - base foot) + root")
    recovery_time: FloatProperty(name="Recovery Time", default=0.5, min=0.0, soft_max=5.0, unit="TIME_ABSOLUTE",
                                 description="Recover to the initial posture when a joint misses its target "
                                             "longer than this")
    fall_back: PointerProperty(name="Fall Back", type=bpy.types.Action,
                               description="Your falling-back action; empty: a generated one")
    fall_forward: PointerProperty(name="Fall Forward", type=bpy.types.Action,
                                  description="Your falling-forward action; empty: a generated one")
    marker_limb: EnumProperty(name="Limb", items=LIMB_ITEMS)
    marker_constraint: EnumProperty(name="Constraint", items=CONSTRAINT_ITEMS)
    last_summary: StringProperty(name="Last Result")


CLASSES = (HumanAnimQueueEntry, HumanAnimSynthesis)

register, unregister = settings_registration(CLASSES, bpy.types.Scene, "humananim_synthesis", HumanAnimSynthesis)
