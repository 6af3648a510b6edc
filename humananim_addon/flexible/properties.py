"""Flexible bodies' settings on the object (object.humananim_flexible): modes, poses of the pose
graph, springs, the simulation and the optimisation."""

import bpy
from bpy.props import (BoolProperty, CollectionProperty, EnumProperty, FloatProperty, FloatVectorProperty,
                       IntProperty, PointerProperty, StringProperty)

from ...solver.flexible.control import COSTS
from ..properties import settings_registration

MAX_ACTIVE = 8          # amplitudes a pose holds: up to 8 active modes

INTEGRATOR_ITEMS = (
    ("implicit", "Implicit Midpoint", "Stable with stiff modes and ground, keeps energy (two force evaluations and one factorisation a step)"),
    ("semi_implicit", "Semi-Implicit", "Linearly implicit: as stable, half the cost, a tumbling body gains a little energy"),
    ("thesis", "Thesis (Explicit)", "The thesis's finite-difference scheme (eq. 4.22-4.23): needs small steps"),
)


class HumanAnimFlexMode(bpy.types.PropertyGroup):
    key: StringProperty(name="Shape Key", description="The lattice shape key that is this mode")
    use: BoolProperty(name="Use", default=True, description="Simulate this mode")
    active: BoolProperty(name="Active", default=False,
                         description="Driven by a PD controller towards the pose graph (else passive)")
    stiffness: FloatProperty(name="Stiffness", default=3.0, min=0.0, soft_max=20.0,
                             description="The mode's natural frequency alone at rest, Hz: its potential "
                                         "1/2 k gamma^2 with k from its modal mass")
    damping: FloatProperty(name="Damping", default=0.3, min=0.0, soft_max=2.0,
                           description="Damping ratio of the mode (1 = critical)")


class HumanAnimFlexPose(bpy.types.PropertyGroup):
    values: FloatVectorProperty(name="Amplitudes", size=MAX_ACTIVE, min=-1.0, max=1.0,
                                description="Target amplitude of each active mode, in their list order")
    duration: FloatProperty(name="Duration", default=0.3, min=0.02, soft_max=2.0, unit="TIME_ABSOLUTE",
                            description="How long this pose stays the target (s)")


class HumanAnimFlexSpring(bpy.types.PropertyGroup):
    # no poll filter: a PointerProperty poll crashes the bpy 4.2 module at exit
    target: PointerProperty(name="To Object", type=bpy.types.Object,
                            description="The spring's other end: this object's origin (followed if animated)")
    point: FloatVectorProperty(name="Lattice Point", size=3, default=(0.5, 0.5, 1.0), min=0.0, max=1.0,
                               description="Where it holds the character: lattice coordinates u, v, w in 0..1")
    stiffness: FloatProperty(name="Stiffness", default=500.0, min=0.0, soft_max=1e5, description="N/m")
    damping: FloatProperty(name="Damping", default=10.0, min=0.0, soft_max=1e4, description="N s/m")
    rest_length: FloatProperty(name="Rest Length", default=0.0, min=0.0, unit="LENGTH")


class HumanAnimFlexible(bpy.types.PropertyGroup):
    lattice: PointerProperty(name="Lattice", type=bpy.types.Object,
                             description="The Lattice deforming the object; empty: its Lattice modifier's")
    modes: CollectionProperty(type=HumanAnimFlexMode)
    mode_index: IntProperty()
    springs: CollectionProperty(type=HumanAnimFlexSpring)
    spring_index: IntProperty()
    points: EnumProperty(name="Masses", items=(
        ("SAMPLES", "Object Samples", "Sample points of the object's undeformed mesh"),
        ("LATTICE", "Lattice Points", "The lattice points themselves"),
    ))
    sample_count: IntProperty(name="Sample Points", default=24, min=2, max=2000,
                              description="How many mesh points carry the mass")
    density: FloatProperty(name="Density", default=500.0, min=1.0, soft_max=5000.0,
                           description="kg per cubic metre: the mass is the mesh volume times this")
    mass: FloatProperty(name="Mass", default=0.0, min=0.0, soft_max=500.0, unit="MASS",
                        description="Total mass; 0: from the volume and density")
    ground_height: FloatProperty(name="Ground Height", default=0.0, unit="LENGTH")
    ground_slope: FloatProperty(name="Slope", default=0.0, min=-1.4, max=1.4, subtype="ANGLE",
                                description="The ground rises by this angle along the heading")
    ground_heading: FloatProperty(name="Heading", default=0.0, subtype="ANGLE",
                                  description="Direction (about Z, from X) the slope rises along")
    friction: FloatProperty(name="Friction", default=0.8, min=0.0, soft_max=2.0,
                            description="Coulomb coefficient: friction never exceeds it times the normal force")
    ground_stiffness: FloatProperty(name="Ground Stiffness", default=6000.0, min=1.0, soft_max=50000.0,
                                    description="Penalty spring, N/m per kg of the character")
    ground_damping: FloatProperty(name="Normal Damping", default=80.0, min=0.0, soft_max=1000.0,
                                  description="N s/m per kg of the character, along the ground normal")
    friction_damping: FloatProperty(name="Friction Damping", default=80.0, min=0.0, soft_max=1000.0,
                                    description="N s/m per kg of the character, along the ground")
    integrator: EnumProperty(name="Integrator", items=INTEGRATOR_ITEMS, default="implicit")
    substeps: IntProperty(name="Steps per Frame", default=4, min=1, max=64)
    frame_start: IntProperty(name="Start", default=1)
    frame_end: IntProperty(name="End", default=250)
    handover_frame: IntProperty(name="Simulate From", default=1,
                                description="Up to this frame the shape-key values are key-framed by hand "
                                            "(the Key's animation); from it the simulation takes over with "
                                            "the key-framed motion's velocity")
    use_hold: BoolProperty(name="Hold Point", default=False,
                           description="While key-framed, move the object so this lattice point stays put")
    hold_point: FloatVectorProperty(name="Held Point", size=3, default=(0.5, 0.5, 0.0), min=0.0, max=1.0,
                                    description="Lattice coordinates (u, v, w in 0..1) of the held point")
    use_control: BoolProperty(name="Pose Control", default=True,
                              description="Drive the active modes through the pose graph")
    controller: EnumProperty(name="Controller", items=(
        ("POSES", "Pose Graph", "The pose graph as edited"),
        ("BEST", "Best Found", "The best controller the optimisation stored"),
    ))
    control_frequency: FloatProperty(name="Control Stiffness", default=4.0, min=0.1, soft_max=20.0,
                                     description="PD stiffness C as the natural frequency (Hz) of each active mode")
    control_damping: FloatProperty(name="Control Damping", default=0.8, min=0.0, soft_max=3.0,
                                   description="PD damping D as a damping ratio")
    poses: CollectionProperty(type=HumanAnimFlexPose)
    pose_index: IntProperty()
    optimize: EnumProperty(name="Optimise", items=(
        ("both", "Poses and Durations", ""), ("poses", "Poses", ""), ("durations", "Durations", "")))
    cost: EnumProperty(name="Cost", items=tuple((k, k.replace("_", " ").title(), v) for k, v in COSTS.items()),
                       default="energy_distance")
    direction: FloatVectorProperty(name="Direction", size=3, default=(1.0, 0.0, 0.0), subtype="DIRECTION",
                                   description="World direction the character should travel")
    cost_scale: FloatProperty(name="Cost Scale", default=1.0, min=1e-9,
                              description="The constant of the thesis's energy / (scale sqrt(...)) costs")
    w_energy: FloatProperty(name="Energy Weight", default=0.0001, description="Custom cost: per joule consumed")
    w_distance: FloatProperty(name="Distance Weight", default=1.0, description="Custom cost: per metre forward")
    w_speed: FloatProperty(name="Speed Weight", default=0.0, description="Custom cost: per m/s at the end")
    w_tilt: FloatProperty(name="Tilt Weight", default=0.0, description="Custom cost: per radian tilted at the end")
    trials: IntProperty(name="Trials", default=60, min=1, max=100000, description="Forward simulations")
    trial_seconds: FloatProperty(name="Trial Length", default=12.0, min=0.5, soft_max=60.0, unit="TIME_ABSOLUTE")
    trial_step: FloatProperty(name="Trial Step", default=0.02, min=0.001, max=0.05,
                              description="Time step of the trials (s), semi-implicit integration")
    start_temperature: FloatProperty(name="Start Temperature", default=0.2, min=1e-6,
                                     description="T0, relative to the first cost")
    frozen_temperature: FloatProperty(name="Frozen Temperature", default=0.002, min=1e-9,
                                      description="T_frozen, relative to the first cost")
    seed: IntProperty(name="Seed", default=0, min=0, description="The same seed gives the same result")
    best_poses: CollectionProperty(type=HumanAnimFlexPose)
    best_cost: FloatProperty(name="Best Cost", default=0.0)
    best_distance: FloatProperty(name="Best Distance", default=0.0, unit="LENGTH")
    best_energy: FloatProperty(name="Best Energy", default=0.0)


CLASSES = (HumanAnimFlexMode, HumanAnimFlexPose, HumanAnimFlexSpring, HumanAnimFlexible)

register, unregister = settings_registration(CLASSES, bpy.types.Object, "humananim_flexible", HumanAnimFlexible)
