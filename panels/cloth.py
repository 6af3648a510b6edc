"""The Cloth panel: garment, pins, body, material, smoothing, frame range; simulate."""

import bpy

from ..humananim_addon.cloth import job as cloth
from .rig import HumanAnimPanel


class VIEW3D_PT_humananim_cloth(HumanAnimPanel, bpy.types.Panel):
    bl_label = "Cloth"
    bl_options = {"DEFAULT_CLOSED"}

    @classmethod
    def poll(cls, context):
        return hasattr(context.scene, "humananim_cloth")

    def draw(self, context):
        props = context.scene.humananim_cloth
        layout = self.layout
        wm = context.window_manager
        if wm.humananim_progress >= 0.0:
            layout.progress(factor=wm.humananim_progress, type="BAR",
                            text=f"{wm.humananim_job}: {100 * wm.humananim_progress:.0f}% (Esc keeps frames done)")
        row = layout.row(align=True)
        row.operator("humananim.cloth_add_skirt", icon="MOD_CLOTH")
        row.operator("humananim.cloth_add_body", icon="MESH_CAPSULE")
        col = layout.column()
        col.use_property_split = True
        col.prop(props, "garment")
        if props.garment is not None and props.garment.type == "MESH":
            col.prop_search(props, "pin_group", props.garment, "vertex_groups")
        else:
            col.prop(props, "pin_group")
        col.prop(props, "armature")
        col.prop(props, "body")
        col.prop(props, "collider")
        col.separator()
        col.prop(props, "preset")
        sub = col.column(align=True)
        if props.preset == "CUSTOM":
            for name in cloth.PHYSICAL:
                sub.prop(props, name)
        else:
            values = cloth.material(props)
            sub.label(text=f"{values['density']:g} kg/m², stretch {values['stretch']:g} N/m, "
                           f"bend {values['bend']:g} N/m")
        col.prop(props, "wind")
        col.prop(props, "thickness")
        col.prop(props, "friction")
        col.prop(props, "compress_limit")
        col.separator()
        col.prop(props, "level")
        col.prop(props, "normal_control")
        col.prop(props, "edge_control")
        col.prop(props, "substeps")
        row = col.row(align=True)
        row.prop(props, "frame_start")
        row.prop(props, "frame_end")
        col.prop(props, "frame_step")
        col.prop(props, "keep_coarse")
        col.prop(props, "cache_dir")
        faces = len(props.garment.data.polygons) if props.garment is not None and props.garment.type == "MESH" else 0
        if faces:
            layout.label(text=f"about {faces * 4 * props.level ** 2} rendered faces (if all triangles)")
        row = layout.row(align=True)
        row.operator("humananim.cloth_preview", icon="HIDE_OFF")
        row.operator("humananim.cloth_simulate", icon="PLAY")


CLASSES = (VIEW3D_PT_humananim_cloth,)
