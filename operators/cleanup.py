"""Clean Up Capture (issue 26): the active action repaired (glitches, jitter, floor, foot skate)
into a NEW action, contacts as pose markers; the work lives in humananim_addon.cleanup."""

import bpy
from bpy.props import BoolProperty, FloatProperty, StringProperty

from ..humananim_addon import cleanup
from ..solver.cleanup import Options
from ..solver.errors import MotionError
from .common import run_reporting, with_qa


class HUMANANIM_OT_clean_up_capture(bpy.types.Operator):
    """Repair raw capture on the active action into a new action: flips, spikes and dropouts, jitter, feet through or above the floor, foot skate"""

    bl_idname = "humananim.clean_up_capture"
    bl_label = "Clean Up Capture"
    bl_options = {"REGISTER", "UNDO"}
    measures_motion = True

    glitches: BoolProperty(name="Glitches", default=True, description="Repair flips, spikes and dropouts")
    glitch_strength: FloatProperty(name="Sensitivity", default=1.0, min=0.1, max=4.0,
                                   description="Glitch limits (1800 deg/s for joints, 5 g for the root) are divided by this")
    jitter: BoolProperty(name="Jitter", default=True, description="Remove jitter, keeping fast intended motion")
    jitter_hz: FloatProperty(name="Cut-off", default=6.0, min=0.5, soft_max=30.0, description="Low-pass cut-off, Hz")
    jitter_strength: FloatProperty(name="Strength", default=1.0, min=0.0, max=1.0, subtype="FACTOR")
    floor: BoolProperty(name="Floor", default=True, description="Find the floor and put the planted feet on it")
    ground: FloatProperty(name="Ground", default=0.0, unit="LENGTH", description="Floor height the feet are put on")
    ground_object: StringProperty(name="Ground Mesh", default="",
                                  description="A mesh object the feet are put on (empty: a flat floor at Ground)",
                                  search=lambda self, context, text: [o.name for o in bpy.data.objects
                                                                      if o.type == "MESH" and text.lower() in o.name.lower()])
    skate: BoolProperty(name="Foot Skate", default=True, description="Hold planted feet where they land")
    physics: BoolProperty(name="Physical Pass", default=False,
                          description="Run the result through dynamic control (tracking only): the pelvis and centre of "
                                      "mass obey gravity and the support; the balance error is reported")

    @classmethod
    def poll(cls, context):
        obj = context.active_object
        return obj is not None and obj.type == "ARMATURE" and cleanup.active_action(obj) is not None

    def execute(self, context):
        def work():
            obj = context.active_object
            action = cleanup.active_action(obj)
            if action is None:
                raise MotionError("the active armature has no action to clean")
            ground = self.ground
            if self.floor and self.ground_object:
                mesh = bpy.data.objects.get(self.ground_object)
                if mesh is None:
                    raise MotionError(f"no object named '{self.ground_object}' for the ground")
                ground = cleanup.ground_from_object(mesh, context.evaluated_depsgraph_get())
            options = Options(glitches=self.glitches, jitter=self.jitter, floor=self.floor, skate=self.skate,
                              physics=self.physics,
                              glitch_strength=self.glitch_strength, jitter_strength=self.jitter_strength,
                              jitter_hz=self.jitter_hz, ground=ground)
            s = cleanup.clean_action(obj, context.scene, action, options)
            events = sum(len(r.get("events", [])) for r in s["report"]["repairs"])
            text = f"'{s['action']}': {events} glitches repaired, {s['markers']} contact markers"
            flat = self.floor and not self.ground_object
            return with_qa(self, context, obj, s, text, self.ground if flat else None)
        return run_reporting(self, work)


CLASSES = (HUMANANIM_OT_clean_up_capture,)
