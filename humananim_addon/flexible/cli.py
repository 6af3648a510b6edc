"""Batch flexible characters: `python -m humananim flexible simulate|optimize FILE ...`.

FILE is a .blend holding an object deformed by a Lattice (or --demo: the thesis's table, made on
the spot). `simulate` bakes new actions (lattice transform, shape-key values); `optimize` runs
the simulated annealing, stores the best controller on the object (and with --bake bakes it).
Both save the .blend (--out) and print a summary (--json: one object)."""

import math
import os
import time

from ..arguments import COUNT, FINITE, FRAME, NON_NEGATIVE, POSITIVE, UsageError, add_frames, add_out

COST_NAMES = ("distance", "energy_distance", "energy_speed", "energy_sqrt_distance", "custom")


def add_commands(sub, add_common_options):
    f = sub.add_parser("flexible", help="flexible characters: simulate a lattice-deformed object and bake it, "
                                        "or search a pose-graph controller by simulated annealing")
    actions = f.add_subparsers(dest="flexible_command", required=True, metavar="action")
    sim = actions.add_parser("simulate", help="key-framed until --handover, simulated after; bakes new actions")
    opt = actions.add_parser("optimize", help="simulated annealing of the pose graph; stores the best controller")
    for p in (sim, opt):
        p.add_argument("file", nargs="?", help="a .blend with the character (omit with --demo)")
        p.add_argument("--demo", action="store_true", help="use a generated table character (thesis Fig. 1.2)")
        p.add_argument("--object", help="the character object (default: the only one with a Lattice modifier)")
        add_frames(p, "frame range to bake")
        p.add_argument("--integrator", choices=("implicit", "semi_implicit", "thesis"))
        p.add_argument("--substeps", type=COUNT, help="simulation steps per frame")
        p.add_argument("--ground", type=FINITE, help="ground height (m)")
        p.add_argument("--slope", type=FINITE, help="ground slope in degrees, rising along X")
        p.add_argument("--friction", type=NON_NEGATIVE, help="Coulomb friction coefficient")
        add_out(p, "flexible.blend")
        add_common_options(p)
    sim.add_argument("--handover", type=FRAME, help="frame the simulation takes over from the key-framing")
    sim.add_argument("--controller", choices=("POSES", "BEST"), help="pose graph as edited, or the best found")
    sim.add_argument("--passive", action="store_true", help="no pose control")
    opt.add_argument("--trials", type=COUNT, help="forward simulations (default: the object's, 60)")
    opt.add_argument("--seed", type=int, help="random seed (same seed, same result)")
    opt.add_argument("--cost", choices=COST_NAMES, help="cost function (thesis Table 5.1, or custom)")
    opt.add_argument("--optimize", choices=("both", "poses", "durations"), help="what the annealing changes")
    opt.add_argument("--trial-seconds", type=POSITIVE, help="simulated time per trial (default 12)")
    opt.add_argument("--trial-step", type=POSITIVE, help="time step of the trials (default 0.02 s)")
    opt.add_argument("--direction", nargs=3, type=FINITE, metavar=("X", "Y", "Z"), help="travel direction")
    opt.add_argument("--bake", action="store_true", help="also bake the best controller found")
    return {"flexible": cmd_flexible}


def cmd_flexible(args):
    import bpy
    from ...solver.progress import run_to_end
    from . import job as flexible
    t0 = time.perf_counter()
    obj, scene = _load(args)
    props = obj.humananim_flexible
    _apply_common(args, props)
    if args.flexible_command == "simulate":
        if args.handover is not None:
            props.handover_frame = args.handover
        if args.controller:
            props.controller = args.controller
        if args.passive:
            props.use_control = False
        summary = run_to_end(flexible.run(obj, scene))
    else:
        for name in ("trials", "seed", "cost", "optimize", "trial_seconds", "trial_step"):
            value = getattr(args, name)
            if value is not None:
                setattr(props, name, value)
        if args.direction:
            props.direction = args.direction
        summary = run_to_end(flexible.optimize(obj, scene))
        if args.bake:
            props.controller = "BEST"
            baked = run_to_end(flexible.run(obj, scene))
            summary["baked"] = {k: baked[k] for k in ("lattice_action", "key_action", "frames", "distance_m")
                                if k in baked}
    from ..cli import save_blend
    out = save_blend(args.out)
    summary.update(command=f"flexible {args.flexible_command}", wrote=[out],
                   file=os.path.abspath(args.file) if args.file else None,
                   total_seconds=round(time.perf_counter() - t0, 3))
    summary["summary"] = text_summary(summary)
    return summary


def _apply_common(args, props):
    if args.frames:
        if args.frames[1] <= args.frames[0]:
            raise UsageError("--frames: END must be after START")
        props.frame_start, props.frame_end = args.frames
        props.handover_frame = max(props.handover_frame, args.frames[0])
    if args.integrator:
        props.integrator = args.integrator
    if args.substeps is not None:
        if args.substeps < 1:
            raise UsageError("--substeps must be at least 1")
        props.substeps = args.substeps
    if args.ground is not None:
        props.ground_height = args.ground
    if args.slope is not None:
        props.ground_slope = math.radians(args.slope)
    if args.friction is not None:
        props.friction = args.friction
    if args.mass:
        props.mass = args.mass


def _load(args):
    import bpy
    from . import job as flexible
    if args.demo:
        if args.file:
            raise UsageError("give a FILE or --demo, not both")
        bpy.ops.wm.read_homefile(use_empty=True)
        obj, _ = flexible.create_demo_table(bpy.context)
        return obj, bpy.context.scene
    if not args.file:
        raise UsageError("give a .blend FILE with the character, or --demo")
    if not os.path.isfile(args.file):
        raise UsageError(f"no such file: {args.file}")
    try:
        bpy.ops.wm.open_mainfile(filepath=os.path.abspath(args.file))
    except RuntimeError as error:
        raise UsageError(f"cannot open {os.path.basename(args.file)}: {str(error).splitlines()[0]}") from None
    if args.object:
        obj = bpy.data.objects.get(args.object)
        if obj is None:
            raise UsageError(f"no object named '{args.object}'")
    else:
        found = [o for o in bpy.data.objects if any(m.type == "LATTICE" and m.object for m in getattr(o, "modifiers", ()))]
        if len(found) != 1:
            raise UsageError(f"{len(found)} objects with a Lattice modifier: pass --object"
                             + (f" ({', '.join(o.name for o in found)})" if found else ""))
        obj = found[0]
    scene = obj.users_scene[0] if obj.users_scene else bpy.context.scene
    return obj, scene


def text_summary(s):
    lines = [f"{s['command']}: '{s['object']}' in lattice '{s['lattice']}' {'x'.join(map(str, s['lattice_points']))}, "
             f"{s['points']} points, {s['mass_kg']:g} kg, modes {', '.join(s['modes'])} "
             f"(active: {', '.join(s['active_modes']) or 'none'})"]
    if s["command"].endswith("simulate"):
        lines.append(f"  frames {s['frame_range'][0]}-{s['frame_range'][1]}, simulated from {s['handover_frame']} "
                     f"({s['integrator']}, step {1000 * s['time_step_s']:.2f} ms), cond(M) <= {s['condition_number_max']}")
        if "distance_m" in s:
            lines.append(f"  moved {s['distance_m']:.3f} m along the direction, {s['energy_j']:.1f} J by the modes")
        lines.append(f"  wrote actions '{s['lattice_action']}'" + (f", '{s['key_action']}'" if "key_action" in s else "")
                     + (f", '{s['object_action']}'" if "object_action" in s else ""))
        for w in s["warnings"]:
            lines.append(f"  warning: {w}")
    else:
        lines.append(f"  {s['trials']} trials ({s['accepted']} accepted, {s['uphill']} uphill), cost "
                     f"{s['initial_cost']:.4g} -> {s['best_cost']:.4g} ({s['cost']}, seed {s['seed']})")
        lines.append(f"  best: {s['distance_m']:.3f} m forward, {s['energy_j']:.1f} J; durations "
                     f"{', '.join(f'{d:.3f}' for d in s['best_durations'])} s")
        if "baked" in s:
            lines.append(f"  baked '{s['baked']['lattice_action']}', '{s['baked'].get('key_action', '-')}'")
    lines.append(f"  wrote {s['wrote'][0]} in {s['total_seconds']:.2f} s")
    return "\n".join(lines)
