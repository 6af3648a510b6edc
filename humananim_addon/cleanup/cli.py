"""The `cleanup` command: python -m humananim cleanup FILE [--no-glitches --no-jitter --no-floor
--no-skate] [--jitter-hz HZ] --out OUT.blend --json. Reads a .blend (--armature, --action) or a
.bvh, writes a NEW action (the source untouched) into OUT.blend, prints the summary with the
`report` (per repair) and the motion QA (`qa`)."""

import os
import time

from ..arguments import FINITE, FRACTION, POSITIVE, UsageError, add_input, add_out


def add_commands(sub, add_common_options):
    c = sub.add_parser("cleanup", help="clean up capture: glitches, jitter, floor, foot skate (a new action)")
    add_input(c)
    c.add_argument("--action", help="source action (default: the armature's active action)")
    add_out(c, "cleanup.blend")
    for repair, what in (("glitches", "flips, spikes and dropouts"), ("jitter", "jitter"),
                         ("floor", "the floor"), ("skate", "foot skate")):
        c.add_argument(f"--no-{repair}", action="store_true", help=f"leave {what} as they are")
    c.add_argument("--jitter-hz", type=POSITIVE, default=6.0, help="jitter low-pass cut-off in Hz (default 6)")
    c.add_argument("--jitter-strength", type=FRACTION, default=1.0, help="0-1: how much jitter to remove (default 1)")
    c.add_argument("--glitch-strength", type=POSITIVE, default=1.0,
                   help="glitch sensitivity: the speed limits are divided by it (default 1)")
    c.add_argument("--ground", type=FINITE, default=0.0, help="floor height in metres the feet are put on (default 0)")
    add_common_options(c)
    return {"cleanup": cmd_cleanup}


def options(args):
    from ...solver.cleanup import Options
    return Options(glitches=not args.no_glitches, jitter=not args.no_jitter, floor=not args.no_floor,
                   skate=not args.no_skate, glitch_strength=args.glitch_strength,
                   jitter_strength=args.jitter_strength, jitter_hz=args.jitter_hz, ground=args.ground)


def cmd_cleanup(args):
    import bpy
    from ..cli import _load, save_blend
    from . import active_action, assign, clean_action, lines
    t0 = time.perf_counter()
    obj, scene, unit = _load(args.file, args.armature, args.scale)
    if args.action:
        action = bpy.data.actions.get(args.action)
        if action is None:
            raise UsageError(f"no action named '{args.action}'")
        assign(obj, action)
    else:
        action = active_action(obj)
        if action is None:
            raise UsageError(f"'{obj.name}' has no active action: pass --action")
    summary = clean_action(obj, scene, action, options(args))
    out = save_blend(args.out, summary, obj, args.ground)
    summary.update(file=os.path.abspath(args.file), wrote=[out], seconds=round(time.perf_counter() - t0, 3))
    if unit:
        summary["bvh_unit"] = unit
    summary["summary"] = "\n".join(
        [f"cleanup: '{obj.name}' action '{action.name}' -> new action '{summary['action']}', "
         f"{summary['markers']} contact markers"] + [f"  {line}" for line in lines(summary["report"])]
        + [f"  wrote {out}", f"  took {summary['seconds']:.2f} s"])
    return summary
