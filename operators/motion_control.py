"""Dynamic motion control: the character keeps its motion and reacts to loads, impulses and collisions."""

import bpy

from ..humananim_addon import validation
from ..humananim_addon.motion_control import job as motion_control
from ..humananim_addon.motion_control import overlay
from .common import ArmatureJob, arrow_list_operators


class HUMANANIM_OT_dynamic_control(ArmatureJob, bpy.types.Operator):
    """Keep the character's motion under loads, impulses and collisions (comfort and balance control), and bake the result"""

    bl_idname = "humananim.dynamic_control"
    bl_label = "Dynamic Control"

    @staticmethod
    def run(obj, scene):
        validation.check_job(obj, scene.humananim_control, "impulses")
        return motion_control.run(obj, scene)

    @staticmethod
    def message(summary):
        return (f"'{summary['action']}': {summary['frames']} frames in {summary['seconds']:.1f} s "
                f"({summary['real_time_factor']:.2f}x real time), peak stress "
                f"{summary['peak_stress_nm']:.0f} N m ({summary['peak_stress_bone']}), balance error "
                f"{100 * summary['max_balance_error_m']:.1f} cm, {summary['frames_falling']} frames falling")


HUMANANIM_OT_add_impulse, HUMANANIM_OT_remove_impulse = arrow_list_operators(
    "impulse", "an impulse", "humananim_control", "impulses", "impulse_index", motion_control.add_impulse)


class HUMANANIM_OT_toggle_overlay(bpy.types.Operator):
    """Show or hide the dynamic control overlay: the input motion as a ghost, bones coloured by control
    (red stressed, blue comfort, green balance, yellow passive), ZMP and support polygon"""

    bl_idname = "humananim.toggle_overlay"
    bl_label = "Control Overlay"

    def execute(self, context):
        if overlay.is_enabled():
            overlay.disable()
        else:
            overlay.enable()
        for area in getattr(context.screen, "areas", ()):
            if area.type == "VIEW_3D":
                area.tag_redraw()
        return {"FINISHED"}


CLASSES = (HUMANANIM_OT_dynamic_control, HUMANANIM_OT_add_impulse, HUMANANIM_OT_remove_impulse,
           HUMANANIM_OT_toggle_overlay)
