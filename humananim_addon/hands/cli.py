"""Batch grasping: `python -m humananim grasp scene.blend --object Mug [--side R] [--type WRAP] ...`.

Runs the same bridge code as the Hands panel's Grasp operator on a .blend holding an armature and
the object, saves the result (--out) and prints a summary (--json: one object)."""

import os
import time

from ..arguments import FRAME, POSITIVE, UsageError, add_out, number

TYPES = ("AUTO", "LATERAL", "PINCH", "TRIPOD", "WRAP", "DISK")


def add_commands(sub, add_common_options):
    g = sub.add_parser("grasp", help="reach for an object and close the fingers on it: a new action and the "
                                     "object held by the hand (keyed Child Of)")
    g.add_argument("file", help="a .blend with the armature and the object")
    g.add_argument("--object", required=True, help="the mesh object to grasp")
    g.add_argument("--armature", help="the armature object (default: the only one)")
    g.add_argument("--side", choices=("AUTO", "L", "R"), default="AUTO", help="hand (default: the nearer)")
    g.add_argument("--type", choices=TYPES, default="AUTO", help="grasp type (default: from the thesis's table)")
    g.add_argument("--start", type=FRAME, default=1, help="frame the reach starts (default 1)")
    g.add_argument("--reach", type=POSITIVE, default=1.0, help="seconds to reach (default 1)")
    g.add_argument("--close", type=POSITIVE, default=0.5, help="seconds to close the fingers (default 0.5)")
    g.add_argument("--release", type=number(0, integer=True), default=0, help="frame the object is let go (default: never)")
    g.add_argument("--spine", action="store_true", help="let the spine help the reach")
    add_out(g, "grasp.blend")
    add_common_options(g)
    return {"grasp": cmd_grasp}


def cmd_grasp(args):
    import bpy
    from ...solver.progress import run_to_end
    from . import job as hands
    from ..cli import load_rig
    t0 = time.perf_counter()
    obj, scene, _ = load_rig(args)
    target = bpy.data.objects.get(args.object)
    if target is None or target.type != "MESH":
        raise UsageError(f"--object: no mesh object named '{args.object}'")
    props = scene.humananim_hands
    props.side, props.grasp_type = args.side, args.type
    props.start_frame, props.duration, props.close_duration = args.start, args.reach, args.close
    props.release_frame, props.with_spine = args.release, args.spine
    summary = run_to_end(hands.run_grasp(obj, scene, target))
    from ..cli import save_blend
    out = save_blend(args.out, summary, obj)
    summary.update(command="grasp", file=os.path.abspath(args.file), armature=obj.name, wrote=[out],
                   seconds=round(time.perf_counter() - t0, 3))
    summary["summary"] = (f"grasp: '{obj.name}' {summary['type'].lower()} grasp of '{target.name}' "
                          f"({summary['primitive'].lower()}) with {' and '.join(summary['hands'])} hand(s), frames "
                          f"{summary['frames'][0]}-{summary['frames'][1]} -> action '{summary['action']}'\n"
                          f"  fingers touching: " + "; ".join(f"{k}: {', '.join(v)}" for k, v in
                                                             summary["fingers_touching"].items())
                          + f"\n  deepest finger {summary['max_penetration_mm']:.2f} mm, widest gap of a used finger "
                            f"{summary['max_finger_gap_mm']:.2f} mm\n"
                          + (f"  keyed on {len(summary['controls'])} controls of the control rig, switches "
                             + ", ".join(f"{k} = {v:g}" for k, v in summary["switches"].items()) + "\n"
                             if summary.get("controls") else "")
                          + f"  wrote {out}")
    return summary
