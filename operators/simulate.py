"""Closed-loop simulation: the body follows its action under gravity, loads and pushes."""

import time

import bpy
import numpy as np

from ..humananim_addon import actions, armature, simulation
from ..solver import rotations
from ..solver.dynamics.closed_loop import iter_simulate
from ..solver.errors import MotionError
from .common import JobOperator, active_armature


class HUMANANIM_OT_simulate(JobOperator, bpy.types.Operator):
    """Simulate the character following its action, with gravity, ground, loads and pushes, and bake the result"""

    bl_idname = "humananim.simulate"
    bl_label = "Simulate"

    @classmethod
    def poll(cls, context):
        return active_armature(context) is not None

    def job(self, context):
        obj, scene = active_armature(context), context.scene
        props = scene.humananim_simulation
        source = props.action or (obj.animation_data.action if obj.animation_data else None)
        if source is None:
            raise MotionError(f"'{obj.name}' has no action to simulate: choose a source action")
        skeleton = armature.skeleton_from_armature(obj, scene)
        traj = yield from actions.iter_read_action(obj, scene, skeleton, source,
                                                    frame_range=simulation.frame_range(props, source))
        settings = simulation.solver_settings(scene, props, skeleton, traj)
        t0 = time.perf_counter()
        result = yield from iter_simulate(skeleton, traj, settings)
        seconds = time.perf_counter() - t0
        channels = simulation.stress_channels(obj, skeleton, result)
        out = actions.write_action(obj, skeleton, result.trajectories, f"{source.name}.sim",
                                   scene.humananim.output, source, channels)
        error = tracking_error_deg(traj, result.trajectories, result.model.dof_joint[6:])
        return (f"'{out.name}': {traj.frame_count} frames in {seconds:.1f} s "
                f"({traj.frame_count / traj.fps / seconds:.2f}x real time), "
                f"tracking error {error:.1f} deg RMS, peak strength use {np.abs(result.usage).max():.2f}")


def tracking_error_deg(source, simulated, joints):
    """RMS over frames and simulated joints of the rotation between input and result."""
    joints = np.unique(joints)
    angle = rotations.angle_between(source.rotations[:, joints], simulated.rotations[:, joints])
    return float(np.degrees(np.sqrt(np.mean(angle ** 2))))


class HUMANANIM_OT_add_push(bpy.types.Operator):
    """Add a push on the active bone: an arrow Empty in front of it, pointing into the body"""

    bl_idname = "humananim.add_push"
    bl_label = "Add Push"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        obj = active_armature(context)
        return obj is not None and obj.data.bones.active is not None

    def execute(self, context):
        obj, scene = active_armature(context), context.scene
        bone = obj.data.bones.active
        pose = obj.matrix_world @ obj.pose.bones[bone.name].matrix
        middle = pose @ _vector((0.0, bone.length / 2, 0.0))
        empty = bpy.data.objects.new(f"Push {bone.name}", None)
        empty.empty_display_type = "SINGLE_ARROW"
        empty.empty_display_size = 0.3
        axis = (obj.matrix_world.to_3x3() @ _vector((0.0, 1.0, 0.0))).normalized()  # the rig faces -Y
        empty.location = middle - 0.3 * axis
        empty.rotation_euler = _vector((0.0, 0.0, 1.0)).rotation_difference(axis).to_euler()
        scene.collection.objects.link(empty)
        item = scene.humananim_simulation.pushes.add()
        item.empty, item.bone, item.frame = empty, bone.name, scene.frame_current
        scene.humananim_simulation.push_index = len(scene.humananim_simulation.pushes) - 1
        self.report({"INFO"}, f"push on '{bone.name}' at frame {scene.frame_current}: move and turn the arrow")
        return {"FINISHED"}


def _vector(values):
    from mathutils import Vector
    return Vector(values)


class HUMANANIM_OT_remove_push(bpy.types.Operator):
    """Remove the selected push (its arrow Empty stays in the scene)"""

    bl_idname = "humananim.remove_push"
    bl_label = "Remove Push"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        props = context.scene.humananim_simulation
        return 0 <= props.push_index < len(props.pushes)

    def execute(self, context):
        props = context.scene.humananim_simulation
        props.pushes.remove(props.push_index)
        props.push_index = min(props.push_index, len(props.pushes) - 1)
        return {"FINISHED"}


CLASSES = (HUMANANIM_OT_simulate, HUMANANIM_OT_add_push, HUMANANIM_OT_remove_push)
