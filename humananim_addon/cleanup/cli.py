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
    c.add_argument("--physics", action="store_true",
                   help="the optional physical pass: the result run through dynamic control, tracking only "
                        "(balance error reported)")
    c.add_argument("--jitter-hz", type=POSITIVE, default=6.0, help="jitter low-pass cut-off in Hz (default 6)")
    c.add_argument("--jitter-strength", type=FRACTION, default=1.0, help="0-1: how much jitter to remove (default 1)")
    c.add_argument("--glitch-strength", type=POSITIVE, default=1.0,
                   help="glitch sensitivity: the speed limits are divided by it (default 1)")
    c.add_argument("--ground", type=FINITE, default=0.0, help="floor height in metres the feet are put on (default 0)")
    c.add_argument("--ground-mesh", metavar="FILE",
                   help="put the feet on this ground instead of a flat floor: an .obj mesh (Y up, as Blender "
                        "exports it), or a height field (.npz with 'heights', 'cell', 'origin'; or a grid in "
                        ".npy/.csv/.txt with --ground-cell)")
    c.add_argument("--ground-object", metavar="NAME", help="put the feet on this mesh object of the .blend")
    c.add_argument("--ground-cell", type=POSITIVE, help="a height grid's spacing in metres")
    c.add_argument("--ground-origin", type=FINITE, nargs=2, default=(0.0, 0.0), metavar=("X", "Y"),
                   help="a height grid's first point (metres, default 0 0)")
    c.add_argument("--ground-z-up", action="store_true", help="the .obj was written Z up")
    add_common_options(c)
    return {"cleanup": cmd_cleanup}


def options(args, ground=None):
    from ...solver.cleanup import Options
    return Options(glitches=not args.no_glitches, jitter=not args.no_jitter, floor=not args.no_floor,
                   skate=not args.no_skate, physics=args.physics, glitch_strength=args.glitch_strength,
                   jitter_strength=args.jitter_strength, jitter_hz=args.jitter_hz,
                   ground=args.ground if ground is None else ground)


def ground_of(args):
    """The ground surface asked for (--ground-mesh FILE or --ground-object NAME), or None."""
    if args.ground_mesh and args.ground_object:
        raise UsageError("give --ground-mesh or --ground-object, not both")
    if args.ground_object:
        import bpy
        from . import ground_from_object
        obj = bpy.data.objects.get(args.ground_object)
        if obj is None:
            raise UsageError(f"no object named '{args.ground_object}' for the ground")
        return ground_from_object(obj)
    if args.ground_mesh:
        from ...solver.cleanup import ground
        if not os.path.isfile(args.ground_mesh):
            raise UsageError(f"no ground file {args.ground_mesh}")
        try:
            return ground.load(args.ground_mesh, y_up=not args.ground_z_up, cell=args.ground_cell,
                               origin=args.ground_origin)
        except (ValueError, OSError) as error:
            raise UsageError(f"--ground-mesh: {error}") from None
    return None


def cmd_cleanup(args):
    import bpy
    from ..cli import _load, save_blend
    from . import active_action, assign, clean_action, lines
    t0 = time.perf_counter()
    surface = None if args.ground_object else ground_of(args)  # a broken ground file: refused first
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
    surface = ground_of(args) if args.ground_object else surface
    summary = clean_action(obj, scene, action, options(args, surface))
    out = save_blend(args.out, summary, obj, args.ground if surface is None else None)
    summary.update(file=os.path.abspath(args.file), wrote=[out], seconds=round(time.perf_counter() - t0, 3))
    if unit:
        summary["bvh_unit"] = unit
    summary["summary"] = "\n".join(
        [f"cleanup: '{obj.name}' action '{action.name}' -> new action '{summary['action']}', "
         f"{summary['markers']} contact markers"] + [f"  {line}" for line in lines(summary["report"])]
        + [f"  wrote {out}", f"  took {summary['seconds']:.2f} s"])
    return summary
