"""BVH through Blender's own importer, with the unit guessed so the figure comes out in metres.

Blender's importer reads one frame per line, ignores the header's frame count and takes NaN,
infinities and truncated files without a word. So the file is first read by the solver's BVH
reader (any whitespace, line endings and layout; a broken file is one clear message), its height
measured to guess the unit (a figure no common unit makes human-sized is refused), and Blender
imports a canonical copy of it (same name, one frame per line)."""

import logging
import os
import shutil
import tempfile

import bpy

from ..solver import bvh
from ..solver.errors import HumanAnimError
from ..solver.units import guess_length_scale

log = logging.getLogger(__name__)


def read_checked(path):
    """The parsed BVH of `path` (file units), or a HumanAnimError naming the file and the problem."""
    if not os.path.isfile(path):
        raise HumanAnimError(f"no such file: {path}")
    try:
        with open(path, encoding="utf-8", errors="replace") as f:
            return bvh.parse(f.read())
    except OSError as error:
        raise HumanAnimError(f"cannot read {os.path.basename(path)}: {error.strerror}") from None
    except HumanAnimError as error:
        raise type(error)(f"{os.path.basename(path)}: {error}") from None


def import_bvh(path, scale=None, update_scene=True):
    """Import a BVH file; returns (armature object, metres per file unit, unit name)."""
    clip = read_checked(path)
    height = bvh.figure_height(clip)
    unit = "given"
    if scale is None:
        try:
            scale, unit = guess_length_scale(height)
        except HumanAnimError as error:
            raise type(error)(f"{os.path.basename(path)}: {error}") from None
    elif not (scale > 0.0 and scale < float("inf")):
        raise HumanAnimError(f"--scale {scale:g}: expected a positive number of metres per file unit")
    if bpy.ops.object.mode_set.poll():
        bpy.ops.object.mode_set(mode="OBJECT")
    before = set(bpy.data.objects)
    folder = tempfile.mkdtemp(prefix="humananim-bvh-")
    try:
        canonical = os.path.join(folder, os.path.basename(path))  # Blender names the armature after the file
        bvh.write(clip, canonical)
        result = bpy.ops.import_anim.bvh(filepath=canonical, global_scale=scale,
                                         update_scene_fps=update_scene, update_scene_duration=update_scene,
                                         use_fps_scale=False)
    except (RuntimeError, ValueError, IndexError) as error:
        raise HumanAnimError(f"Blender's BVH importer failed on {os.path.basename(path)}: "
                             f"{str(error).strip().splitlines()[-1]}") from None
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    new = [o for o in bpy.data.objects if o not in before and o.type == "ARMATURE"]
    if "FINISHED" not in result or not new:
        raise HumanAnimError(f"Blender's BVH importer made no armature from {os.path.basename(path)}")
    new[0]["humananim_figure_height_m"] = height * scale
    log.info("imported %s: unit %s (%.4g m per unit), figure %.2f m tall", os.path.basename(path), unit, scale,
             height * scale)
    return new[0], scale, unit
