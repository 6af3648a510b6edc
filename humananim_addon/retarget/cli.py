"""The `retarget` command: python -m humananim retarget SRC.bvh|.fbx --to scene.blend --armature RIG
[--action NAME] [--frames A B] [--out OUT.blend] [--json]. Opens the scene, imports the source
(Blender's BVH or FBX importer; its motion read at the scene's frame rate, the scene's rate and range
kept), puts its motion on the armature RIG's controls in a NEW action and saves the scene to
OUT.blend (the source file and the scene's file untouched)."""

import os
import time

from ..arguments import UsageError, add_frames, add_out, add_output


def add_commands(sub, add_common_options):
    c = sub.add_parser("retarget", help="put a BVH or FBX capture on a rig's controls (a new action)")
    c.add_argument("file", help="the source motion: a .bvh or .fbx file")
    c.add_argument("--to", required=True, metavar="SCENE.blend", help="the .blend holding the target rig")
    c.add_argument("--armature", help="the target armature in the .blend (default: the only one)")
    c.add_argument("--source-armature", help="in a .fbx with several armatures, the one to read")
    c.add_argument("--action", help="the source action (default: the imported one)")
    add_frames(c, "source frame range")
    add_output(c)
    add_out(c, "retarget.blend")
    add_common_options(c)
    return {"retarget": cmd_retarget}


def cmd_retarget(args):
    import bpy
    from ..cli import _load, save_blend
    from . import job
    t0 = time.perf_counter()
    if not args.file.lower().endswith((".bvh", ".fbx")):
        raise UsageError(f"{os.path.basename(args.file)}: the source must be a .bvh or .fbx file")
    if not os.path.isfile(args.file):
        raise UsageError(f"no such file: {args.file}")
    if not args.to.lower().endswith(".blend"):
        raise UsageError(f"--to {args.to}: expected the .blend holding the target rig")
    target, scene, _ = _load(args.to, args.armature, None)
    source = _import_source(args.file, args.source_armature, args.scale, scene)
    if args.action:
        action = bpy.data.actions.get(args.action)
        if action is None:
            raise UsageError(f"no action named '{args.action}'")
    else:
        action = source.animation_data.action if source.animation_data else None
    summary = job.retarget(source, target, scene, action, tuple(args.frames) if args.frames else None,
                           output=args.output)
    out = save_blend(args.out, summary, target, job.GROUND)
    summary.update(file=os.path.abspath(args.file), wrote=[out], seconds=round(time.perf_counter() - t0, 3))
    summary["summary"] = "\n".join([f"retarget: '{source.name}' onto '{target.name}'"]
                                   + [f"  {line}" for line in job.lines(summary)]
                                   + [f"  wrote {out}", f"  took {summary['seconds']:.2f} s"])
    return summary


def _import_source(path, armature_name, scale, scene):
    """The source armature imported into the open scene (its frame rate kept)."""
    if path.lower().endswith(".bvh"):
        from ..bvh_import import import_bvh
        return import_bvh(path, scale, update_scene=False)[0]
    from ..rig.load import _check_fbx, import_fbx
    _check_fbx(path)
    render = scene.render
    kept = (render.fps, render.fps_base, scene.frame_start, scene.frame_end, scene.frame_current)
    try:  # here --armature is the target rig: the source's armature is --source-armature
        obj = import_fbx(path, armature_name, armature_option="--source-armature")
    finally:  # Blender's importer sets the scene's rate and range to the file's: the target's scene keeps its own
        file_fps = render.fps / render.fps_base
        render.fps, render.fps_base = kept[:2]
        scene.frame_start, scene.frame_end = kept[2:4]
        scene.frame_set(kept[4])
    if obj.animation_data and obj.animation_data.action:
        _retime(obj, obj.animation_data.action, (render.fps / render.fps_base) / file_fps)
    return obj


def _retime(obj, action, ratio):
    """The keys of `action` moved from the file's rate to the scene's (`ratio`: scene fps over the
    file's), frame 1 held (where the importer puts the file's time 0), as the BVH import resamples."""
    import numpy as np
    from ..action_api import fcurves_of
    if abs(ratio - 1.0) < 1e-9:
        return
    for fc in fcurves_of(action, obj):
        for prop in ("co", "handle_left", "handle_right"):
            xy = np.empty(2 * len(fc.keyframe_points))
            fc.keyframe_points.foreach_get(prop, xy)
            xy[0::2] = 1.0 + (xy[0::2] - 1.0) * ratio
            fc.keyframe_points.foreach_set(prop, xy)
        fc.update()
