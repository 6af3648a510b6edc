"""Settings stored on the armature: role overrides, detected roles and the mass model."""

import bpy
from bpy.props import (CollectionProperty, EnumProperty, FloatProperty, FloatVectorProperty,
                       IntProperty, PointerProperty, StringProperty)

from ..solver.body_roles import ALL_ROLES, CHAIN_ROLES


def role_key(role):
    """Property identifier of a role: 'thigh.L' -> 'thigh_l'."""
    return role.replace(".", "_").lower()


def _role_annotations():
    out = {}
    for role in ALL_ROLES:
        kind = "bone names, comma-separated, proximal first" if role in CHAIN_ROLES else "bone"
        out[role_key(role)] = StringProperty(
            name=role.replace("_", " ").replace(".", " ").title(),
            description=f"Override the detected {role} {kind}; empty: use the detected one")
    return out


HumanAnimRoleBones = type("HumanAnimRoleBones", (bpy.types.PropertyGroup,),
                          {"__annotations__": _role_annotations()})


class HumanAnimDetectedRole(bpy.types.PropertyGroup):
    role: StringProperty()
    bones: StringProperty()


class HumanAnimSegment(bpy.types.PropertyGroup):
    bone: StringProperty(name="Bone")
    mass: FloatProperty(name="Mass", unit="MASS", min=0.0, soft_max=50.0, precision=3)
    com: FloatVectorProperty(name="Centre of Mass", size=3, subtype="TRANSLATION", unit="LENGTH",
                             description="In the bone's rest frame, metres")
    inertia: FloatVectorProperty(name="Inertia", size=6, precision=5,
                                 description="About the centre, bone frame (kg m²): xx yy zz xy xz yz")


class HumanAnimRigSettings(bpy.types.PropertyGroup):
    roles: PointerProperty(type=HumanAnimRoleBones)
    detected_roles: CollectionProperty(type=HumanAnimDetectedRole)
    detected_convention: StringProperty(name="Convention")
    missing_roles: StringProperty(name="Missing Roles")
    mass_source: EnumProperty(name="Mass From", items=(
        ("AUTO", "Auto", "The bound mesh when the armature deforms one, else the body tables"),
        ("ANTHROPOMETRIC", "Body Tables", "de Leva 1996 segment tables scaled to the bones and total mass"),
        ("MESH", "Bound Mesh", "Volumes of the skin weighted to each bone, at the body density"),
    ), default="AUTO")
    total_mass: FloatProperty(name="Total Mass", unit="MASS", default=70.0, min=1.0, soft_max=200.0)
    density: FloatProperty(name="Body Density", default=1050.0, min=100.0, soft_max=2000.0,
                           description="kg per cubic metre, for the mesh volumes")
    body_type: EnumProperty(name="Table", items=(("MALE", "Male", ""), ("FEMALE", "Female", "")),
                            default="MALE")
    segments: CollectionProperty(type=HumanAnimSegment)
    segment_index: IntProperty()


class HumanAnimSceneSettings(bpy.types.PropertyGroup):
    output: EnumProperty(name="Output", items=(
        ("ACTION", "New Action", "Assign the result as the active action; the source keeps a fake user"),
        ("NLA", "NLA Track", "Put the result on a new NLA track above the others"),
    ), default="ACTION")
    exact: EnumProperty(name="Evaluation", items=(
        ("AUTO", "Auto", "Depsgraph when the rig has constraints or drivers, else F-curves"),
        ("FCURVES", "F-Curves", "Sample the action's F-curves (fast, plain FK rigs)"),
        ("DEPSGRAPH", "Depsgraph", "Evaluate every frame as Blender shows it (constraints, drivers)"),
    ), default="AUTO")


def settings_registration(classes, owner, attribute, group):
    """register/unregister for property groups whose settings live at `owner.attribute`."""
    register_classes, unregister_classes = bpy.utils.register_classes_factory(classes)

    def register():
        register_classes()
        setattr(owner, attribute, PointerProperty(type=group))

    def unregister():
        delattr(owner, attribute)
        unregister_classes()

    return register, unregister


def role_overrides(settings):
    """The animator's role choices: {role: bone names}. (A plain function: a Python property
    on a PropertyGroup class crashes bpy 4.2 at exit.)"""
    out = {}
    for role in ALL_ROLES:
        value = getattr(settings.roles, role_key(role)).strip()
        if value:
            out[role] = tuple(v.strip() for v in value.split(",") if v.strip())
    return out


CLASSES = (HumanAnimRoleBones, HumanAnimDetectedRole, HumanAnimSegment, HumanAnimRigSettings,
           HumanAnimSceneSettings)


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.Armature.humananim = PointerProperty(type=HumanAnimRigSettings)
    bpy.types.Scene.humananim = PointerProperty(type=HumanAnimSceneSettings)
    bpy.types.WindowManager.humananim_progress = FloatProperty(default=-1.0, options={"SKIP_SAVE"})
    bpy.types.WindowManager.humananim_job = StringProperty(options={"SKIP_SAVE"})


def unregister():
    del bpy.types.WindowManager.humananim_job
    del bpy.types.WindowManager.humananim_progress
    del bpy.types.Scene.humananim
    del bpy.types.Armature.humananim
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
