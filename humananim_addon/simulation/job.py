"""Closed-loop simulation in Blender: its settings, pushes from Empties, stress curves back out."""

import time

import numpy as np

from ...solver import rotations
from ...solver.dynamics.closed_loop import Push, Settings, iter_simulate
from ...solver.motion_control.contacts import contact_floor
from ...solver.dynamics.ground_contact import GroundModel
from ...solver.errors import MotionError
from .. import actions
from ..actions import bone_path
from ..armature import skeleton_from_armature
from ..arrows import arrow_forces
from ..forces import add_arrow, gravity_of, hand_loads
from ..rig.capability import RigView

TORQUE = "humananim_torque"  # N m, magnitude over the joint's axes
USAGE = "humananim_strength_usage"  # required / available torque, worst axis; > 1: too weak
ASSIST = "humananim_balance_assist"  # N of residual force the pelvis needed


def frame_range(props, action):
    start = props.frame_start or action.frame_range[0]
    end = props.frame_end or action.frame_range[1]
    return start, end


def solver_settings(scene, props, skeleton, traj):
    """The solver's Settings from the panel's values, the scene's gravity and the pushes."""
    gravity = gravity_of(scene)
    loads = dict(hand_loads(props, skeleton))
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
    from ..validation import check_job
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
    return add_arrow(obj, scene, scene.humananim_simulation, "pushes", "push_index", bone_name, frame, direction,
                     magnitude, duration, "Push")
