"""The Hands panel: grasp, release, follow, hold, self-collisions."""

import bpy

from .rig import HumanAnimPanel


class VIEW3D_PT_humananim_hands(HumanAnimPanel, bpy.types.Panel):
    bl_label = "Hands"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        props = context.scene.humananim_hands
        layout = self.layout
        col = layout.column()
        col.use_property_split = True
        col.prop(props, "side")
        col.prop(props, "grasp_type")
        col.prop(props, "pattern")
        col.prop(props, "duration")
        col.prop(props, "close_duration")
        col.prop(props, "start_frame")
        col.prop(props, "release_frame")
        col.prop(props, "with_spine")
        row = layout.row(align=True)
        row.operator("humananim.grasp", icon="VIEW_PAN")
        row.operator("humananim.release")
        col = layout.column()
        col.use_property_split = True
        row = col.row(align=True)
        row.prop(props, "frame_start")
        row.prop(props, "frame_end")
        layout.operator("humananim.follow_object")
        col = layout.column()
        col.use_property_split = True
        col.prop(props, "other")
        if props.other is not None and props.other.type == "ARMATURE":
            col.prop_search(props, "other_bone", props.other.data, "bones")
        layout.operator("humananim.hold")
        layout.operator("humananim.remove_self_collisions")


CLASSES = (VIEW3D_PT_humananim_hands,)
