"""Closed-loop simulation: the body follows its action under gravity, loads and pushes."""

import bpy

from ..humananim_addon.simulation import job as simulation
from .common import AddOnActiveBone, JobOperator, RemoveActiveItem, active_armature, with_qa


class HUMANANIM_OT_simulate(JobOperator, bpy.types.Operator):
    """Simulate the character following its action, with gravity, ground, loads and pushes, and bake the result"""

    bl_idname = "humananim.simulate"
    bl_label = "Simulate"
    measures_motion = True

    @classmethod
    def poll(cls, context):
        return active_armature(context) is not None

    def job(self, context):
        obj = active_armature(context)
        summary = yield from simulation.run(obj, context.scene)
        return with_qa(self, context, obj, summary, f"'{summary['action']}': {summary['frames']} frames in {summary['seconds']:.1f} s "
                f"({summary['real_time_factor']:.2f}x real time), tracking error "
                f"{summary['tracking_error_deg_rms']:.1f} deg RMS, peak strength use "
                f"{summary['peak_strength_usage']:.2f}")


class HUMANANIM_OT_add_push(AddOnActiveBone, bpy.types.Operator):
    """Add a push on the active bone: an arrow Empty in front of it, pointing into the body"""

    bl_idname = "humananim.add_push"
    bl_label = "Add Push"
    what = "push"
    add = staticmethod(simulation.add_push)


class HUMANANIM_OT_remove_push(RemoveActiveItem, bpy.types.Operator):
    """Remove the selected push (its arrow Empty stays in the scene)"""

    bl_idname = "humananim.remove_push"
    bl_label = "Remove Push"
    settings, items, index = "humananim_simulation", "pushes", "push_index"


CLASSES = (HUMANANIM_OT_simulate, HUMANANIM_OT_add_push, HUMANANIM_OT_remove_push)
