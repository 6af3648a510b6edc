"""Batch closed-loop simulation: `python -m humananim simulate clip.bvh --push 30:Chest:0,-300,0 ...`.

Runs the same bridge code as the Simulation panel, saves a .blend (--out) and prints a summary
(--json: one object)."""

import os
import time

import numpy as np

from ..arguments import (FRACTION, NON_NEGATIVE, add_arrows, add_ground_height, add_input, add_loads,
                         add_out, add_output, add_source, add_strength)


def add_commands(sub, add_common_options):
    sim = sub.add_parser("simulate", help="closed-loop simulation: the rig follows its action under "
                                          "gravity, loads and pushes; writes a new action")
    add_input(sim)
    add_source(sim)
    sim.add_argument("--tracking", type=FRACTION, default=1.0, help="0 ragdoll .. 1 full tracking (default 1)")
    sim.add_argument("--controller", choices=("inverse_dynamics", "pd"), default="inverse_dynamics")
    sim.add_argument("--balance-assist", type=NON_NEGATIVE, default=1.0,
                     help="share of the pelvis force the feet can't give that is applied anyway (default 1)")
    add_strength(sim)
    add_ground_height(sim, "ground height in metres (default: the lowest point the feet reach in the motion)")
    add_loads(sim)
    add_arrows(sim, "--push", "a push of the force vector (N, world axes) on a bone; repeatable; BONE may hold "
                              "colons (10:mixamorig:Spine2:0,-300,0) or be in double quotes")
    add_output(sim)
    add_out(sim, "simulate.blend")
    add_common_options(sim)
    return {"simulate": cmd_simulate}


def cmd_simulate(args):
    from ...solver.progress import run_to_end
    from .. import validation
    from ..cli import load_job, parse_arrow, save_blend, set_loads_and_ground
    from . import job as simulation
    t0 = time.perf_counter()
    obj, scene, unit = load_job(args, "humananim_simulation")
    props = scene.humananim_simulation
    props.tracking, props.controller = args.tracking, args.controller.upper()
    props.balance_assist = args.balance_assist
    set_loads_and_ground(args, props)
    scene.humananim.output = args.output
    for text in args.push:
        frame, bone, force, seconds = parse_arrow(text, obj, "--push", 0.1)
        simulation.add_push(obj, scene, bone, frame, force, float(np.linalg.norm(force)), seconds)
    validation.check_job(obj, props, "pushes")
    summary = run_to_end(simulation.run(obj, scene))
    out = save_blend(args.out, summary, obj, args.ground)
    summary.update(command="simulate", file=os.path.abspath(args.file), armature=obj.name, wrote=[out],
                   seconds=round(time.perf_counter() - t0, 3))
    if unit:
        summary["bvh_unit"] = unit
    summary["summary"] = text_summary(summary)
    return summary


def text_summary(r):
    return "\n".join([
        f"simulate: '{r['armature']}' followed '{r['source_action']}' for {r['frames']} frames "
        f"({r['simulated_seconds']:.2f} s) in {r['seconds']:.2f} s, {r['real_time_factor']:.2f}x real time",
        f"  tracking error {r['tracking_error_deg_rms']:.2f} deg RMS, peak strength use "
        f"{r['peak_strength_usage']:.2f}, peak balance assist {r['peak_balance_assist_n']:.0f} N",
        f"  wrote action '{r['action']}' and {r['wrote'][0]}"])
