"""Closed-loop simulation in Blender: its settings, pushes from Empties, stress curves back out."""

import time

import bpy
import numpy as np
from bpy.props import CollectionProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty, StringProperty

from ..solver import rotations
from ..solver.body_roles import SIDES, sided
from ..solver.dynamics.closed_loop import Push, Settings, iter_simulate
from ..solver.motion_control.contacts import contact_floor
from ..solver.dynamics.ground_contact import GroundModel
from ..solver.errors import MotionError
from .actions import bone_path
from .arrows import arrow_forces, place_arrow
from .properties import settings_registration
from .rig.capability import RigView

TORQUE = "humananim_torque"  # N m, magnitude over the joint's axes
USAGE = "humananim_strength_usage"  # required / available torque, worst axis; > 1: too weak
ASSIST = "humananim_balance_assist"  # N of residual force the pelvis needed


class HumanAnimPush(bpy.types.PropertyGroup):
    # no poll filter to Empties: a PointerProperty poll crashes the bpy 4.2 module at exit, and
    # any object's location and Z axis define a push as well as an arrow Empty's
    empty: PointerProperty(name="Arrow", type=bpy.types.Object,
                           description="An object (an arrow Empty) whose location is where the push hits "
                                       "and whose Z axis is its direction")
    bone: StringProperty(name="Bone", description="The bone that is pushed")
    frame: IntProperty(name="Frame", default=1)
    duration: FloatProperty(name="Duration", default=0.1, min=0.001, soft_max=2.0, unit="TIME_ABSOLUTE")
    magnitude: FloatProperty(name="Force", default=300.0, min=0.0, soft_max=3000.0,
                             description="Newtons")


class HumanAnimSimulation(bpy.types.PropertyGroup):
    action: PointerProperty(name="Source Action", type=bpy.types.Action,
                            description="The motion to follow; empty: the active action")
    frame_start: IntProperty(name="Start", default=0, description="0: the action's first frame")
    frame_end: IntProperty(name="End", default=0, description="0: the action's last frame")
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
    strength_scale: FloatProperty(name="Strength", default=1.0, min=0.0, soft_max=3.0,
                                  description="Scale of the muscle strength model")
    ground: EnumProperty(name="Ground", items=(
        ("MOTION", "From Motion", "At the lowest point the feet (or any contact) reach in the source motion"),
        ("HEIGHT", "Height", "A horizontal ground at the height below"),
    ))
    ground_height: FloatProperty(name="Ground Height", default=0.0, unit="LENGTH")
    load_left: FloatProperty(name="Left Hand Load", default=0.0, min=0.0, soft_max=50.0, unit="MASS")
    load_right: FloatProperty(name="Right Hand Load", default=0.0, min=0.0, soft_max=50.0, unit="MASS")
    pushes: CollectionProperty(type=HumanAnimPush)
    push_index: IntProperty()


CLASSES = (HumanAnimPush, HumanAnimSimulation)


register, unregister = settings_registration(CLASSES, bpy.types.Scene, "humananim_simulation", HumanAnimSimulation)


def frame_range(props, action):
    start = props.frame_start or action.frame_range[0]
    end = props.frame_end or action.frame_range[1]
    return start, end


def solver_settings(scene, props, skeleton, traj):
    """The solver's Settings from the panel's values, the scene's gravity and the pushes."""
    gravity = tuple(scene.gravity) if scene.use_gravity else (0.0, 0.0, 0.0)
    loads = {}
    for side, kg in zip(SIDES, (props.load_left, props.load_right)):
        hand = skeleton.roles.bone(sided("hand", side))
        if kg > 0.0 and hand:
            loads[hand] = kg
    height = contact_floor(skeleton, traj) if props.ground == "MOTION" else props.ground_height
    return Settings(gravity=gravity, ground=GroundModel(height=height), loads=loads,
                    pushes=tuple(pushes(props, skeleton, traj, scene)), strength_scale=props.strength_scale,
                    tracking=props.tracking, controller=props.controller.lower(),
                    root_support=props.balance_assist)


def pushes(props, skeleton, traj, scene):
    """Each arrow becomes a force on its bone (see arrows.arrow_forces)."""
    return [Push(time=seconds, joint=item.bone, point=point, direction=direction, magnitude=item.magnitude,
                 duration=item.duration)
            for item, seconds, point, direction in arrow_forces(props.pushes, skeleton, traj, scene)]


def stress_channels(obj, skeleton, result):
    """Custom-property curves per bone (torque, strength usage) and on the object (assist)."""
    joints = result.model.dof_joint[6:]
    channels = {}
    for j in np.unique(joints):
        cols = joints == j
        bone = skeleton.names[j]
        pb = obj.pose.bones[bone]
        for prop in (TORQUE, USAGE):
            if prop not in pb:
                pb[prop] = 0.0  # the property must exist for its curve to evaluate
        channels[(f'{bone_path(bone)}["{TORQUE}"]', bone)] = np.linalg.norm(result.torques[:, cols], axis=1)
        channels[(f'{bone_path(bone)}["{USAGE}"]', bone)] = np.abs(result.usage[:, cols]).max(axis=1)
    if ASSIST not in obj:
        obj[ASSIST] = 0.0
    channels[(f'["{ASSIST}"]', "HumanAnim")] = np.linalg.norm(result.root_wrench[:, 3:6], axis=1)
    return channels


def run(obj, scene):
    """The simulation job: read the source motion, simulate, write a new action with stress
    curves. Yields progress; returns a summary dict."""
    from .validation import check_job
    props = scene.humananim_simulation
    source, start, end = check_job(obj, props, "pushes")
    rig = RigView(obj, scene)  # a control rig: the deform bones as Blender shows them, keyed through the controls
    skeleton = rig.skeleton
    traj = yield from rig.iter_read(source, frame_range=(start, end))
    if traj.frame_count < 3:
        raise MotionError(f"'{source.name}' has {traj.frame_count} frame{'s' if traj.frame_count != 1 else ''} "
                          "in the range: at least 3 are needed to simulate")
    settings = solver_settings(scene, props, skeleton, traj)
    t0 = time.perf_counter()
    result = yield from iter_simulate(skeleton, traj, settings)
    seconds = time.perf_counter() - t0
    out = yield from rig.iter_write(result.trajectories, f"{source.name}.sim", scene.humananim.output, source,
                                    stress_channels(obj, skeleton, result))
    joints = np.unique(result.model.dof_joint[6:])
    angle = rotations.angle_between(traj.rotations[:, joints], result.trajectories.rotations[:, joints])
    return {"source_action": source.name, "action": out.name, "frames": traj.frame_count,
            "fps": traj.fps, "simulated_seconds": traj.frame_count / traj.fps,
            "seconds": round(seconds, 3), "real_time_factor": traj.frame_count / traj.fps / seconds,
            "tracking_error_deg_rms": float(np.degrees(np.sqrt(np.mean(angle ** 2)))),
            "peak_strength_usage": float(np.abs(result.usage).max()),
            "peak_balance_assist_n": float(np.linalg.norm(result.root_wrench[:, 3:6], axis=1).max()),
            "pushes": len(settings.pushes), "loads_kg": dict(settings.loads),
            "ground_height_m": settings.ground.height, **rig.summary()}


def add_push(obj, scene, bone_name, frame, direction=None, magnitude=300.0, duration=0.1):
    """An arrow Empty in front of the bone (see arrows.place_arrow), registered as a push."""
    empty = place_arrow(obj, scene, bone_name, frame, direction, name="Push")
    props = scene.humananim_simulation
    item = props.pushes.add()
    item.empty, item.bone, item.frame = empty, bone_name, frame
    item.magnitude, item.duration = magnitude, duration
    props.push_index = len(props.pushes) - 1
    return item
