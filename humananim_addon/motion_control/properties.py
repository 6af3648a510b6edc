"""Dynamic Control's settings on the scene (scene.humananim_control): the source, loads and
ground it shares with Simulate (forces.LoadsAndPushes), the impulses, a collider, the control's steps."""

import bpy
from bpy.props import BoolProperty, CollectionProperty, FloatProperty, IntProperty, PointerProperty

from ..forces import ArrowForce, LoadsAndPushes
from ..properties import settings_registration


class HumanAnimImpulse(ArrowForce, bpy.types.PropertyGroup):
    duration: FloatProperty(name="Duration", default=0.0, min=0.0, soft_max=2.0, unit="TIME_ABSOLUTE",
                            description="0: an instantaneous impulse (Magnitude in N s); "
                                        "otherwise a force (Magnitude in N) over this many seconds")
    magnitude: FloatProperty(name="Magnitude", default=30.0, min=0.0, soft_max=3000.0,
                             description="N s for an impulse (Duration 0), N for a force over its duration")


class HumanAnimControl(LoadsAndPushes, bpy.types.PropertyGroup):
    """The source, loads and ground (forces.LoadsAndPushes), when the loads are picked up, the
    impulses, a collider, the control's steps."""

    load_frame: IntProperty(name="Load From", default=0,
                            description="Frame the loads are picked up at (their weight taken up over 0.25 s); "
                                        "0: from the start")
    impulses: CollectionProperty(type=HumanAnimImpulse)
    impulse_index: IntProperty()
    collider: PointerProperty(name="Collide With", type=bpy.types.Object,
                              description="Another armature (its bones become spheres) or a moving mesh "
                                          "(bounding spheres of its evaluated vertices) the body bumps into")
    collider_radius: FloatProperty(name="Bone Radius", default=0.06, min=0.005, soft_max=0.3, unit="LENGTH",
                                   description="Radius of the spheres along another armature's bones")
    collider_spheres: IntProperty(name="Spheres", default=1, min=1, max=16,
                                  description="A mesh collider is covered by this many spheres along its "
                                              "longest axis")
    collider_mass: FloatProperty(name="Collider Mass", default=0.0, min=0.0, soft_max=200.0, unit="MASS",
                                 description="0: it moves as animated whatever it hits")
    substeps: IntProperty(name="Substeps", default=1, min=1, max=16, description="Control steps per frame")
    tracking_only: BoolProperty(name="Tracking Only",
                                description="Track the motion without comfort and balance control "
                                            "(to compare)")


CLASSES = (HumanAnimImpulse, HumanAnimControl)

register, unregister = settings_registration(CLASSES, bpy.types.Scene, "humananim_control", HumanAnimControl)
