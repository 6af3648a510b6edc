"""The Motion QA panel: the last result's measures (slide, ground, pops, lengths, height, NaN,
source), the worst bone and frame of each, and a button to go to that frame."""

import bpy

from ..humananim_addon.qa import job as qa
from ..solver.qa import rows
from .rig import HumanAnimPanel


class VIEW3D_PT_humananim_qa(HumanAnimPanel, bpy.types.Panel):
    bl_label = "Motion QA"

    def draw(self, context):
        layout = self.layout
        report = qa.stored(context.active_object)
        if report is None:
            layout.label(text="No result measured yet: run a HumanAnim tool", icon="INFO")
            return
        failed = report.get("passed") is False
        sources = ", ".join(report.get("sources", [])) or "nothing (made from scratch)"
        layout.label(text=f"'{report.get('action', '?')}' against {sources}", icon="ACTION")
        layout.label(text=f"{len(report['warnings'])} warning(s)" if failed else "Within every threshold",
                     icon="ERROR" if failed else "CHECKMARK")
        col = layout.column(align=True)
        for label, text, bad, bone, frame in rows(report):
            row = col.row(align=True)
            row.alert = bad
            row.label(text=f"{label}: {text}" + (f" '{bone}'" if bone else ""))
            if frame is not None:
                op = row.operator("humananim.qa_jump", text=f"{frame:g}", icon="TIME")
                if op is not None:  # None in a layout that only records the calls
                    op.frame = int(round(frame))


CLASSES = (VIEW3D_PT_humananim_qa,)
