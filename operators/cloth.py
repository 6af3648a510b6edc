"""Fast plausible cloth: simulate a garment over the frame range, add a skirt or a stand-in body."""

import bpy
from bpy.props import FloatProperty, IntProperty

from ..humananim_addon.cloth import job as cloth
from ..solver.errors import HumanAnimError
from .common import JobOperator, _end_job, _fail, active_armature, run_reporting


def _message(s):
    t = s["timing_ms_per_frame"]
    done = "" if s["complete"] else " (cancelled: frames done kept)"
    return (f"'{s['object']}': {s['frames']} frames {s['frame_range'][0]}-{s['frame_range'][1]}{done}, "
            f"{s['particles']} particles -> {s['fine_faces']} faces, {t['total_ms']:.1f} ms/frame "
            f"(simulation {t['integration_ms']:.1f}, collision {t['collision_ms']:.1f}, smoothing "
            f"{t['smoothing_ms']:.1f}), deepest {s['max_depth_inside_mm']:.1f} mm")


class HUMANANIM_OT_cloth_simulate(JobOperator, bpy.types.Operator):
    """Simulate the garment over the frame range and write the smoothed cloth as a new mesh object played from a point cache (Esc keeps the frames done)"""

    bl_idname = "humananim.cloth_simulate"
    bl_label = "Simulate Cloth"

    @classmethod
    def poll(cls, context):
        props = getattr(context.scene, "humananim_cloth", None)
        return props is not None and props.garment is not None and props.armature is not None

    def job(self, context):
        self._cloth = cloth.ClothJob(context.scene)
        yield from self._cloth.steps()
        return _message(self._cloth.write())

    def modal(self, context, event):
        if event.type == "ESC":  # unlike other jobs, cloth keeps the frames done
            return self._cancel_keeping(context)
        return super().modal(context, event)

    def _cancel_keeping(self, context):
        self._steps.close()  # restores the scene frame
        _end_job(self, context)
        job = getattr(self, "_cloth", None)
        if job is None or len(job.frames_done) < 2:
            self.report({"WARNING"}, f"{self.bl_label}: cancelled before any frame was simulated")
            return {"CANCELLED"}
        return run_reporting(self, lambda: _message(job.write()))


class HUMANANIM_OT_cloth_preview(bpy.types.Operator):
    """Simulate the first frames of the range into a temporary mesh shown in the viewport, then play them in a loop (Esc stops and removes it: nothing is kept)"""

    bl_idname = "humananim.cloth_preview"
    bl_label = "Preview Cloth"
    bl_options = {"REGISTER"}  # it leaves nothing behind: no undo step to push

    frames: IntProperty(name="Frames", default=30, min=1, max=600, description="Simulated frames to preview")

    @classmethod
    def poll(cls, context):
        return HUMANANIM_OT_cloth_simulate.poll(context)

    def execute(self, context):
        """Without a window (batch, the bpy module): the frames are simulated and the preview
        removed at once; reports the speed."""
        def work():
            preview = cloth.ClothPreview(context.scene, self.frames)
            try:
                while preview.simulating:
                    preview.tick()
            finally:
                preview.stop()
            return preview.message()

        return run_reporting(self, work)

    def invoke(self, context, event):
        if bpy.app.background or context.window is None:
            return self.execute(context)
        self._preview = cloth.ClothPreview(context.scene, self.frames)
        self._timer = context.window_manager.event_timer_add(1.0 / 30.0, window=context.window)
        context.window_manager.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        if event.type == "ESC":
            return self._stop(context)
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        try:
            self._preview.tick()
        except HumanAnimError as error:  # ends the preview, which leaves nothing
            self._stop(context, report=False)
            return _fail(self, error)
        except Exception:
            self._stop(context, report=False)
            raise
        return {"RUNNING_MODAL"}

    def _stop(self, context, report=True):
        timer = getattr(self, "_timer", None)
        if timer is not None:
            context.window_manager.event_timer_remove(timer)
            self._timer = None
        self._preview.stop()
        if report:
            self.report({"INFO"}, self._preview.message())
        return {"CANCELLED"}


class HUMANANIM_OT_cloth_add_skirt(bpy.types.Operator):
    """Add a procedural skirt fitted to the armature's hips and thighs (the waistband is pinned), and make it the cloth garment"""

    bl_idname = "humananim.cloth_add_skirt"
    bl_label = "Add Skirt"
    bl_options = {"REGISTER", "UNDO"}

    rings: IntProperty(name="Rings", default=6, min=2, max=40)
    columns: IntProperty(name="Columns", default=11, min=4, max=80)
    length: FloatProperty(name="Length", default=0.9, min=0.1, max=3.0,
                          description="Hem below the hip joints, in thigh lengths")
    flare: FloatProperty(name="Flare", default=1.3, min=1.0, max=3.0, description="Hem width over the waist")

    @classmethod
    def poll(cls, context):
        return _armature(context) is not None

    def execute(self, context):
        arm = _armature(context)

        def work():
            obj = cloth.add_skirt(arm, context.scene, rings=self.rings, columns=self.columns, length=self.length,
                                  flare=self.flare)
            return f"'{obj.name}': {len(obj.data.vertices)} particles, waist pinned to '{arm.name}'"

        return run_reporting(self, work)


class HUMANANIM_OT_cloth_add_body(bpy.types.Operator):
    """Add a stand-in skinned body (capsules on the bones, deformed by the armature) to collide with"""

    bl_idname = "humananim.cloth_add_body"
    bl_label = "Add Capsule Body"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return _armature(context) is not None

    def execute(self, context):
        arm = _armature(context)

        def work():
            obj = cloth.add_capsule_body(arm, context.scene)
            context.scene.humananim_cloth.body = obj
            return f"'{obj.name}': {len(obj.data.polygons)} faces on '{arm.name}'"

        return run_reporting(self, work)


def _armature(context):
    arm = active_armature(context)
    if arm is None:
        props = getattr(context.scene, "humananim_cloth", None)
        arm = props.armature if props is not None else None
    return arm if arm is not None and arm.type == "ARMATURE" else None


CLASSES = (HUMANANIM_OT_cloth_simulate, HUMANANIM_OT_cloth_preview, HUMANANIM_OT_cloth_add_skirt,
           HUMANANIM_OT_cloth_add_body)
