"""The Simulation panel: closed-loop dynamics with loads and pushes."""

import bpy

from .common import draw_loads_and_pushes
from .rig import HumanAnimPanel


class VIEW3D_PT_humananim_simulation(HumanAnimPanel, bpy.types.Panel):
    bl_label = "Simulation"

    def draw(self, context):
        props = context.scene.humananim_simulation
        layout = self.layout
        draw_loads_and_pushes(layout, context, props, ("controller", "tracking", "balance_assist", "strength_scale"),
                              "pushes", "push_index", "push", "Pushes", after_ground=("load_left", "load_right"))
        layout.prop(context.scene.humananim, "output")
        layout.operator("humananim.simulate", icon="PHYSICS")


CLASSES = (VIEW3D_PT_humananim_simulation,)
