"""Closed-loop simulation: the body follows its action under gravity, loads and pushes."""

import bpy

from ..humananim_addon.simulation import job as simulation
from .common import ArmatureJob, arrow_list_operators


class HUMANANIM_OT_simulate(ArmatureJob, bpy.types.Operator):
    """Simulate the character following its action, with gravity, ground, loads and pushes, and bake the result"""

    bl_idname = "humananim.simulate"
    bl_label = "Simulate"
    run = staticmethod(simulation.run)

    @staticmethod
    def message(summary):
        return (f"'{summary['action']}': {summary['frames']} frames in {summary['seconds']:.1f} s "
                f"({summary['real_time_factor']:.2f}x real time), tracking error "
                f"{summary['tracking_error_deg_rms']:.1f} deg RMS, peak strength use "
                f"{summary['peak_strength_usage']:.2f}")


HUMANANIM_OT_add_push, HUMANANIM_OT_remove_push = arrow_list_operators(
    "push", "a push", "humananim_simulation", "pushes", "push_index", simulation.add_push)

CLASSES = (HUMANANIM_OT_simulate, HUMANANIM_OT_add_push, HUMANANIM_OT_remove_push)
