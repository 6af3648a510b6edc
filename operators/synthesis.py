"""Motion synthesis: the Motion Queue's operators (add, remove, move, queue the NLA strips, mark a
limb's constraint) and the bake into a new action."""

import bpy
from bpy.props import IntProperty

from ..humananim_addon.synthesis import job as synthesis
from ..solver.errors import MotionError
from .common import ArmatureJob, RemoveActiveItem, active_armature, run_reporting


class HUMANANIM_OT_synthesize(ArmatureJob, bpy.types.Operator):
    """Join the Motion Queue's actions (blend, connect or inertialize), optionally under dynamic control with protective steps, falls and recovery, into a new action"""

    bl_idname = "humananim.synthesize"
    bl_label = "Synthesize Motion"
    run = staticmethod(synthesis.run)

    @staticmethod
    def message(s):
        msg = synthesis.text_line(s)
        rejected = [r for r in s["requests"] if not r["accepted"]]
        if rejected:
            msg += "; " + "; ".join(r["reason"] for r in rejected)
        return msg


class HUMANANIM_OT_queue_add(bpy.types.Operator):
    """Add the active action (or the first action) to the Motion Queue"""

    bl_idname = "humananim.queue_add"
    bl_label = "Add to Motion Queue"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        def work():
            obj = active_armature(context)
            act = obj.animation_data.action if obj is not None and obj.animation_data else None
            act = act or next(iter(bpy.data.actions), None)
            if act is None:
                raise MotionError("there is no action to queue")
            synthesis.add_entry(context.scene, act)
            return None
        return run_reporting(self, work)


class HUMANANIM_OT_queue_remove(RemoveActiveItem, bpy.types.Operator):
    """Remove the selected entry from the Motion Queue"""

    bl_idname = "humananim.queue_remove"
    bl_label = "Remove from Motion Queue"
    settings, items, index = "humananim_synthesis", "entries", "entry_index"


class HUMANANIM_OT_queue_move(bpy.types.Operator):
    """Move the selected entry up or down the Motion Queue"""

    bl_idname = "humananim.queue_move"
    bl_label = "Move in Motion Queue"
    bl_options = {"REGISTER", "UNDO"}
    direction: IntProperty(default=-1)

    def execute(self, context):
        props = context.scene.humananim_synthesis
        i, j = props.entry_index, props.entry_index + self.direction
        if 0 <= i < len(props.entries) and 0 <= j < len(props.entries):
            props.entries.move(i, j)
            props.entry_index = j
        return {"FINISHED"}


class HUMANANIM_OT_queue_from_nla(bpy.types.Operator):
    """Fill the Motion Queue with the active armature's NLA strips, in playing order"""

    bl_idname = "humananim.queue_from_nla"
    bl_label = "Queue NLA Strips"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return active_armature(context) is not None

    def execute(self, context):
        return run_reporting(self, lambda: f"queued {synthesis.entries_from_nla(active_armature(context), context.scene)} strips")


class HUMANANIM_OT_mark_constraint(bpy.types.Operator):
    """Mark the chosen limb's constraint from the current frame on, as a pose marker on the selected entry's action"""

    bl_idname = "humananim.mark_constraint"
    bl_label = "Mark Limb Constraint"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        def work():
            props = context.scene.humananim_synthesis
            if not 0 <= props.entry_index < len(props.entries) or props.entries[props.entry_index].action is None:
                raise MotionError("select a Motion Queue entry with an action")
            act = props.entries[props.entry_index].action
            synthesis.add_marker(act, context.scene.frame_current, props.marker_limb, props.marker_constraint)
            return f"'{act.name}': {props.marker_limb} {props.marker_constraint} from frame {context.scene.frame_current}"
        return run_reporting(self, work)


CLASSES = (HUMANANIM_OT_synthesize, HUMANANIM_OT_queue_add, HUMANANIM_OT_queue_remove, HUMANANIM_OT_queue_move,
           HUMANANIM_OT_queue_from_nla, HUMANANIM_OT_mark_constraint)
