"""The Retarget Motion panel: the button, and the last retarget onto the active armature: feet,
leg ratio and the write-back's mismatch per role."""

import bpy

from ..humananim_addon.retarget import job
from .common import draw_button_and_report
from .rig import HumanAnimPanel


class VIEW3D_PT_humananim_retarget(HumanAnimPanel, bpy.types.Panel):
    bl_label = "Retarget Motion"

    def draw(self, context):
        summary = job.stored(context.active_object)
        lines = None if summary is None else job.lines(summary)
        draw_button_and_report(self.layout, "humananim.retarget_motion", lines, "Select the source, then the target rig")


CLASSES = (VIEW3D_PT_humananim_retarget,)
