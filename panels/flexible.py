"""The Flexible Character panel: lattice modes, masses, ground, key-framing, pose graph, annealing."""

import bpy

from ..humananim_addon.flexible.job import MAX_ACTIVE
from ..operators.flexible import flexible_object
from .common import edited_list
from .rig import HumanAnimPanel


class HUMANANIM_UL_flexible_modes(bpy.types.UIList):
    def draw_item(self, _context, layout, _data, item, _icon, _active, _prop):
        row = layout.row(align=True)
        row.prop(item, "use", text="")
        row.label(text=item.key, icon="SHAPEKEY_DATA")
        row.prop(item, "active", text="Active", toggle=True)


class HUMANANIM_UL_flexible_poses(bpy.types.UIList):
    def draw_item(self, context, layout, _data, item, _icon, _active, _prop, index=0):
        obj = flexible_object(context)
        active = [m for m in obj.humananim_flexible.modes if m.use and m.active] if obj else []
        row = layout.row(align=True)
        row.prop(item, "duration", text="")
        for i, _mode in enumerate(active[:MAX_ACTIVE]):
            row.prop(item, "values", index=i, text="")


class HUMANANIM_UL_flexible_springs(bpy.types.UIList):
    def draw_item(self, _context, layout, _data, item, _icon, _active, _prop):
        row = layout.row(align=True)
        row.label(text=item.target.name if item.target else "?", icon="FORCE_HARMONIC")
        row.prop(item, "stiffness", text="")


class VIEW3D_PT_humananim_flexible(HumanAnimPanel, bpy.types.Panel):
    bl_label = "Flexible Character"
    bl_options = {"DEFAULT_CLOSED"}

    @classmethod
    def poll(cls, context):
        return True  # the demo button is useful with nothing selected

    def draw(self, context):
        layout = self.layout
        wm = context.window_manager
        if getattr(wm, "humananim_progress", -1.0) >= 0.0:
            layout.progress(factor=wm.humananim_progress, type="BAR",
                            text=f"{wm.humananim_job}: {100 * wm.humananim_progress:.0f}% (Esc cancels)")
        layout.operator("humananim.flexible_demo_table", icon="MOD_LATTICE")
        obj = flexible_object(context)
        if obj is None:
            layout.label(text="Select an object with a Lattice modifier")
            return
        props = obj.humananim_flexible
        col = layout.column()
        col.use_property_split = True
        col.prop(props, "lattice")
        row = layout.row()
        row.label(text="Deformation Modes (lattice shape keys)")
        row.operator("humananim.flexible_sync_modes", icon="FILE_REFRESH", text="")
        layout.template_list("HUMANANIM_UL_flexible_modes", "", props, "modes", props, "mode_index", rows=3)
        if 0 <= props.mode_index < len(props.modes):
            mode = props.modes[props.mode_index]
            sub = layout.column(align=True)
            sub.use_property_split = True
            sub.prop(mode, "stiffness", text="Stiffness (Hz)")
            sub.prop(mode, "damping", text="Damping Ratio")
        box = layout.box()
        box.use_property_split = True
        box.label(text="Masses and Ground")
        box.prop(props, "points")
        if props.points == "SAMPLES":
            box.prop(props, "sample_count")
        box.prop(props, "density")
        box.prop(props, "mass")
        box.prop(props, "ground_height")
        box.prop(props, "ground_slope")
        box.prop(props, "ground_heading")
        box.prop(props, "friction")
        box.prop(props, "ground_stiffness")
        box.prop(props, "ground_damping")
        box.prop(props, "friction_damping")
        box.label(text="Springs")
        _, sp = edited_list(box, "HUMANANIM_UL_flexible_springs", props, "springs", "spring_index",
                            "humananim.flexible_spring_add", "humananim.flexible_spring_remove")
        if sp is not None:
            for name in ("target", "point", "stiffness", "damping", "rest_length"):
                box.prop(sp, name)
        box = layout.box()
        box.use_property_split = True
        box.label(text="Simulation")
        row = box.row(align=True)
        row.prop(props, "frame_start")
        row.prop(props, "frame_end")
        box.prop(props, "handover_frame")
        box.prop(props, "use_hold")
        if props.use_hold:
            box.prop(props, "hold_point")
        box.prop(props, "integrator")
        box.prop(props, "substeps")
        box = layout.box()
        box.use_property_split = True
        box.prop(props, "use_control")
        if props.use_control:
            box.prop(props, "controller")
            box.prop(props, "control_frequency")
            box.prop(props, "control_damping")
            box.label(text="Pose Graph (cyclic): duration, active amplitudes")
            edited_list(box, "HUMANANIM_UL_flexible_poses", props, "poses", "pose_index",
                        "humananim.flexible_pose_add", "humananim.flexible_pose_remove", rows=3)
        layout.operator("humananim.flexible_simulate", icon="PLAY")
        box = layout.box()
        box.use_property_split = True
        box.label(text="Motion Synthesis (simulated annealing)")
        box.prop(props, "optimize")
        box.prop(props, "cost")
        box.prop(props, "direction")
        if props.cost == "custom":
            for name in ("w_energy", "w_distance", "w_speed", "w_tilt"):
                box.prop(props, name)
        elif props.cost in ("energy_speed", "energy_sqrt_distance"):
            box.prop(props, "cost_scale")
        box.prop(props, "trials")
        box.prop(props, "trial_seconds")
        box.prop(props, "trial_step")
        box.prop(props, "start_temperature")
        box.prop(props, "frozen_temperature")
        box.prop(props, "seed")
        box.operator("humananim.flexible_optimize", icon="SORTTIME")
        if len(props.best_poses):
            box.label(text=f"Best: cost {props.best_cost:.4g}, {props.best_distance:.2f} m, "
                           f"{props.best_energy:.0f} J", icon="CHECKMARK")


CLASSES = (HUMANANIM_UL_flexible_modes, HUMANANIM_UL_flexible_poses, HUMANANIM_UL_flexible_springs,
           VIEW3D_PT_humananim_flexible)
