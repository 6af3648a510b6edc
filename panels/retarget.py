"""The Retarget Motion panel: the button, and the last retarget onto the active armature: feet,
leg ratio and the write-back's mismatch per role."""

import bpy

from ..humananim_addon.retarget import job
from .rig import HumanAnimPanel


class VIEW3D_PT_humananim_retarget(HumanAnimPanel, bpy.types.Panel):
    bl_label = "Retarget Motion"

    def draw(self, context):
        layout = self.layout
        layout.operator("humananim.retarget_motion")
        summary = job.stored(context.active_object)
        if summary is None:
            layout.label(text="Select the source, then the target rig", icon="INFO")
            return
        col = layout.column(align=True)
        for line in job.lines(summary):
            col.label(text=line)


CLASSES = (VIEW3D_PT_humananim_retarget,)
