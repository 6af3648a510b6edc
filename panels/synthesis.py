"""The Motion Queue panel: actions with a transition mode each and their accept/reject status,
per-limb constraint markers, reactions, and the bake."""

import bpy

from .common import edited_list
from .rig import HumanAnimPanel


class HUMANANIM_UL_motion_queue(bpy.types.UIList):
    def draw_item(self, _context, layout, _data, item, _icon, _active, _prop):
        row = layout.row(align=True)
        row.prop(item, "action", text="", emboss=False, icon="ACTION")
        row.prop(item, "mode", text="")
        if item.status:
            row.label(text="", icon="CHECKMARK" if item.accepted else "ERROR")


class VIEW3D_PT_humananim_synthesis(HumanAnimPanel, bpy.types.Panel):
    bl_label = "Motion Queue"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        props = context.scene.humananim_synthesis
        layout = self.layout
        buttons, _ = edited_list(layout, "HUMANANIM_UL_motion_queue", props, "entries", "entry_index",
                                 "humananim.queue_add", "humananim.queue_remove", rows=3)
        for icon, step in (("TRIA_UP", -1), ("TRIA_DOWN", 1)):
            op = buttons.operator("humananim.queue_move", icon=icon, text="")
            if op is not None:  # None in a layout that only records the calls
                op.direction = step
        layout.operator("humananim.queue_from_nla", icon="NLA")
        if 0 <= props.entry_index < len(props.entries):
            e = props.entries[props.entry_index]
            col = layout.column()
            col.use_property_split = True
            col.prop(e, "action")
            r = col.row(align=True)
            r.prop(e, "frame_start")
            r.prop(e, "frame_end")
            col.prop(e, "mode")
            col.prop(e, "initial_duration")
            col.prop(e, "terminal_duration")
            col.prop(e, "interrupt")
            if e.interrupt:
                col.prop(e, "interrupt_frame")
            if e.status:
                layout.label(text=e.status, icon="CHECKMARK" if e.accepted else "ERROR")
            box = layout.box()
            box.label(text="Limb Constraints (pose markers)")
            r = box.row(align=True)
            r.prop(props, "marker_limb", text="")
            r.prop(props, "marker_constraint", text="")
            r.operator("humananim.mark_constraint", text="", icon="MARKER_HLT")
            if e.action is not None:
                for m in sorted(e.action.pose_markers, key=lambda m: m.frame):
                    if "=" in m.name:
                        box.label(text=f"{m.frame}: {m.name}")
        col = layout.column()
        col.use_property_split = True
        col.prop(props, "reactions")
        from ..humananim_addon.synthesis.job import environment_set
        if props.reactions or environment_set(context.scene.humananim_control):
            col.label(text="Loads, pushes and collider: Dynamic Control panel")
            col.prop(props, "step_speed_min")
            col.prop(props, "step_speed_max")
            col.prop(props, "step_acceleration")
            col.prop(props, "k_root")
            col.prop(props, "k_foot")
            col.prop(props, "recovery_time")
            col.prop(props, "fall_back")
            col.prop(props, "fall_forward")
        layout.operator("humananim.synthesize", icon="PLAY")
        if props.last_summary:
            layout.label(text=props.last_summary)


CLASSES = (HUMANANIM_UL_motion_queue, VIEW3D_PT_humananim_synthesis)
