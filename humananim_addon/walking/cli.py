"""Batch walking: `python -m humananim walk FILE --path CURVE ...`.

FILE is a .blend (with a curve or keyed object to follow) or a .bvh (default: the bundled CMU
clip), whose skeleton can walk a generated straight line (--line) or S curve (--s-curve) without
any .blend. Runs the same bridge code as the Walking panel, saves a .blend (--out) and prints a
summary (--json: one object)."""

import os
import time

from ..cli import DEFAULT_CLIP
from ..arguments import FINITE, NON_NEGATIVE, POSITIVE, UsageError, add_out, number


def add_commands(sub, add_common_options):
    c = sub.add_parser("walk", help="procedural walking (Boulic's model) along a path; writes a new action "
                                    "on an NLA strip with the support intervals")
    c.add_argument("file", nargs="?", default=DEFAULT_CLIP,
                   help="a .blend or .bvh file (default: the bundled CMU clip's skeleton)")
    c.add_argument("--armature", help="the armature object in a .blend (default: the only one)")
    where = c.add_mutually_exclusive_group()
    where.add_argument("--path", metavar="CURVE", help="a curve object in the .blend to walk along")
    where.add_argument("--keyed", metavar="OBJECT", help="an object whose keyed location the root follows")
    where.add_argument("--line", type=POSITIVE, metavar="METRES", help="walk a straight line this long (default 5)")
    where.add_argument("--s-curve", type=POSITIVE, metavar="METRES", help="walk an S curve this long")
    c.add_argument("--s-amplitude", type=FINITE, default=1.0, help="sideways amplitude of the S curve (m, default 1)")
    speed = c.add_mutually_exclusive_group()
    speed.add_argument("--speed", type=POSITIVE, help="walking speed in m/s (default 1.3)")
    speed.add_argument("--speed-keys", metavar="S:V,...", help="speeds (m/s) at distances (m) along the path")
    speed.add_argument("--segment-speeds", metavar="V,...", help="one speed per segment between control points")
    c.add_argument("--style", default="neutral", help="neutral, brisk, tired or sneaking (default neutral)")
    c.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                   help="a personification parameter (stride, pelvis_rotation, pelvis_tilt, arm_swing, "
                        "knee_flexion, heel_strike, torso_lean); repeatable")
    ground = c.add_mutually_exclusive_group()
    ground.add_argument("--ground", metavar="OBJECT", help="a mesh object in the .blend the feet stand on")
    ground.add_argument("--bumps", type=NON_NEGATIVE, metavar="METRES",
                        help="make a bumpy ground mesh of this amplitude under the path")
    c.add_argument("--frame-start", type=number(0, integer=True), default=0, help="first frame of the walk (default: scene start)")
    c.add_argument("--generator", action="append", default=[], metavar="ACTION:SCOPE:FRAME[:PRIORITY[:WEIGHT]]",
                   help="add a generator strip playing ACTION on SCOPE from FRAME; repeatable")
    add_out(c, "walk.blend")
    add_common_options(c)
    return {"walk": cmd_walk}


def cmd_walk(args):
    import bpy
    from ...solver.walking import PRESETS
    from . import job as walking
    from ..cli import load_rig
    t0 = time.perf_counter()
    obj, scene, unit = load_rig(args)
    props = scene.humananim_walk
    props.armature = obj
    if args.style not in PRESETS:
        raise UsageError(f"--style: unknown style '{args.style}' (styles: {', '.join(PRESETS)})")
    props.preset = args.style.upper()
    if args.set:
        walking.apply_preset(props, args.style)
    for item in args.set:
        name, _, value = item.partition("=")
        if name not in walking.STYLE_FIELDS:
            raise UsageError(f"--set {item!r}: unknown parameter (parameters: {', '.join(walking.STYLE_FIELDS)})")
        try:
            setattr(props, name, FINITE(value))
        except Exception:
            raise UsageError(f"--set {item!r}: the value must be a number") from None
    _choose_path(args, bpy, scene, obj, props, walking)
    if args.ground:
        props.ground = _object(bpy, args.ground, "--ground", "MESH")
    elif args.bumps:
        props.ground = bumpy_ground(scene, args.bumps)
    props.frame_start = args.frame_start
    from ...solver.progress import run_to_end
    summary = run_to_end(walking.run(obj, scene))
    for text in args.generator:
        _add_generator(text, bpy, obj, scene, walking)
    summary["stack"] = walking.stack_summary(obj)
    from ..cli import save_blend
    out = save_blend(args.out, summary, obj)
    summary.update(command="walk", file=os.path.abspath(args.file), wrote=[out],
                   seconds=round(time.perf_counter() - t0, 3))
    if unit:
        summary["bvh_unit"] = unit
    summary["summary"] = text_summary(summary)
    return summary


def _object(bpy, name, option, kind=None):
    obj = bpy.data.objects.get(name)
    if obj is None or (kind and obj.type != kind):
        raise UsageError(f"{option}: no {kind.lower() + ' ' if kind else ''}object named '{name}'")
    return obj


def _choose_path(args, bpy, scene, obj, props, walking):
    if args.keyed:
        props.path_mode, props.path = "KEYED", _object(bpy, args.keyed, "--keyed")
        return
    props.path_mode = "CURVE"
    if args.path:
        props.path = _object(bpy, args.path, "--path", "CURVE")
    else:
        start = tuple(obj.matrix_world.translation)[:2]
        props.path = s_curve_object(scene, args.s_curve, args.s_amplitude, start) if args.s_curve \
            else line_object(scene, args.line or 5.0, start)
    if args.speed_keys:
        _check_speeds("--speed-keys", args.speed_keys, keyed=True)
        props.speed_mode, props.speed_keys = "KEYED", args.speed_keys
    elif args.segment_speeds:
        _check_speeds("--segment-speeds", args.segment_speeds)
        props.speed_mode, props.segment_speeds = "SEGMENTS", args.segment_speeds
    else:
        props.speed_mode, props.speed = "CONSTANT", args.speed or 1.3


def _check_speeds(option, text, keyed=False):
    """Every speed positive and finite (S:V pairs with distances >= 0 when keyed)."""
    try:
        for item in text.split(","):
            if keyed:
                distance, _, speed = item.partition(":")
                NON_NEGATIVE(distance)
            else:
                speed = item
            POSITIVE(speed)
    except Exception:
        raise UsageError(f"{option} {text!r}: expected " + ("DISTANCE:SPEED pairs (distance >= 0 m, speed > 0 m/s)" if keyed
                                                           else "speeds > 0 m/s") + " separated by commas") from None


def _add_generator(text, bpy, obj, scene, walking):
    parts = text.split(":")
    if len(parts) < 3:
        raise UsageError(f"--generator {text!r}: expected ACTION:SCOPE:FRAME[:PRIORITY[:WEIGHT]]")
    action = bpy.data.actions.get(parts[0])
    if action is None:
        raise UsageError(f"--generator {text!r}: no action named '{parts[0]}'")
    try:
        frame = float(parts[2])
        weight = float(parts[4]) if len(parts) > 4 else 1.0
    except ValueError:
        raise UsageError(f"--generator {text!r}: FRAME and WEIGHT are numbers") from None
    priority = parts[3] if len(parts) > 3 else "default"
    walking.add_generator(obj, scene, action, parts[1], frame, priority, weight)


def _curve(scene, name, points):
    import bpy
    data = bpy.data.curves.new(name, "CURVE")
    data.dimensions = "3D"
    spline = data.splines.new("POLY")
    spline.points.add(len(points) - 1)
    for p, co in zip(spline.points, points):
        p.co = (co[0], co[1], co[2], 1.0)
    obj = bpy.data.objects.new(name, data)
    scene.collection.objects.link(obj)
    return obj


def line_object(scene, length, start=(0.0, 0.0)):
    """A straight path of `length` (scene units) along +X from `start`."""
    return _curve(scene, "WalkLine", [(start[0], start[1], 0.0), (start[0] + length, start[1], 0.0)])


def s_curve_object(scene, length, amplitude=1.0, start=(0.0, 0.0), n=64):
    """An S curve: one period of a sine along +X."""
    import numpy as np
    x = np.linspace(0.0, length, n)
    y = amplitude * np.sin(2 * np.pi * x / length)
    return _curve(scene, "WalkS", [(start[0] + a, start[1] + b, 0.0) for a, b in zip(x, y)])


def bumpy_ground(scene, amplitude, size=40.0, n=160):
    """A grid mesh (size x size, centred on the origin) with smooth bumps of `amplitude`."""
    import bpy
    import numpy as np
    xs = np.linspace(-size / 2, size / 2, n + 1)
    gx, gy = np.meshgrid(xs, xs, indexing="ij")
    gz = amplitude * (np.sin(1.3 * gx) * np.cos(0.9 * gy) + 0.5 * np.sin(3.1 * gx + 0.5))
    verts = np.column_stack((gx.ravel(), gy.ravel(), gz.ravel()))
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    faces = np.column_stack((idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()))
    mesh = bpy.data.meshes.new("Bumps")
    mesh.from_pydata(verts.tolist(), [], faces.tolist())
    obj = bpy.data.objects.new("Bumps", mesh)
    scene.collection.objects.link(obj)
    return obj


def text_summary(s):
    lines = [f"walk: '{s['armature']}' walked '{s['path']}' in {s['steps']} steps, {s['walk_seconds']:.2f} s of walk "
             f"(frames {s['frame_range'][0]:g}-{s['frame_range'][1]:g}), generated in {s['generate_seconds']:.2f} s "
             f"({s['ms_per_walk_second']:.0f} ms per second of walk)",
             f"  thigh height {s['thigh_height_m']:.3f} m; cycle length within {100 * s['cycle_length_error_max']:.1f} % "
             f"of 1.346 sqrt(RV) over {s['cycles']} cycles; double support {100 * s['double_support_share']:.0f} %"
             + (f"; {s['flight_frames']} frames of flight" if s["flight_frames"] else ""),
             f"  feet slide {s['max_foot_slip_mm']:.2f} mm at most, root within {s['max_root_deviation_cm']:.1f} cm "
             f"of the path, knees flexed {s['min_knee_flexion_deg']:.1f} deg at least",
             f"  wrote action '{s['action']}' with {s['supports']} support intervals"]
    for item in s.get("stack", []):
        lines.append(f"  strip '{item['action']}' on '{item['track']}': frames {item['frame_start']:g}-"
                     f"{item['frame_end']:g}, {item['bones']} bones, influence {item['influence']:.2f}")
    for path in s["wrote"]:
        lines.append(f"  wrote {path}")
    lines.append(f"  took {s['seconds']:.2f} s")
    return "\n".join(lines)
