"""The Rig panel: body roles, mass model, baking."""

import bpy

from ..humananim_addon.properties import role_key
from ..solver.body_roles import CENTRE_CHAINS, CENTRE_ROLES, FINGERS, SIDED_ROLES, SIDES, sided


class HumanAnimPanel:
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "HumanAnim"

    @classmethod
    def poll(cls, context):
        return context.active_object is not None and context.active_object.type == "ARMATURE"


class VIEW3D_PT_humananim_rig(HumanAnimPanel, bpy.types.Panel):
    bl_label = "Rig"

    def draw(self, context):
        settings = context.active_object.data.humananim
        layout = self.layout
        wm = context.window_manager
        if wm.humananim_progress >= 0.0:
            layout.progress(factor=wm.humananim_progress, type="BAR",
                            text=f"{wm.humananim_job}: {100 * wm.humananim_progress:.0f}% (Esc cancels)")
        layout.operator("humananim.detect_roles", icon="ARMATURE_DATA")
        if settings.detected_convention:
            layout.label(text=f"Convention: {settings.detected_convention}")
        if settings.missing_roles:
            layout.label(text=f"Missing: {settings.missing_roles}", icon="ERROR")


class VIEW3D_PT_humananim_roles(HumanAnimPanel, bpy.types.Panel):
    bl_label = "Body Roles"
    bl_parent_id = "VIEW3D_PT_humananim_rig"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        obj = context.active_object
        settings = obj.data.humananim
        detected = {item.role: item.bones for item in settings.detected_roles}
        col = self.layout.column(align=True)
        col.use_property_split = True
        for role in CENTRE_ROLES + CENTRE_CHAINS:
            role_row(col, obj, settings, role, detected)
        for side in SIDES:
            col.separator()
            for role in SIDED_ROLES + FINGERS:
                role_row(col, obj, settings, sided(role, side), detected)


def role_row(col, obj, settings, role, detected):
    row = col.row(align=True)
    key = role_key(role)
    if role.split(".")[0] in CENTRE_CHAINS + FINGERS:
        row.prop(settings.roles, key, text=role)
    else:
        row.prop_search(settings.roles, key, obj.data, "bones", text=role)
    if not getattr(settings.roles, key):
        row.label(text=detected.get(role, "-"))


class HUMANANIM_UL_segments(bpy.types.UIList):
    def draw_item(self, _context, layout, _data, item, _icon, _active, _prop):
        row = layout.row(align=True)
        row.label(text=item.bone)
        row.prop(item, "mass", text="")


class VIEW3D_PT_humananim_mass(HumanAnimPanel, bpy.types.Panel):
    bl_label = "Mass Model"
    bl_parent_id = "VIEW3D_PT_humananim_rig"

    def draw(self, context):
        settings = context.active_object.data.humananim
        layout = self.layout
        col = layout.column()
        col.use_property_split = True
        col.prop(settings, "mass_source")
        if settings.mass_source != "ANTHROPOMETRIC":
            col.prop(settings, "density")
        if settings.mass_source != "MESH":
            col.prop(settings, "total_mass")
            col.prop(settings, "body_type")
        layout.operator("humananim.compute_mass_model", icon="PHYSICS")
        if len(settings.segments):
            total = sum(s.mass for s in settings.segments)
            layout.label(text=f"{len(settings.segments)} segments, {total:.1f} kg")
            layout.template_list("HUMANANIM_UL_segments", "", settings, "segments", settings, "segment_index",
                                 rows=4)
            if 0 <= settings.segment_index < len(settings.segments):
                item = settings.segments[settings.segment_index]
                col = layout.column()
                col.prop(item, "com")
                col.prop(item, "inertia")


class VIEW3D_PT_humananim_bake(HumanAnimPanel, bpy.types.Panel):
    bl_label = "Bake"
    bl_parent_id = "VIEW3D_PT_humananim_rig"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        settings = context.scene.humananim
        col = self.layout.column()
        col.use_property_split = True
        col.prop(settings, "output")
        col.prop(settings, "exact")
        self.layout.operator("humananim.bake_action", icon="ACTION")


CLASSES = (VIEW3D_PT_humananim_rig, VIEW3D_PT_humananim_roles, HUMANANIM_UL_segments,
           VIEW3D_PT_humananim_mass, VIEW3D_PT_humananim_bake)
