"""Procedural walking: walk a rig along a path, add generator strips to its stack."""

import bpy

from ..humananim_addon.walking import job as walking
from .common import JobOperator, active_armature, run_reporting, with_qa


class HUMANANIM_OT_walk(JobOperator, bpy.types.Operator):
    """Walk the armature along the path (Boulic's walking model) and write the walk as a new action on an NLA strip"""

    bl_idname = "humananim.walk"
    bl_label = "Walk Along Path"
    measures_motion = True

    @classmethod
    def poll(cls, context):
        props = context.scene.humananim_walk
        return (props.armature or active_armature(context)) is not None and props.path is not None

    def job(self, context):
        obj = walking.walk_armature(context.scene.humananim_walk, active_armature(context))
        s = yield from walking.run(obj, context.scene)
        return with_qa(self, context, obj, s, f"'{s['action']}': {s['steps']} steps, {s['walk_seconds']:.1f} s of walk (frames "
                f"{s['frame_range'][0]:g}-{s['frame_range'][1]:g}) in {s['generate_seconds']:.2f} s; feet slide "
                f"{s['max_foot_slip_mm']:.2f} mm at most, root within {s['max_root_deviation_cm']:.1f} cm of the path")


class HUMANANIM_OT_customise_walk_style(bpy.types.Operator):
    """Copy the chosen style preset into the custom style values, to edit them"""

    bl_idname = "humananim.customise_walk_style"
    bl_label = "Customise Style"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return context.scene.humananim_walk.preset != "CUSTOM"

    def execute(self, context):
        props = context.scene.humananim_walk
        walking.apply_preset(props, props.preset)
        return {"FINISHED"}


class HUMANANIM_OT_add_generator(bpy.types.Operator):
    """Add a generator strip on the armature's stack: the chosen action on a scope (its bones only), with a priority"""

    bl_idname = "humananim.add_generator"
    bl_label = "Add Generator Strip"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        props = context.scene.humananim_walk
        return (props.armature or active_armature(context)) is not None and props.gen_action is not None

    def execute(self, context):
        props = context.scene.humananim_walk

        def work():
            obj = walking.walk_armature(props, active_armature(context))
            action = walking.add_generator(obj, context.scene, props.gen_action, props.gen_scope, props.gen_start,
                                           props.gen_priority, props.gen_weight)
            return f"'{action.name}' on the {props.gen_scope} scope ({props.gen_priority}); stack rescheduled"
        return run_reporting(self, work)


class HUMANANIM_OT_clear_generators(bpy.types.Operator):
    """Remove the armature's generator strips (their actions stay in the file)"""

    bl_idname = "humananim.clear_generators"
    bl_label = "Clear Generator Stack"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return (context.scene.humananim_walk.armature or active_armature(context)) is not None

    def execute(self, context):
        def work():
            obj = walking.walk_armature(context.scene.humananim_walk, active_armature(context))
            n = walking.clear_stack(obj)
            return f"removed {n} generator strips from '{obj.name}'"
        return run_reporting(self, work)


CLASSES = (HUMANANIM_OT_walk, HUMANANIM_OT_customise_walk_style, HUMANANIM_OT_add_generator, HUMANANIM_OT_clear_generators)
