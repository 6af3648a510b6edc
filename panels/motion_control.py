"""The Dynamic Control panel: loads, impulses and collisions the motion reacts to."""

import bpy

from ..humananim_addon.motion_control import overlay
from .common import draw_force_list
from .rig import HumanAnimPanel


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
        draw_force_list(layout, context, props, "impulses", "impulse_index", "humananim.add_impulse",
                        "humananim.remove_impulse", "Impulses and Forces")
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


CLASSES = (VIEW3D_PT_humananim_control,)
