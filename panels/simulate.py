"""The Simulation panel: closed-loop dynamics with loads and pushes."""

import bpy

from .common import draw_force_list
from .rig import HumanAnimPanel


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
        draw_force_list(layout, context, props, "pushes", "push_index", "humananim.add_push",
                        "humananim.remove_push", "Pushes")
        layout.prop(context.scene.humananim, "output")
        layout.operator("humananim.simulate", icon="PHYSICS")


CLASSES = (VIEW3D_PT_humananim_simulation,)
