"""The Live Capture panel: devices, connection and status per device, calibration, recording."""

import bpy

from ..humananim_addon.capture import job as capture
from .common import edited_list
from .rig import HumanAnimPanel

STATUS_ICONS = {"connected": "CHECKMARK", "resyncing": "FILE_REFRESH", "disconnected": "ERROR",
                "connecting": "TIME", "stopped": "PAUSE"}


class HUMANANIM_UL_capture_devices(bpy.types.UIList):
    def draw_item(self, _context, layout, _data, item, _icon, _active, _prop):
        row = layout.row(align=True)
        row.prop(item, "use", text="")
        row.prop(item, "name", text="", emboss=False)
        row.label(text=item.kind.replace("_", " ").title() + (" (simulated)" if item.simulate else ""))


class VIEW3D_PT_humananim_capture(HumanAnimPanel, bpy.types.Panel):
    bl_label = "Live Capture"
    bl_options = {"DEFAULT_CLOSED"}

    @classmethod
    def poll(cls, context):
        return HumanAnimPanel.poll(context) or capture.LIVE is not None

    def draw(self, context):
        s = context.scene.humananim_capture
        layout = self.layout
        live = capture.LIVE
        _, device = edited_list(layout, "HUMANANIM_UL_capture_devices", s, "devices", "device_index",
                                "humananim.capture_add_device", "humananim.capture_remove_device")
        if device is not None:
            draw_device(layout, device, live is None)
        col = layout.column()
        col.use_property_split = True
        col.prop(s, "display_rate")
        col.prop(s, "gestures")
        col.prop(s, "grasp_collection")
        col.prop(s, "take_name")
        col.prop(s, "quaternion_bones")
        col.prop(s, "reduce_keys")
        if s.reduce_keys:
            col.prop(s, "reduce_degrees")
        if live is None:
            layout.operator("humananim.capture_live", text="Connect", icon="PLAY")
            return
        layout.operator("humananim.capture_disconnect", text="Disconnect", icon="CANCEL")
        box = layout.box()
        for d in live.status():
            draw_status(box, d)
        row = layout.row(align=True)
        row.operator("humananim.capture_calibrate", icon="ARMATURE_DATA")
        row.operator("humananim.capture_glove_flat")
        row.operator("humananim.capture_glove_fist")
        recording = live.session.recording
        layout.operator("humananim.capture_record", text="Stop Recording" if recording else "Record",
                        icon="PAUSE" if recording else "REC", depress=recording)
        layout.operator("humananim.capture_save_take", icon="FILE_TICK")
        for side, ga in live.grasp.items():
            layout.label(text=f"{side} hand: {ga.state.replace('_', ' ').lower()}", icon="VIEW_PAN")



def status_lines(d):
    """What the panel says about one device: state, rate, then the counters kept apart (records
    lost, bytes discarded, resyncs) beside the device's last error."""
    lines = [f"{d['rate_hz']:.0f} Hz, {d['samples']} samples, {d['reconnects']} reconnects",
             f"lost {d['dropped']} records, discarded {d['discarded_bytes']} bytes, {d['resyncs']} resyncs"]
    return lines + ([f"last error: {d['last_error']}"] if d["last_error"] else [])


def draw_status(box, d):
    r = box.row()
    r.label(text=d["name"], icon=STATUS_ICONS.get(d["status"], "QUESTION"))
    r.label(text=d["status"])
    for k, line in enumerate(status_lines(d)):
        box.label(text=line, icon="ERROR" if line.startswith("last error") else "NONE")


def draw_device(layout, item, editable):
    col = layout.column()
    col.use_property_split = True
    col.enabled = editable
    col.prop(item, "kind")
    if item.kind in {"FLOCK", "CYBERGLOVE", "MVN"}:
        col.prop(item, "simulate")
    if item.kind in {"FLOCK", "CYBERGLOVE"}:
        if not item.simulate:
            col.prop(item, "port")
            col.prop(item, "baud")
        col.prop(item, "mode")
        col.prop(item, "rate")
    if item.kind == "FLOCK":
        col.prop(item, "birds")
        col.prop(item, "bones")
        col.prop(item, "record")
        col.prop(item, "hemisphere")
        col.prop(item, "standalone")
        if item.simulate:
            col.prop(item, "extended_range")
    elif item.kind == "CYBERGLOVE":
        col.prop(item, "sensors")
        col.prop(item, "hand")
        col.prop(item, "time_stamp")
        col.prop(item, "status_byte")
    elif item.kind == "HID_GLOVE":
        col.prop(item, "decoder")
        col.prop(item, "hand")
    elif item.kind == "MVN":
        col.prop(item, "host")
        col.prop(item, "mvn_port")
        col.prop(item, "actor")
        if item.simulate:
            col.prop(item, "rate")
    elif item.kind == "VMC":
        col.prop(item, "host")
        col.prop(item, "vmc_port")
    elif item.kind == "REPLAY":
        col.prop(item, "filepath")
        col.prop(item, "rate")


CLASSES = (HUMANANIM_UL_capture_devices, VIEW3D_PT_humananim_capture)
