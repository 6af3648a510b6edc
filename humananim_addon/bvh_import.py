"""BVH through Blender's own importer, with the unit guessed so the figure comes out in metres."""

import logging
import os

import bpy

from ..solver.errors import HumanAnimError
from ..solver.units import bvh_rest_extent, guess_length_scale

log = logging.getLogger(__name__)


def import_bvh(path, scale=None, update_scene=True):
    """Import a BVH file; returns (armature object, metres per file unit, unit name)."""
    if not os.path.isfile(path):
        raise HumanAnimError(f"no such file: {path}")
    try:
        with open(path, encoding="utf-8", errors="replace") as f:
            text = f.read()
        if "HIERARCHY" not in text[:200] or "MOTION" not in text:
            raise HumanAnimError(f"{os.path.basename(path)} is not a BVH file (no HIERARCHY/MOTION)")
        extent = bvh_rest_extent(text)
    except (OSError, ValueError) as error:
        raise HumanAnimError(f"cannot read {os.path.basename(path)}: {error}") from None
    unit = "given"
    if scale is None:
        scale, unit = guess_length_scale(extent)
    if bpy.ops.object.mode_set.poll():
        bpy.ops.object.mode_set(mode="OBJECT")
    before = set(bpy.data.objects)
    try:
        result = bpy.ops.import_anim.bvh(filepath=os.path.abspath(path), global_scale=scale,
                                         update_scene_fps=update_scene, update_scene_duration=update_scene,
                                         use_fps_scale=False)
    except (RuntimeError, ValueError, IndexError) as error:
        raise HumanAnimError(f"Blender's BVH importer failed on {os.path.basename(path)}: {error}") from None
    new = [o for o in bpy.data.objects if o not in before and o.type == "ARMATURE"]
    if "FINISHED" not in result or not new:
        raise HumanAnimError(f"Blender's BVH importer made no armature from {os.path.basename(path)}")
    log.info("imported %s: unit %s (%.4g m per unit)", os.path.basename(path), unit, scale)
    return new[0], scale, unit
