"""Forces drawn as arrow Empties: an arrow's location is where the force hits, its Z axis the
direction. Shared by pushes (simulation) and impulses (dynamic control)."""

import bpy
import numpy as np
from mathutils import Vector

from ..solver.errors import RigError


def place_arrow(obj, scene, bone_name, frame, direction=None, name="Push"):
    """An arrow Empty 30 cm before the bone's middle at `frame`, pointing along `direction`
    (default: into the character's front), its tip at the bone."""
    saved = scene.frame_current
    scene.frame_set(frame)
    bone = obj.data.bones[bone_name]
    middle = obj.matrix_world @ obj.pose.bones[bone_name].matrix @ Vector((0.0, bone.length / 2, 0.0))
    scene.frame_set(saved)
    axis = Vector(direction) if direction is not None else obj.matrix_world.to_3x3() @ Vector((0.0, 1.0, 0.0))
    axis.normalize()
    empty = bpy.data.objects.new(f"{name} {bone_name}", None)
    empty.empty_display_type = "SINGLE_ARROW"
    empty.empty_display_size = 0.3
    empty.location = middle - 0.3 * axis
    empty.rotation_euler = Vector((0.0, 0.0, 1.0)).rotation_difference(axis).to_euler()
    scene.collection.objects.link(empty)
    return empty


def arrow_forces(items, skeleton, traj, scene):
    """(item, seconds from the clip's start, point in the bone's frame, world unit direction) of
    every arrow item with an object and a positive magnitude, each read as the arrow stands at the
    item's frame (it may be animated; a new object's matrix is stale until evaluated)."""
    world = None
    saved = scene.frame_current, scene.frame_subframe
    out = []
    try:
        for item in items:
            if item.empty is None or item.magnitude <= 0.0:
                continue
            if item.bone not in skeleton.names:
                raise RigError(f"the arrow '{item.empty.name}' at frame {item.frame} names no bone of "
                               f"the armature: '{item.bone}'")
            if world is None:
                world = traj.world_frames(skeleton)
            f = int(np.clip(np.searchsorted(traj.frames, item.frame), 0, traj.frame_count - 1))
            scene.frame_set(int(traj.frames[f]))
            m = np.array(item.empty.matrix_world)
            m[:3, 3] *= scene.unit_settings.scale_length
            point = np.linalg.solve(world[f, skeleton.index(item.bone)], np.append(m[:3, 3], 1.0))[:3]
            seconds = (traj.frames[f] - traj.frames[0]) / traj.fps
            out.append((item, seconds, tuple(point), tuple(m[:3, 2] / np.linalg.norm(m[:3, 2]))))
    finally:
        scene.frame_set(saved[0], subframe=saved[1])
    return out
