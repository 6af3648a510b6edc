"""Closed-loop simulation: the body follows its action under gravity, loads and pushes."""

import bpy

from ..humananim_addon import simulation
from .common import JobOperator, active_armature


class HUMANANIM_OT_simulate(JobOperator, bpy.types.Operator):
    """Simulate the character following its action, with gravity, ground, loads and pushes, and bake the result"""

    bl_idname = "humananim.simulate"
    bl_label = "Simulate"

    @classmethod
    def poll(cls, context):
        return active_armature(context) is not None

    def job(self, context):
        summary = yield from simulation.run(active_armature(context), context.scene)
        return (f"'{summary['action']}': {summary['frames']} frames in {summary['seconds']:.1f} s "
                f"({summary['real_time_factor']:.2f}x real time), tracking error "
                f"{summary['tracking_error_deg_rms']:.1f} deg RMS, peak strength use "
                f"{summary['peak_strength_usage']:.2f}")


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
        bone = obj.data.bones.active.name
        simulation.add_push(obj, scene, bone, scene.frame_current)
        self.report({"INFO"}, f"push on '{bone}' at frame {scene.frame_current}: move and turn the arrow")
        return {"FINISHED"}


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
