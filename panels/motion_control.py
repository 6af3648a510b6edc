"""The Dynamic Control panel: loads, impulses and collisions the motion reacts to."""

import bpy

from ..humananim_addon.motion_control import overlay
from .common import draw_loads_and_pushes
from .rig import HumanAnimPanel


class VIEW3D_PT_humananim_control(HumanAnimPanel, bpy.types.Panel):
    bl_label = "Dynamic Control"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        props = context.scene.humananim_control
        layout = self.layout
        draw_loads_and_pushes(layout, context, props, ("load_left", "load_right", "load_frame", "strength_scale",
                                                       "substeps", "tracking_only"),
                              "impulses", "impulse_index", "impulse", "Impulses and Forces")
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
