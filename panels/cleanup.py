"""The Clean Up Capture panel: the button, and the last clean-up's report, one line per repair
(what changed, the QA before and after)."""

import bpy

from ..humananim_addon import cleanup
from .rig import HumanAnimPanel


class VIEW3D_PT_humananim_cleanup(HumanAnimPanel, bpy.types.Panel):
    bl_label = "Clean Up Capture"

    def draw(self, context):
        layout = self.layout
        layout.operator("humananim.clean_up_capture")
        report = cleanup.stored(context.active_object)
        if report is None:
            layout.label(text="Cleans the active action into a new one", icon="INFO")
            return
        col = layout.column(align=True)
        for line in cleanup.lines(report):
            col.label(text=line)


CLASSES = (VIEW3D_PT_humananim_cleanup,)
