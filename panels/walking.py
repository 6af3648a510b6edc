"""The Walking panel: path, speed, style, ground; the generator stack of the armature."""

import bpy

from ..humananim_addon.walking import job as walking
from .rig import HumanAnimPanel


class VIEW3D_PT_humananim_walk(HumanAnimPanel, bpy.types.Panel):
    bl_label = "Walking"
    bl_options = {"DEFAULT_CLOSED"}

    @classmethod
    def poll(cls, context):
        return True

    def draw(self, context):
        props = context.scene.humananim_walk
        layout = self.layout
        col = layout.column()
        col.use_property_split = True
        col.prop(props, "armature")
        col.prop(props, "path_mode")
        col.prop(props, "path")
        if props.path_mode == "CURVE":
            col.prop(props, "speed_mode")
            if props.speed_mode == "CONSTANT":
                col.prop(props, "speed")
            elif props.speed_mode == "KEYED":
                col.prop(props, "speed_keys")
            else:
                col.prop(props, "segment_speeds")
            col.prop(props, "frame_start")
        col.prop(props, "ground")
        if props.ground is None:
            col.prop(props, "ground_height")
        col.separator()
        row = col.row(align=True)
        row.prop(props, "preset")
        row.operator("humananim.customise_walk_style", text="", icon="GREASEPENCIL")
        custom = col.column()
        custom.enabled = props.preset == "CUSTOM"  # a preset's own values show in the summary
        for name in walking.STYLE_FIELDS:
            custom.prop(props, name)
        layout.operator("humananim.walk", icon="MOD_DYNAMICPAINT")
        box = layout.box()
        box.label(text="Generator Stack", icon="NLA")
        sub = box.column()
        sub.use_property_split = True
        sub.prop(props, "gen_action")
        sub.prop(props, "gen_scope")
        sub.prop(props, "gen_priority")
        if props.gen_priority == "weighted":
            sub.prop(props, "gen_weight")
        sub.prop(props, "gen_start")
        row = box.row(align=True)
        row.operator("humananim.add_generator", icon="ADD")
        row.operator("humananim.clear_generators", icon="X", text="")
        obj = props.armature or context.active_object
        if obj is not None and obj.type == "ARMATURE":
            for item in walking.stack_summary(obj):
                box.label(text=f"{item['track'][len(walking.TRACK_PREFIX):]}: {item['frame_start']:g}-"
                               f"{item['frame_end']:g}, {item['bones']} bones"
                               + (f", {item['influence']:.2f}" if item["influence"] < 1 else ""))


CLASSES = (VIEW3D_PT_humananim_walk,)
