"""The Batch panel: inputs, pipeline, local workers or a Dask scheduler; the running batch's
progress and its report. Shown whatever is selected: a batch works on files, not on the scene."""

import bpy

from .rig import HumanAnimPanel


class VIEW3D_PT_humananim_batch(HumanAnimPanel, bpy.types.Panel):
    bl_label = "Batch"
    bl_options = {"DEFAULT_CLOSED"}

    @classmethod
    def poll(cls, context):
        return context.scene is not None

    def draw(self, context):
        s = context.scene.humananim_batch
        layout = self.layout
        col = layout.column()
        col.use_property_split = True
        col.enabled = not s.running
        col.prop(s, "inputs")
        col.prop(s, "pipeline")
        col.prop(s, "out_dir")
        col.prop(s, "engine")
        col.prop(s, "workers" if s.engine == "LOCAL" else "scheduler")
        col.prop(s, "retries")
        col.prop(s, "timeout")
        col.prop(s, "python")
        row = layout.row()
        if s.running:
            row.operator("humananim.batch_stop", icon="CANCEL")
        else:
            row.operator("humananim.batch_start", icon="PLAY")
        if s.running or s.status:
            layout.progress(factor=s.fraction, type="BAR", text=s.status or "starting...")
        if s.error:
            layout.label(text=s.error, icon="ERROR")
        if s.report:
            layout.operator("humananim.batch_report", icon="URL")


CLASSES = (VIEW3D_PT_humananim_batch,)
