"""Motion files into the scene for the command line: FBX through Blender's own importer.

`load_fbx` is what the batch command line's loader calls for a `.fbx` file (a Mixamo download, a
studio's export): an empty scene, Blender's FBX importer, the one armature (or the one named),
its imported action active and the scene's frame range set to it. The importer's own frame
offset is kept: a file's time 0 lands on frame 1 (Blender's own exporter writes frame 1 at 1/fps,
so its files come back one frame later)."""

import os

import bpy

from ...solver.errors import HumanAnimError

_BINARY_MAGIC = b"Kaydara FBX Binary"


def _check_fbx(path):
    if not os.path.isfile(path):
        raise HumanAnimError(f"no such file: {path}")
    try:
        with open(path, "rb") as f:
            head = f.read(4096)
    except OSError as error:
        raise HumanAnimError(f"cannot read {os.path.basename(path)}: {error}") from None
    if head.startswith(_BINARY_MAGIC):
        return
    if b"FBXHeaderExtension" in head:
        raise HumanAnimError(f"{os.path.basename(path)} is an ASCII FBX file: Blender's importer reads binary FBX "
                             "only; save it as binary FBX (6.1 or later) first")
    raise HumanAnimError(f"{os.path.basename(path)} is not an FBX file")


def _importer():
    try:
        bpy.ops.import_scene.fbx.get_rna_type()
    except KeyError:
        import addon_utils
        addon_utils.enable("io_scene_fbx", default_set=True)


def import_fbx(path, armature_name=None, armature_option="--armature"):
    """Import an FBX file into the current scene; returns its armature object (the one named
    `armature_name` when given) with the imported action active. `armature_option`: the command's
    option that names it, for the message when the file holds several."""
    _check_fbx(path)
    _importer()
    if bpy.ops.object.mode_set.poll():
        bpy.ops.object.mode_set(mode="OBJECT")
    before = set(bpy.data.objects)
    try:
        result = bpy.ops.import_scene.fbx(filepath=os.path.abspath(path), use_anim=True)
    except (RuntimeError, ValueError, TypeError, AttributeError) as error:
        first = str(error).strip().splitlines()[-1] if str(error).strip() else type(error).__name__
        raise HumanAnimError(f"Blender's FBX importer failed on {os.path.basename(path)}: {first}") from None
    new = [o for o in bpy.data.objects if o not in before and o.type == "ARMATURE"]
    if "FINISHED" not in result or not new:
        raise HumanAnimError(f"Blender's FBX importer made no armature from {os.path.basename(path)}")
    if armature_name:
        named = [o for o in new if o.name == armature_name or o.data.name == armature_name]
        if not named:
            raise HumanAnimError(f"no armature named '{armature_name}' in {os.path.basename(path)} "
                                 f"(armatures: {', '.join(o.name for o in new)})")
        obj = named[0]
    elif len(new) == 1:
        obj = new[0]
    else:
        raise HumanAnimError(f"{len(new)} armatures in {os.path.basename(path)}: pass {armature_option} "
                             f"({', '.join(o.name for o in new)})")
    bpy.context.view_layer.objects.active = obj
    action = obj.animation_data.action if obj.animation_data else None
    scene = bpy.context.scene
    if action is not None:
        start, end = action.frame_range
        scene.frame_start, scene.frame_end = int(round(start)), int(round(end))
        scene.frame_set(scene.frame_start)
    return obj


def load_fbx(path, armature_name=None):
    """The command line's loader for a .fbx file: (armature, scene, None) in a fresh empty scene."""
    _check_fbx(path)
    bpy.ops.wm.read_homefile(use_empty=True)
    obj = import_fbx(path, armature_name)
    return obj, bpy.context.scene, None
