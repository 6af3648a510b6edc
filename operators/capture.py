"""Live capture: the modal session that streams devices into the rig, and its buttons."""

import bpy

from ..humananim_addon.capture import job as capture
from ..solver.errors import HumanAnimError
from .common import RemoveActiveItem, active_armature


def _report_error(op, error):
    op.report({"ERROR"}, str(error))
    return {"CANCELLED"}


class HUMANANIM_OT_capture_live(bpy.types.Operator):
    """Stream the capture devices into the active armature at the display rate (Esc ends the session; a take being recorded becomes a new action)"""

    bl_idname = "humananim.capture_live"
    bl_label = "Live Capture"
    bl_options = {"REGISTER", "UNDO"}

    _timer = None

    @classmethod
    def poll(cls, context):
        return active_armature(context) is not None or capture.LIVE is not None

    def execute(self, context):
        # without a window (batch, the bpy module) there are no timer events: connect only;
        # the caller steps the session with capture.LIVE.step(context)
        try:
            if capture.LIVE is None:
                capture.connect(active_armature(context), context.scene)
        except HumanAnimError as error:
            return _report_error(self, error)
        self.report({"INFO"}, f"capturing into '{capture.LIVE.obj_name}'")
        return {"FINISHED"}

    def invoke(self, context, event):
        result = self.execute(context)
        if "FINISHED" not in result or context.window is None:
            return result
        wm = context.window_manager
        self._timer = wm.event_timer_add(1.0 / context.scene.humananim_capture.display_rate, window=context.window)
        wm.modal_handler_add(self)
        capture.enable_overlay()
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        if capture.LIVE is None:  # disconnected from the panel
            return self._end(context, None)
        if event.type == "ESC":
            return self._end(context, capture.disconnect(context))
        if event.type == "TIMER":
            try:
                capture.LIVE.step(context)
            except HumanAnimError as error:
                self.report({"ERROR"}, str(error))
                return self._end(context, capture.disconnect(context))
            for area in getattr(context.screen, "areas", ()):
                if area.type in {"VIEW_3D", "PROPERTIES"}:
                    area.tag_redraw()
        return {"PASS_THROUGH"}

    def _end(self, context, action):
        capture.disable_overlay()
        if self._timer is not None:
            context.window_manager.event_timer_remove(self._timer)
            self._timer = None
        if action is not None:
            self.report({"INFO"}, f"recorded '{action.name}'")
        return {"FINISHED"}

    def cancel(self, context):
        capture.disconnect(context)  # closing the window: keep what was recorded
        self._end(context, None)


class HUMANANIM_OT_capture_disconnect(bpy.types.Operator):
    """End the capture session (a take being recorded becomes a new action)"""

    bl_idname = "humananim.capture_disconnect"
    bl_label = "Disconnect"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return capture.LIVE is not None

    def execute(self, context):
        action = capture.disconnect(context)
        self.report({"INFO"}, f"disconnected; recorded '{action.name}'" if action else "disconnected")
        return {"FINISHED"}


class HUMANANIM_OT_capture_record(bpy.types.Operator):
    """Start recording every sample into a take, or stop and turn the take into a new action"""

    bl_idname = "humananim.capture_record"
    bl_label = "Record"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return capture.LIVE is not None

    def execute(self, context):
        live = capture.LIVE
        try:
            if live.session.recording:
                action, take = live.stop_recording(context)
                self.report({"INFO"}, f"'{action.name}': {take.count()} samples" if action else "nothing recorded")
            else:
                live.start_recording(context.scene)
                self.report({"INFO"}, "recording")
        except HumanAnimError as error:
            return _report_error(self, error)
        return {"FINISHED"}


class HUMANANIM_OT_capture_calibrate(bpy.types.Operator):
    """The performer stands in the rig's rest pose: solve each sensor's offset to its bone"""

    bl_idname = "humananim.capture_calibrate"
    bl_label = "Calibrate"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return capture.LIVE is not None

    def execute(self, context):
        try:
            capture.LIVE.calibrate()
        except HumanAnimError as error:
            return _report_error(self, error)
        self.report({"INFO"}, f"calibrated {len(capture.LIVE.attach)} sensors")
        return {"FINISHED"}


class _GloveCalibration:
    bl_options = {"REGISTER", "UNDO"}
    pose = "FLAT"

    @classmethod
    def poll(cls, context):
        return capture.LIVE is not None and bool(capture.LIVE.gloves)

    def execute(self, context):
        try:
            done = capture.LIVE.calibrate_glove(self.pose)
        except HumanAnimError as error:
            return _report_error(self, error)
        self.report({"INFO"}, f"glove calibrated: {', '.join(done)}" if done else f"{self.pose.lower()} stored")
        return {"FINISHED"}


class HUMANANIM_OT_capture_glove_flat(_GloveCalibration, bpy.types.Operator):
    """Store the glove's flat hand (fingers straight and together): each sensor's zero"""

    bl_idname = "humananim.capture_glove_flat"
    bl_label = "Flat Hand"
    pose = "FLAT"


class HUMANANIM_OT_capture_glove_fist(_GloveCalibration, bpy.types.Operator):
    """Store the glove's fist: with the flat hand, each flexion sensor's gain"""

    bl_idname = "humananim.capture_glove_fist"
    bl_label = "Fist"
    pose = "FIST"


class HUMANANIM_OT_capture_save_take(bpy.types.Operator):
    """Save the last recorded take (every sample, with its time) as .json, to replay it later"""

    bl_idname = "humananim.capture_save_take"
    bl_label = "Save Take"

    filepath: bpy.props.StringProperty(subtype="FILE_PATH")

    @classmethod
    def poll(cls, context):
        return capture.LIVE is not None and bool(capture.LIVE.session.takes)

    def invoke(self, context, event):
        self.filepath = bpy.path.ensure_ext(capture.LIVE.session.takes[-1].name, ".json")
        context.window_manager.fileselect_add(self)
        return {"RUNNING_MODAL"}

    def execute(self, context):
        path = bpy.path.ensure_ext(bpy.path.abspath(self.filepath), ".json")
        try:
            capture.LIVE.session.takes[-1].save(path)
        except OSError as error:
            return _report_error(self, f"cannot write {path}: {error.strerror}")
        self.report({"INFO"}, f"saved {path}")
        return {"FINISHED"}


class HUMANANIM_OT_capture_add_device(bpy.types.Operator):
    """Add a capture device"""

    bl_idname = "humananim.capture_add_device"
    bl_label = "Add Device"
    bl_options = {"REGISTER", "UNDO"}

    kind: bpy.props.EnumProperty(name="Device", items=capture.DEVICE_KINDS)

    def invoke(self, context, event):
        return context.window_manager.invoke_props_dialog(self)

    def execute(self, context):
        capture.add_device(context.scene, self.kind)
        return {"FINISHED"}


class HUMANANIM_OT_capture_remove_device(RemoveActiveItem, bpy.types.Operator):
    """Remove the selected capture device"""

    bl_idname = "humananim.capture_remove_device"
    bl_label = "Remove Device"
    settings, items, index = "humananim_capture", "devices", "device_index"

    @classmethod
    def poll(cls, context):
        return capture.LIVE is None and super().poll(context)


CLASSES = (HUMANANIM_OT_capture_live, HUMANANIM_OT_capture_disconnect, HUMANANIM_OT_capture_record,
           HUMANANIM_OT_capture_calibrate, HUMANANIM_OT_capture_glove_flat, HUMANANIM_OT_capture_glove_fist,
           HUMANANIM_OT_capture_save_take, HUMANANIM_OT_capture_add_device,
           HUMANANIM_OT_capture_remove_device)
