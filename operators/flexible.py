"""Flexible characters (issue 8): simulate and bake, optimise the pose graph, edit it, make a demo."""

import bpy

from ..humananim_addon.flexible import job as flexible
from ..solver.flexible import FlexibleError
from .common import JobOperator, RemoveActiveItem, run_reporting


def flexible_object(context):
    """The active object when it can be a flexible character: a mesh with a Lattice modifier,
    a lattice, or any object whose lattice is set."""
    obj = context.active_object
    if obj is None or not hasattr(obj, "humananim_flexible"):
        return None
    if obj.type == "LATTICE" or obj.humananim_flexible.lattice is not None:
        return obj
    if any(m.type == "LATTICE" and m.object is not None for m in getattr(obj, "modifiers", ())):
        return obj
    return None


class HUMANANIM_OT_flexible_simulate(JobOperator, bpy.types.Operator):
    """Key-frame the lattice's shape keys up to the hand-over frame, simulate the flexible character after it, and bake new actions (lattice transform and shape-key values)"""

    bl_idname = "humananim.flexible_simulate"
    bl_label = "Simulate and Bake"

    @classmethod
    def poll(cls, context):
        return flexible_object(context) is not None

    def job(self, context):
        s = yield from flexible.run(flexible_object(context), context.scene)
        text = (f"'{s['lattice_action']}' and '{s.get('key_action', '-')}': {s['frames']} frames, "
                f"{s['points']} points, {len(s['modes'])} modes in {s['seconds']:.1f} s")
        if s["warnings"]:
            text += "; " + "; ".join(s["warnings"])
        return text


class HUMANANIM_OT_flexible_optimize(JobOperator, bpy.types.Operator):
    """Search the pose graph's poses and/or durations by simulated annealing for the cheapest motion (thesis ch. 5); the best controller is stored on the object"""

    bl_idname = "humananim.flexible_optimize"
    bl_label = "Optimise Controller"

    @classmethod
    def poll(cls, context):
        return flexible_object(context) is not None

    def job(self, context):
        s = yield from flexible.optimize(flexible_object(context), context.scene)
        return (f"best of {s['trials']} trials: cost {s['best_cost']:.4g} (from {s['initial_cost']:.4g}), "
                f"{s['distance_m']:.2f} m forward, {s['energy_j']:.0f} J; stored as Best Found")


class HUMANANIM_OT_flexible_sync_modes(bpy.types.Operator):
    """List the lattice's shape keys as deformation modes (keeps the settings of listed ones)"""

    bl_idname = "humananim.flexible_sync_modes"
    bl_label = "Read Shape Keys"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return flexible_object(context) is not None

    def execute(self, context):
        def work():
            names = flexible.sync_modes(flexible_object(context))
            return f"{len(names)} modes: {', '.join(names) or 'none'}"
        return run_reporting(self, work)


class HUMANANIM_OT_flexible_pose_add(bpy.types.Operator):
    """Add a pose to the cyclic pose graph (a copy of the last one)"""

    bl_idname = "humananim.flexible_pose_add"
    bl_label = "Add Pose"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return flexible_object(context) is not None

    def execute(self, context):
        flexible.add_pose(flexible_object(context))
        return {"FINISHED"}


class _RemoveFlexibleItem(RemoveActiveItem):
    @classmethod
    def settings_of(cls, context):
        obj = flexible_object(context)
        return None if obj is None else obj.humananim_flexible


class HUMANANIM_OT_flexible_pose_remove(_RemoveFlexibleItem, bpy.types.Operator):
    """Remove the selected pose from the pose graph"""

    bl_idname = "humananim.flexible_pose_remove"
    bl_label = "Remove Pose"
    items, index = "poses", "pose_index"


class HUMANANIM_OT_flexible_spring_add(bpy.types.Operator):
    """Add a spring from the character to another object (the other selected object, if any)"""

    bl_idname = "humananim.flexible_spring_add"
    bl_label = "Add Spring"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return flexible_object(context) is not None

    def execute(self, context):
        obj = flexible_object(context)
        others = [o for o in context.selected_objects if o != obj and o != obj.humananim_flexible.lattice]
        flexible.add_spring(obj, others[0] if others else None)
        return {"FINISHED"}


class HUMANANIM_OT_flexible_spring_remove(_RemoveFlexibleItem, bpy.types.Operator):
    """Remove the selected spring"""

    bl_idname = "humananim.flexible_spring_remove"
    bl_label = "Remove Spring"
    items, index = "springs", "spring_index"


class HUMANANIM_OT_flexible_demo_table(bpy.types.Operator):
    """Add the thesis's table: a mesh in a 4x2x4 lattice with shear, bend, squash and stretch shape keys, set up to hop"""

    bl_idname = "humananim.flexible_demo_table"
    bl_label = "Add Flexible Table"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        def work():
            obj, lat = flexible.create_demo_table(context, tuple(context.scene.cursor.location))
            return f"added '{obj.name}' in lattice '{lat.name}'"
        return run_reporting(self, work)


CLASSES = (HUMANANIM_OT_flexible_simulate, HUMANANIM_OT_flexible_optimize, HUMANANIM_OT_flexible_sync_modes,
           HUMANANIM_OT_flexible_pose_add, HUMANANIM_OT_flexible_pose_remove, HUMANANIM_OT_flexible_spring_add,
           HUMANANIM_OT_flexible_spring_remove, HUMANANIM_OT_flexible_demo_table)

_ = FlexibleError  # raised by the bridge, reported by JobOperator/run_reporting
