"""Loads and pushes: the settings Simulate and Dynamic Control share, in one place.

Both jobs follow a source action over a frame range, carry loads in the hands, stand on a ground
(the motion's own or a height) and are hit by forces drawn as arrow Empties (see arrows.py): a
push in Simulate, an impulse or a force in Dynamic Control. The property groups here are mixins
(Blender registers annotations inherited from a plain base class); each job's group adds its own
settings and names its list of arrows (`pushes` / `impulses`), so the property paths saved in an
animator's .blend (scene.humananim_simulation.pushes[0].magnitude, scene.humananim_control.load_left,
...) are the ones they always were."""

from bpy.props import EnumProperty, FloatProperty, IntProperty, PointerProperty, StringProperty
import bpy

from ..solver.body_roles import SIDES, sided
from ..solver.errors import RigError
from .arrows import place_arrow


class ArrowForce:
    """One force drawn as an arrow: where and when it acts. A job's item adds its own duration and
    magnitude (a push's newtons, an impulse's newton-seconds)."""

    # no poll filter to Empties: a PointerProperty poll crashes the bpy 4.2 module at exit, and
    # any object's location and Z axis define a force as well as an arrow Empty's
    empty: PointerProperty(name="Arrow", type=bpy.types.Object,
                           description="An object (an arrow Empty) whose location is where the force acts "
                                       "and whose Z axis is its direction")
    bone: StringProperty(name="Bone", description="The bone that is pushed")
    frame: IntProperty(name="Frame", default=1, description="When the force starts")


class LoadsAndPushes:
    """The settings a body job on a source action shares: the action and its frames, the loads in
    the hands, the strength, the ground."""

    action: PointerProperty(name="Source Action", type=bpy.types.Action,
                            description="The motion to follow; empty: the active action")
    frame_start: IntProperty(name="Start", default=0, description="0: the action's first frame")
    frame_end: IntProperty(name="End", default=0, description="0: the action's last frame")
    load_left: FloatProperty(name="Left Hand Load", default=0.0, min=0.0, soft_max=50.0, unit="MASS",
                             description="kg carried at the left hand")
    load_right: FloatProperty(name="Right Hand Load", default=0.0, min=0.0, soft_max=50.0, unit="MASS",
                              description="kg carried at the right hand")
    strength_scale: FloatProperty(name="Strength", default=1.0, min=0.0, soft_max=3.0,
                                  description="Scale of the muscle strength model")
    ground: EnumProperty(name="Ground", items=(
        ("MOTION", "From Motion", "At the lowest point the feet (or any contact) reach in the source motion"),
        ("HEIGHT", "Height", "A horizontal ground at the height below"),
    ))
    ground_height: FloatProperty(name="Ground Height", default=0.0, unit="LENGTH")


def gravity_of(scene):
    return tuple(scene.gravity) if scene.use_gravity else (0.0, 0.0, 0.0)


def hand_loads(props, skeleton, required=False):
    """[(hand bone, kg)] of the loads set; a load on a hand the rig lacks is left out, or refused
    when `required`."""
    out = []
    for side, kg in zip(SIDES, (props.load_left, props.load_right)):
        if kg <= 0.0:
            continue
        hand = skeleton.roles.bone(sided("hand", side))
        if hand:
            out.append((hand, kg))
        elif required:
            raise RigError(f"no {'left' if side == 'L' else 'right'} hand found to carry the load: "
                           "set it in Body Roles")
    return out


def add_arrow(obj, scene, props, items, index, bone_name, frame, direction, magnitude, duration, name):
    """An arrow Empty in front of the bone (see arrows.place_arrow), added to the job's list
    `items` of `props` and made its active item (`index`)."""
    if bone_name not in obj.data.bones:
        raise RigError(f"'{obj.name}' has no bone named '{bone_name}'")
    empty = place_arrow(obj, scene, bone_name, frame, direction, name=name)
    collection = getattr(props, items)
    item = collection.add()
    item.empty, item.bone, item.frame = empty, bone_name, frame
    item.magnitude, item.duration = magnitude, duration
    setattr(props, index, len(collection) - 1)
    return item
