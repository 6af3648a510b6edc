"""Hands (Huang 1996 ch. 4): grasp, release, follow an object, hold another character, remove
self-collisions. Each writes a new action; the animator's keys are only read."""

import bpy

from ..humananim_addon.hands import job as hands
from .common import ArmatureJob, JobOperator, active_armature, with_qa


def _selected_object(context):
    obj = active_armature(context)
    others = [o for o in context.selected_objects if o is not obj and o.type == "MESH"]
    return others[0] if len(others) == 1 else None


class HUMANANIM_OT_grasp(JobOperator, bpy.types.Operator):
    """Reach for the selected object and close the fingers on it (the active armature's hand): a new
    action, and the object held by the hand (a keyed Child Of constraint)"""

    bl_idname = "humananim.grasp"
    bl_label = "Grasp Selected Object"
    measures_motion = True

    @classmethod
    def poll(cls, context):
        return active_armature(context) is not None and _selected_object(context) is not None

    def job(self, context):
        obj = active_armature(context)
        s = yield from hands.run_grasp(obj, context.scene, _selected_object(context))
        return with_qa(self, context, obj, s, f"'{s['action']}': {s['type'].lower()} grasp of '{s['object']}' ({s['primitive'].lower()}) "
                f"with {' and '.join(s['hands'])}, frames {s['frames'][0]}-{s['frames'][1]}, fingers touching: "
                + ", ".join(f"{k}: {' '.join(v)}" for k, v in s["fingers_touching"].items()))


class HUMANANIM_OT_release(bpy.types.Operator):
    """Let the selected object go at the current frame (its Child Of influence keyed to 0)"""

    bl_idname = "humananim.release"
    bl_label = "Release"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        obj = context.active_object
        return obj is not None and obj.constraints.get(hands.CONSTRAINT) is not None

    def execute(self, context):
        from ..solver.errors import HumanAnimError
        try:
            hands.set_release(context.active_object, context.scene.frame_current)
        except HumanAnimError as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        self.report({"INFO"}, f"released at frame {context.scene.frame_current}")
        return {"FINISHED"}


class HUMANANIM_OT_follow_object(JobOperator, bpy.types.Operator):
    """The arm follows the held object's own animation over the frame range (the object leads)"""

    bl_idname = "humananim.follow_object"
    bl_label = "Follow Object"
    measures_motion = True

    @classmethod
    def poll(cls, context):
        return active_armature(context) is not None and _selected_object(context) is not None

    def job(self, context):
        obj = active_armature(context)
        s = yield from hands.run_follow(obj, context.scene, _selected_object(context))
        return with_qa(self, context, obj, s, f"'{s['action']}': the hand keeps '{s['object']}' within {s['max_grip_error_mm']:.2f} mm and "
                f"{s['max_grip_error_deg']:.2f} deg over frames {s['frames'][0]}-{s['frames'][1]}")


class HUMANANIM_OT_hold(ArmatureJob, bpy.types.Operator):
    """Reach and hold another character's bone, then follow it as it moves"""

    bl_idname = "humananim.hold"
    bl_label = "Hold"
    run = staticmethod(hands.run_hold)

    @classmethod
    def poll(cls, context):
        return active_armature(context) is not None and context.scene.humananim_hands.other is not None

    @staticmethod
    def message(s):
        return (f"'{s['action']}': holds {s['held']} ({s['type'].lower()}), frames {s['frames'][0]}-"
                f"{s['frames'][1]}, grip kept within {s['max_grip_error_mm']:.2f} mm")


class HUMANANIM_OT_remove_self_collisions(ArmatureJob, bpy.types.Operator):
    """Keep the arms out of the trunk and head, and the legs out of each other, over the frame range (sensors
    at elbows, hands, knees and feet, corrected while hands and feet keep their goals)"""

    bl_idname = "humananim.remove_self_collisions"
    bl_label = "Remove Self-Collisions"
    run = staticmethod(hands.run_self_collisions)

    @staticmethod
    def message(s):
        return (f"'{s['action']}': {s['frames_corrected']} frames corrected ({s['leg_frames_corrected']} for "
                f"the legs), deepest {s['max_depth_before_mm']:.0f} mm -> {s['max_depth_after_mm']:.0f} mm")


CLASSES = (HUMANANIM_OT_grasp, HUMANANIM_OT_release, HUMANANIM_OT_follow_object, HUMANANIM_OT_hold,
           HUMANANIM_OT_remove_self_collisions)
