"""Rig set-up: detect body roles, compute the mass model, bake an action to dense keys."""

import bpy
from bpy.props import EnumProperty, StringProperty

from ..humananim_addon import actions, armature, mass_model, properties
from ..solver.role_detection import require_roles
from ..solver.errors import MotionError
from .common import JobOperator, active_armature, run_reporting


class HUMANANIM_OT_detect_roles(bpy.types.Operator):
    """Find the pelvis, spine, limbs, head and fingers of the active armature"""

    bl_idname = "humananim.detect_roles"
    bl_label = "Detect Body Roles"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return active_armature(context) is not None

    def execute(self, context):
        return run_reporting(self, lambda: detect_and_store(active_armature(context)))


def detect_and_store(obj):
    detection = armature.detect(obj)
    settings = obj.data.humananim
    roles = detection.roles.with_overrides(properties.role_overrides(settings))
    settings.detected_roles.clear()
    for role, bones in detection.roles.bones.items():
        item = settings.detected_roles.add()
        item.role, item.bones = role, ", ".join(bones)
    settings.detected_convention = detection.convention
    settings.missing_roles = ", ".join(roles.missing())
    require_roles(type(detection)(roles, detection.convention, tuple(roles.missing()), detection.notes))
    return f"{len(roles.bones)} body roles found ({detection.convention})"


class HUMANANIM_OT_compute_mass_model(bpy.types.Operator):
    """Compute every segment's mass, centre of mass and inertia, and store them on the armature"""

    bl_idname = "humananim.compute_mass_model"
    bl_label = "Compute Mass Model"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return active_armature(context) is not None

    def execute(self, context):
        def work():
            obj = active_armature(context)
            obj.data.humananim.segments.clear()  # recompute, never reuse the stored values
            skeleton = armature.skeleton_from_armature(obj, context.scene)
            mass_model.store(obj.data.humananim, skeleton, skeleton.mass, skeleton.com, skeleton.inertia)
            return (f"{int((skeleton.mass > 0).sum())} segments, {skeleton.total_mass:.1f} kg "
                    f"({obj.data.humananim.mass_source.lower()})")
        return run_reporting(self, work)


class HUMANANIM_OT_bake_action(JobOperator, bpy.types.Operator):
    """Bake the active action, as Blender evaluates it, to a new action with a key on every frame"""

    bl_idname = "humananim.bake_action"
    bl_label = "Bake to New Action"

    action: StringProperty(name="Source Action", description="Empty: the active action")
    output: EnumProperty(name="Output", items=(
        ("SCENE", "Scene Setting", ""), ("ACTION", "New Action", ""), ("NLA", "NLA Track", "")),
        default="SCENE")

    @classmethod
    def poll(cls, context):
        obj = active_armature(context)
        return obj is not None and obj.animation_data is not None and obj.animation_data.action is not None

    def job(self, context):
        obj, scene = active_armature(context), context.scene
        source = bpy.data.actions.get(self.action) if self.action else obj.animation_data.action
        if source is None:
            raise MotionError(f"no action named '{self.action}'")
        settings = scene.humananim
        skeleton = armature.skeleton_from_armature(obj, scene, require=False)
        exact = {"AUTO": None, "FCURVES": False, "DEPSGRAPH": True}[settings.exact]
        traj = yield from actions.iter_read_action(obj, scene, skeleton, source, exact=exact)
        output = settings.output if self.output == "SCENE" else self.output
        from ..humananim_addon.rig.bones import classify
        from ..humananim_addon.rig.capability import with_control_channels
        controls = classify(obj).control  # a control rig's mechanism and deform bones follow its controls
        if set(skeleton.names) - controls:
            traj = with_control_channels(obj, context.scene, skeleton, traj, controls)
        result = actions.write_action(obj, skeleton, traj, f"{source.name}.baked", output, source, bones=controls)
        return f"'{result.name}': {traj.frame_count} frames of {len(controls)} control bones"


CLASSES = (HUMANANIM_OT_detect_roles, HUMANANIM_OT_compute_mass_model, HUMANANIM_OT_bake_action)
