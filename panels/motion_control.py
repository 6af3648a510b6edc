"""The Dynamic Control panel: loads, impulses and collisions the motion reacts to."""

import bpy

from ..humananim_addon import overlay
from .rig import HumanAnimPanel


class HUMANANIM_UL_impulses(bpy.types.UIList):
    def draw_item(self, _context, layout, _data, item, _icon, _active, _prop):
        row = layout.row(align=True)
        row.label(text=f"{item.bone or '?'} @ {item.frame}", icon="FORCE_FORCE")
        row.prop(item, "magnitude", text="")


class VIEW3D_PT_humananim_control(HumanAnimPanel, bpy.types.Panel):
    bl_label = "Dynamic Control"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        props = context.scene.humananim_control
        layout = self.layout
        col = layout.column()
        col.use_property_split = True
        col.prop(props, "action")
        row = col.row(align=True)
        row.prop(props, "frame_start")
        row.prop(props, "frame_end")
        col.prop(props, "load_left")
        col.prop(props, "load_right")
        col.prop(props, "load_frame")
        col.prop(props, "strength_scale")
        col.prop(props, "substeps")
        col.prop(props, "tracking_only")
        col.prop(props, "ground")
        if props.ground == "HEIGHT":
            col.prop(props, "ground_height")
        col.prop(context.scene, "gravity")
        layout.label(text="Impulses and Forces")
        row = layout.row()
        row.template_list("HUMANANIM_UL_impulses", "", props, "impulses", props, "impulse_index", rows=2)
        buttons = row.column(align=True)
        buttons.operator("humananim.add_impulse", icon="ADD", text="")
        buttons.operator("humananim.remove_impulse", icon="REMOVE", text="")
        if 0 <= props.impulse_index < len(props.impulses):
            item = props.impulses[props.impulse_index]
            sub = layout.column()
            sub.use_property_split = True
            sub.prop(item, "empty")
            sub.prop_search(item, "bone", context.active_object.data, "bones")
            sub.prop(item, "frame")
            sub.prop(item, "duration")
            sub.prop(item, "magnitude", text="Impulse (N s)" if item.duration == 0.0 else "Force (N)")
        col = layout.column()
        col.use_property_split = True
        col.prop(props, "collider")
        if props.collider is not None:
            if props.collider.type == "ARMATURE":
                col.prop(props, "collider_radius")
            else:
                col.prop(props, "collider_spheres")
            col.prop(props, "collider_mass")
        layout.prop(context.scene.humananim, "output")
        layout.operator("humananim.dynamic_control", icon="CON_ARMATURE")
        layout.operator("humananim.toggle_overlay", icon="OVERLAY", depress=overlay.is_enabled(),
                        text="Hide Overlay" if overlay.is_enabled() else "Show Overlay")


CLASSES = (HUMANANIM_UL_impulses, VIEW3D_PT_humananim_control)
