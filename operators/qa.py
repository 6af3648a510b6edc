"""The motion QA panel's operators: jump to the frame a measure names."""

import bpy
from bpy.props import IntProperty


class HUMANANIM_OT_qa_jump(bpy.types.Operator):
    """Go to the frame where the motion QA found this measure's worst value"""

    bl_idname = "humananim.qa_jump"
    bl_label = "Go to Frame"
    bl_options = {"REGISTER"}

    frame: IntProperty(name="Frame", default=1)

    def execute(self, context):
        context.scene.frame_set(self.frame)
        return {"FINISHED"}


CLASSES = (HUMANANIM_OT_qa_jump,)
