"""Retarget Motion (issue 25): another armature's motion put on the active armature's controls in a
NEW action; the work lives in humananim_addon.retarget.job."""

import bpy
from bpy.props import EnumProperty, IntProperty, StringProperty

from ..humananim_addon.retarget import job
from ..solver.errors import RigError
from .common import Message, active_armature, run_reporting, with_qa


def _armatures(self, context, text):
    active = context.active_object
    return [o.name for o in bpy.data.objects
            if o.type == "ARMATURE" and o != active and text.lower() in o.name.lower()]


class HUMANANIM_OT_retarget_motion(bpy.types.Operator):
    """Put the source armature's motion on the active armature (its controls on a control rig) in a new action: rotations per body role relative to each rig's rest pose, root motion scaled by leg length, feet planted on the ground where the source's are"""

    bl_idname = "humananim.retarget_motion"
    bl_label = "Retarget Motion"
    bl_options = {"REGISTER", "UNDO"}
    measures_motion = True

    source: StringProperty(name="Source", default="", description="The armature whose active action is retargeted",
                           search=_armatures)
    frame_start: IntProperty(name="Start", default=0, min=0, description="First source frame (0: the action's own range)")
    frame_end: IntProperty(name="End", default=0, min=0, description="Last source frame (0: the action's own range)")
    output: EnumProperty(name="Output", items=(("ACTION", "New Action", "The result becomes the active action"),
                                                ("NLA", "NLA Track", "The result goes on a new NLA track")))

    @classmethod
    def poll(cls, context):
        return active_armature(context) is not None

    def invoke(self, context, event):
        if not self.source:
            others = [o for o in context.selected_objects if o.type == "ARMATURE" and o != context.active_object]
            if others:
                self.source = others[0].name
        return self.execute(context)

    def execute(self, context):
        def work():
            target = active_armature(context)
            source = bpy.data.objects.get(self.source)
            if source is None or source.type != "ARMATURE":
                raise RigError(f"no source armature '{self.source}': select the source with the target active, "
                               "or name it in Source")
            frames = (self.frame_start, self.frame_end) if self.frame_end > self.frame_start > 0 else None
            s = job.retarget(source, target, context.scene, frame_range=frames, output=self.output)
            text = (f"'{s['action']}': {s['roles_mapped']} roles, legs x{s['leg_ratio']:.2f}, planted feet slide "
                    f"{s['planted_slide_mm']:.1f} mm" + (f", mismatch {s['mismatch_mm']:.2f} mm / "
                                                         f"{s['mismatch_deg']:.2f} deg" if "mismatch_mm" in s else ""))
            twisted = {r: v[1] for r, v in (s.get("mismatch_per_role") or {}).items() if v[1] > job.TWIST_WARNING_DEG}
            if twisted:  # the rig shows these joints turned otherwise than the solve: said, not hidden
                role = max(twisted, key=twisted.get)
                text += f"; the rig turns {role} {twisted[role]:.0f} deg away from the retargeted pose"
            warned = twisted or s.get("source_rest_warning")
            if s.get("source_rest_warning"):  # a rest that looks captured moves the result: said, not hidden
                text += f"; {s['source_rest_warning']}"
            message = with_qa(self, context, target, s, text, job.GROUND)
            if warned:
                message = Message(str(message))
                message.level = "WARNING"
            return message
        return run_reporting(self, work)


CLASSES = (HUMANANIM_OT_retarget_motion,)
