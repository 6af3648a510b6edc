"""Batch cloth: `python -m humananim cloth clip.bvh --skirt ...` simulates a garment on the
character and saves a .blend whose new mesh object plays the cloth from a PC2 point cache
(written next to the .blend), then prints a summary (--json: one object)."""

import os
import tempfile
import time

from ...solver.cloth.materials import ClothParams
from ..arguments import UsageError, add_input, add_out

COLLIDERS = ("auto", "mesh", "capsules", "both", "none")
PRESET_NAMES = ("cotton", "denim", "leather")


def add_commands(sub, add_common_options):
    c = sub.add_parser("cloth", help="fast plausible cloth: simulate a garment (or a generated skirt) on the "
                                     "character; writes a mesh object played from a PC2 point cache")
    add_input(c)
    c.add_argument("--garment", help="the coarse garment mesh object (default: the scene's cloth garment)")
    c.add_argument("--skirt", action="store_true", help="generate a skirt for the character and simulate it")
    c.add_argument("--skirt-size", nargs=2, type=int, default=(6, 11), metavar=("RINGS", "COLUMNS"),
                   help="rings and columns of the generated skirt (default 6 11: the thesis's 66 particles)")
    c.add_argument("--pin-group", default=None, help="the garment's pinned vertex group (default 'waist')")
    c.add_argument("--body", help="the skinned body mesh to collide with")
    c.add_argument("--capsule-body", action="store_true",
                   help="add a stand-in skinned body of capsules on the bones and collide with its mesh")
    c.add_argument("--collider", choices=COLLIDERS, default="auto",
                   help="auto: the body mesh if any, else capsules on the bones")
    c.add_argument("--preset", choices=PRESET_NAMES, default="cotton", help="material (default cotton)")
    c.add_argument("--level", type=int, default=2, help="smoothing level: 4 x level^2 triangles per face")
    c.add_argument("--substeps", type=int, default=ClothParams.substeps,
                   help=f"RK4 steps per simulated frame (default {ClothParams.substeps})")
    c.add_argument("--frames", nargs=2, type=int, metavar=("START", "END"), help="frame range")
    c.add_argument("--step", type=int, default=0, help="simulate every Nth frame (default: about 30 per second)")
    c.add_argument("--wind", help="wind velocity X,Y,Z in m/s")
    c.add_argument("--compress-limit", type=float, default=ClothParams.compress_limit,
                   help="shortening undone in the simulation beyond this share (0: all left to the smoothing; "
                        f"default {ClothParams.compress_limit})")
    c.add_argument("--pn-only", action="store_true", help="plain PN triangles (no normal or edge length control)")
    c.add_argument("--keep-coarse", action="store_true", help="also write the coarse simulated mesh")
    add_out(c, "cloth.blend")
    add_common_options(c)
    return {"cloth": cmd_cloth}


def _vector(text, option):
    try:
        v = [float(t) for t in text.split(",")]
        if len(v) != 3:
            raise ValueError
    except ValueError:
        raise UsageError(f"{option} {text!r}: expected X,Y,Z") from None
    return v


def cmd_cloth(args):
    import bpy
    from . import job as cloth
    from ..cli import _load
    from ...solver.progress import run_to_end
    t0 = time.perf_counter()
    if args.level < 1 or args.substeps < 1 or args.step < 0:
        raise UsageError("--level and --substeps must be at least 1, --step at least 0")
    arm, scene, unit = _load(args.file, args.armature, args.scale)
    out = os.path.abspath(args.out)
    os.makedirs(os.path.dirname(out), exist_ok=True)
    scene = bpy.context.scene
    props = scene.humananim_cloth
    props.armature = arm
    if args.frames:
        props.frame_start, props.frame_end = args.frames
    if args.skirt:
        rings, columns = args.skirt_size
        if rings < 2 or columns < 4:
            raise UsageError("--skirt-size needs at least 2 rings and 4 columns")
        # fitted at the pose of the first simulated frame
        cloth.add_skirt(arm, scene, rings=rings, columns=columns, frame=props.frame_start or scene.frame_start)
    elif args.garment:
        obj = bpy.data.objects.get(args.garment)
        if obj is None or obj.type != "MESH":
            raise UsageError(f"--garment: no mesh object named '{args.garment}'")
        props.garment = obj
    elif props.garment is None:
        raise UsageError("no garment: pass --garment NAME or --skirt")
    if args.pin_group is not None:
        props.pin_group = args.pin_group
    if args.body:
        body = bpy.data.objects.get(args.body)
        if body is None or body.type != "MESH":
            raise UsageError(f"--body: no mesh object named '{args.body}'")
        props.body = body
    elif args.capsule_body:
        props.body = cloth.add_capsule_body(arm, scene)
    props.collider = args.collider.upper()
    props.preset = args.preset.upper()
    props.level, props.substeps, props.frame_step = args.level, args.substeps, args.step
    props.normal_control = props.edge_control = not args.pn_only
    props.keep_coarse = args.keep_coarse
    if not 0.0 <= args.compress_limit <= 0.5:
        raise UsageError("--compress-limit must be between 0 and 0.5")
    props.compress_limit = args.compress_limit
    props.cache_dir = os.path.join(os.path.dirname(out), os.path.splitext(os.path.basename(out))[0] + "_cache")
    if args.wind:
        props.wind = _vector(args.wind, "--wind")
    summary = run_to_end(cloth.run(scene))
    save_blend(out, [bpy.data.objects[n] for n in (summary["object"], summary["coarse_object"]) if n])
    summary.update(command="cloth", file=os.path.abspath(args.file), armature=arm.name,
                   garment=props.garment.name, body=props.body.name if props.body else None,
                   preset=args.preset, wrote=[out] + summary["wrote"], seconds=round(time.perf_counter() - t0, 3))
    if unit:
        summary["bvh_unit"] = unit
    summary["summary"] = text_summary(summary)
    return summary


def save_blend(out, objects):
    """Save the .blend at `out` whole or not at all: written next to it under a temporary name
    (the point caches' paths made relative to that folder), then renamed over it."""
    import bpy
    folder = os.path.dirname(out)
    fd, tmp = tempfile.mkstemp(prefix=".cloth-", suffix=".blend", dir=folder)
    os.close(fd)
    try:
        bpy.ops.wm.save_as_mainfile(filepath=tmp)  # (now '//' is the output's folder)
        for obj in objects:
            for mod in obj.modifiers:
                if mod.type == "MESH_CACHE":
                    mod.filepath = bpy.path.relpath(bpy.path.abspath(mod.filepath))
        bpy.ops.wm.save_as_mainfile(filepath=tmp)
        os.replace(tmp, out)
    finally:
        for leftover in (tmp, tmp + "1"):
            if os.path.exists(leftover):
                os.remove(leftover)


def text_summary(s):
    t = s["timing_ms_per_frame"]
    lines = [f"cloth: '{s['garment']}' on '{s['armature']}' ({s['preset']}), {s['frames']} frames "
             f"{s['frame_range'][0]}-{s['frame_range'][1]} (every {s['frame_step']}), {s['particles']} particles "
             f"-> {s['fine_faces']} faces",
             f"  {t['total_ms']:.2f} ms/frame: simulation {t['integration_ms']:.2f}, collision "
             f"{t['collision_ms']:.2f}, smoothing {t['smoothing_ms']:.2f}; colliders {', '.join(s['colliders'])}",
             f"  deepest inside the body {s['max_depth_inside_mm']:.2f} mm, mean stretch up to "
             f"{100 * s['max_mean_stretch']:.2f} %",
             f"  wrote object '{s['object']}'" + (f" and '{s['coarse_object']}'" if s["coarse_object"] else "")]
    for path in s["wrote"]:
        lines.append(f"  wrote {path}")
    lines.append(f"  took {s['seconds']:.2f} s")
    return "\n".join(lines)
