"""Batch operators: start a batch in the background (polled by a timer, never blocking Blender),
stop it as Ctrl-C would, open its HTML report."""

import functools
import os
import webbrowser

import bpy

from ..humananim_addon.batch import blender as batch


class HUMANANIM_OT_batch_start(bpy.types.Operator):
    """Run the pipeline over every take in the background (see the Batch panel)"""
    bl_idname = "humananim.batch_start"
    bl_label = "Start Batch"

    def execute(self, context):
        settings = context.scene.humananim_batch
        try:
            job = batch.start_job(settings)
        except (ValueError, OSError) as error:
            self.report({"ERROR"}, f"Batch: {error}")
            return {"CANCELLED"}
        bpy.app.timers.register(functools.partial(_poll, context.scene.name), first_interval=batch.POLL_SECONDS)
        self.report({"INFO"}, f"Batch started: {job.describe()}")
        return {"FINISHED"}


def _poll(scene_name):
    scene = bpy.data.scenes.get(scene_name)
    return batch.poll_job(scene.humananim_batch) if scene is not None else None


class HUMANANIM_OT_batch_stop(bpy.types.Operator):
    """Stop the batch: finished takes are kept, starting it again does the rest"""
    bl_idname = "humananim.batch_stop"
    bl_label = "Stop Batch"

    @classmethod
    def poll(cls, context):
        return context.scene.humananim_batch.running

    def execute(self, context):
        job = batch.JOBS.get("current")
        if job is not None:
            job.stop()
        return {"FINISHED"}


class HUMANANIM_OT_batch_report(bpy.types.Operator):
    """Open the batch's HTML report in the web browser"""
    bl_idname = "humananim.batch_report"
    bl_label = "Open Report"

    @classmethod
    def poll(cls, context):
        return bool(context.scene.humananim_batch.report)

    def execute(self, context):
        path = context.scene.humananim_batch.report
        if not os.path.isfile(path):
            self.report({"ERROR"}, f"Batch: no report at {path}")
            return {"CANCELLED"}
        webbrowser.open("file://" + path)
        return {"FINISHED"}


CLASSES = (batch.HumanAnimBatchSettings, HUMANANIM_OT_batch_start, HUMANANIM_OT_batch_stop,
           HUMANANIM_OT_batch_report)
