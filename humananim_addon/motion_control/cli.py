"""Batch dynamic motion control: `python -m humananim control clip.bvh --load-left 8 ...`.

Runs the same bridge code as the Dynamic Control panel, saves a .blend (--out), optionally a
picture of the result (--picture), and prints a summary (--json: one object)."""

import os
import time

import numpy as np

from ..arguments import (COUNT, UsageError, add_arrows, add_collider, add_ground_height, add_input, add_loads,
                         add_out, add_output, add_source, add_strength)


def add_commands(sub, add_common_options):
    c = sub.add_parser("control", help="dynamic motion control: the motion is kept and reacts to loads, "
                                       "impulses and collisions; writes a new action with stress curves")
    add_input(c)
    add_source(c)
    add_loads(c, pick_up=True)
    add_arrows(c, "--impulse", "an impulse (N s, world axes) on a bone, or with SECONDS a force (N) over that "
                               "time; repeatable")
    add_collider(c, "an armature or mesh object in the .blend to collide with")
    c.add_argument("--collide-spheres", type=COUNT, default=1, help="spheres covering a colliding mesh (default 1)")
    add_strength(c)
    c.add_argument("--substeps", type=COUNT, default=1, help="control steps per frame (default 1)")
    c.add_argument("--tracking-only", action="store_true", help="no comfort or balance control (to compare)")
    add_ground_height(c, "ground height in metres (default: the motion's floor)")
    add_output(c)
    add_out(c, "control.blend")
    c.add_argument("--picture", metavar="PNG", help="also render a picture of the result")
    add_common_options(c)
    return {"control": cmd_control}


def cmd_control(args):
    import bpy
    from ..cli import load_job, parse_arrow, set_loads_and_ground
    t0 = time.perf_counter()
    obj, scene, unit = load_job(args, "humananim_control")
    props = scene.humananim_control
    if args.collide:
        other = bpy.data.objects.get(args.collide)
        if other is None:
            raise UsageError(f"--collide: no object named '{args.collide}'")
        props.collider = other
    props.collider_radius, props.collider_spheres = args.collide_radius, max(1, args.collide_spheres)
    set_loads_and_ground(args, props)
    props.load_frame, props.substeps, props.tracking_only = args.load_frame, args.substeps, args.tracking_only
    scene.humananim.output = args.output
    for text in args.impulse:
        frame, bone, vector, seconds = parse_arrow(text, obj, "--impulse", 0.0)
        add_impulse_from_vector(obj, scene, bone, frame, vector, seconds)
    from .. import validation
    validation.check_job(obj, props, "impulses")
    summary = control_and_save(obj, scene, args.out, args.picture, ground=args.ground)
    summary.update(command="control", file=os.path.abspath(args.file), armature=obj.name,
                   seconds=round(time.perf_counter() - t0, 3))
    if unit:
        summary["bvh_unit"] = unit
    summary["summary"] = text_summary(summary)
    return summary


def add_impulse_from_vector(obj, scene, bone, frame, vector, seconds=0.0):
    """An impulse (N s) along `vector`, or a force (N) over `seconds`: its length is the magnitude."""
    from . import job as motion_control
    vector = np.asarray(vector, float)
    return motion_control.add_impulse(obj, scene, bone, frame, vector, float(np.linalg.norm(vector)), seconds)


def control_and_save(obj, scene, out, picture=None, title=None, ground=None):
    """Run the job, measure it (the motion QA), save the .blend, render the picture; the summary
    with `wrote` and `qa`."""
    from ...solver.progress import run_to_end
    from . import job as motion_control
    from . import overlay
    from ..cli import save_blend, write_atomically
    summary = run_to_end(motion_control.run(obj, scene))
    summary["armature"] = obj.name
    out = save_blend(out, summary, obj, ground)
    wrote = [out]
    if picture:
        title = title or _title(summary)

        def render(path):
            summary["picture_frames"] = overlay.render_result(obj, scene, summary["action"], path, title=title)
        wrote.append(write_atomically(picture, render))
    summary["wrote"] = wrote
    return summary


def _title(s):
    loads = " + ".join(f"{kg:g} kg" for kg in s["loads_kg"].values())
    parts = [f"'{s['source_action']}' under dynamic control"]
    if loads:
        parts.append(f"carrying {loads}")
    if s["impulses"]:
        parts.append(f"{s['impulses']} push{'es' if s['impulses'] > 1 else ''}")
    if s["colliders"]:
        parts.append(f"colliding with {', '.join(s['colliders'])}")
    return ", ".join(parts) + f" (frames {s['frame_range'][0]:g}-{s['frame_range'][1]:g})"


def text_summary(s):
    lines = [f"control: '{s['armature']}' kept '{s['source_action']}' for {s['frames']} frames "
             f"({s['simulated_seconds']:.2f} s) in {s['control_seconds']:.2f} s, {s['real_time_factor']:.2f}x real time"]
    if s["loads_kg"] or s["impulses"] or s["colliders"]:
        lines.append("  loads " + (", ".join(f"{b} {kg:g} kg" for b, kg in s["loads_kg"].items()) or "none")
                     + f"; {s['impulses']} impulses; colliders: {', '.join(s['colliders']) or 'none'}")
    lines.append(f"  peak stress {s['peak_stress_nm']:.1f} N m ({s['peak_stress_bone']}, frame "
                 f"{s['peak_stress_frame']:g}), balance error up to {100 * s['max_balance_error_m']:.1f} cm, "
                 f"{s['frames_falling']} frames falling, foot slide up to {s['max_foot_slide_mm']:.1f} mm")
    controlled = s["frames_controlled"]
    lines.append("  frames with control: " + ", ".join(f"{k} {v}" for k, v in controlled.items()))
    lines.append(f"  wrote action '{s['action']}'")
    for path in s["wrote"]:
        lines.append(f"  wrote {path}")
    lines.append(f"  took {s['seconds']:.2f} s")
    return "\n".join(lines)
