"""The Clean Up Capture panel: the button, and the last clean-up's report, one line per repair
(what changed, the QA before and after)."""

import bpy

from ..humananim_addon import cleanup
from .common import draw_button_and_report
from .rig import HumanAnimPanel


class VIEW3D_PT_humananim_cleanup(HumanAnimPanel, bpy.types.Panel):
    bl_label = "Clean Up Capture"

    def draw(self, context):
        report = cleanup.stored(context.active_object)
        lines = None if report is None else cleanup.lines(report)
        draw_button_and_report(self.layout, "humananim.clean_up_capture", lines, "Cleans the active action into a new one")


CLASSES = (VIEW3D_PT_humananim_cleanup,)
