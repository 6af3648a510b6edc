"""The Simulation panel: closed-loop dynamics with loads and pushes."""

import bpy

from .rig import HumanAnimPanel


class HUMANANIM_UL_pushes(bpy.types.UIList):
    def draw_item(self, _context, layout, _data, item, _icon, _active, _prop):
        row = layout.row(align=True)
        row.label(text=f"{item.bone or '?'} @ {item.frame}", icon="FORCE_FORCE")
        row.prop(item, "magnitude", text="")


class VIEW3D_PT_humananim_simulation(HumanAnimPanel, bpy.types.Panel):
    bl_label = "Simulation"

    def draw(self, context):
        props = context.scene.humananim_simulation
        layout = self.layout
        col = layout.column()
        col.use_property_split = True
        col.prop(props, "action")
        row = col.row(align=True)
        row.prop(props, "frame_start")
        row.prop(props, "frame_end")
        col.prop(props, "controller")
        col.prop(props, "tracking")
        col.prop(props, "balance_assist")
        col.prop(props, "strength_scale")
        col.prop(props, "ground")
        if props.ground == "HEIGHT":
            col.prop(props, "ground_height")
        col.prop(props, "load_left")
        col.prop(props, "load_right")
        col.prop(context.scene, "gravity")
        layout.label(text="Pushes")
        row = layout.row()
        row.template_list("HUMANANIM_UL_pushes", "", props, "pushes", props, "push_index", rows=2)
        buttons = row.column(align=True)
        buttons.operator("humananim.add_push", icon="ADD", text="")
        buttons.operator("humananim.remove_push", icon="REMOVE", text="")
        if 0 <= props.push_index < len(props.pushes):
            item = props.pushes[props.push_index]
            sub = layout.column()
            sub.use_property_split = True
            sub.prop(item, "empty")
            sub.prop_search(item, "bone", context.active_object.data, "bones")
            sub.prop(item, "frame")
            sub.prop(item, "duration")
            sub.prop(item, "magnitude")
        layout.prop(context.scene.humananim, "output")
        layout.operator("humananim.simulate", icon="PHYSICS")


CLASSES = (HUMANANIM_UL_pushes, VIEW3D_PT_humananim_simulation)
