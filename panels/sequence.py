"""The Sequence panel (3D view and Graph Editor sidebars, HumanAnim tab) and the Graph Editor's
Key menu entries: equalizer, blend, compression, time warp, squeeze/stretch, band energies."""

import bpy

from .rig import HumanAnimPanel

OPERATORS = (("humananim.equalize", "SEQ_HISTOGRAM"), ("humananim.multires_blend", "NLA"),
             ("humananim.compress_keys", "KEYFRAME"), ("humananim.time_warp", "TIME"),
             ("humananim.squeeze_stretch", "ARROW_LEFTRIGHT"))


def _has_action(context):
    obj = context.active_object
    return obj is not None and obj.animation_data is not None and obj.animation_data.action is not None


def draw_sequence(layout, context):
    if not _has_action(context):
        layout.label(text="No active action", icon="INFO")
        return
    col = layout.column(align=True)
    for idname, icon in OPERATORS:
        col.operator(idname, icon=icon)
    layout.operator("humananim.add_warp_marker", icon="MARKER_HLT")
    props = context.scene.humananim_sequence
    box = layout.box()
    row = box.row(align=True)
    row.prop(props, "levels")
    row.operator("humananim.analyse_bands", icon="GRAPH")
    if props.analysed:
        box.label(text=props.analysed)
        col = box.column(align=True)
        for band in props.bands:
            col.label(text=f"{band.label}: {band.energy:.3g} {props.units}".rstrip())


class VIEW3D_PT_humananim_sequence(HumanAnimPanel, bpy.types.Panel):
    bl_label = "Sequence"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        draw_sequence(self.layout, context)


class GRAPH_PT_humananim_sequence(bpy.types.Panel):
    bl_space_type = "GRAPH_EDITOR"
    bl_region_type = "UI"
    bl_category = "HumanAnim"
    bl_label = "Sequence"

    @classmethod
    def poll(cls, context):
        return context.active_object is not None

    def draw(self, context):
        draw_sequence(self.layout, context)


class GRAPH_MT_humananim_sequence(bpy.types.Menu):
    """Key > HumanAnim Sequence in the Graph Editor; registering it adds it to the Key menu."""

    bl_label = "HumanAnim Sequence"

    def draw(self, context):
        layout = self.layout
        for idname, icon in OPERATORS:
            layout.operator(idname, icon=icon)
        layout.separator()
        layout.operator("humananim.add_warp_marker", icon="MARKER_HLT")
        layout.operator("humananim.analyse_bands", icon="GRAPH")

    @classmethod
    def register(cls):
        bpy.types.GRAPH_MT_key.append(draw_key_menu)

    @classmethod
    def unregister(cls):
        bpy.types.GRAPH_MT_key.remove(draw_key_menu)


def draw_key_menu(self, context):
    self.layout.separator()
    self.layout.menu("GRAPH_MT_humananim_sequence")


CLASSES = (VIEW3D_PT_humananim_sequence, GRAPH_PT_humananim_sequence, GRAPH_MT_humananim_sequence)
