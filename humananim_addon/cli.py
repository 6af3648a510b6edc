"""The batch command line: `python -m humananim <command>` and `blender --command humananim <command>`.

Every command prints a short summary, or with --json one JSON object of what it did, where it
wrote and what it measured. A user mistake is one line on stderr and exit status 2."""

import argparse
import importlib
import contextlib
import json
import logging
import os
import sys
import time

import numpy as np

DEFAULT_CLIP = os.path.join(os.path.dirname(__file__), "data", "mocap", "cmu_131_01.bvh")
log = logging.getLogger(__name__)


class UsageError(Exception):
    """A mistake in the command line or its files: reported in one line."""


def build_parser():
    parser = argparse.ArgumentParser(prog="humananim", description="HumanAnim batch jobs")
    sub = parser.add_subparsers(dest="command", required=True, metavar="command")
    info = sub.add_parser("info", help="bones, body roles, segment masses, frames of a rig")
    info.add_argument("file", help="a .blend or .bvh file")
    info.add_argument("--armature", help="the armature object in a .blend (default: the only one)")
    _common(info)
    demo = sub.add_parser("demo", help="import the bundled CMU clip, build the body model, save a .blend")
    demo.add_argument("--bvh", default=DEFAULT_CLIP, help="motion to import (default: bundled CMU 131_01)")
    demo.add_argument("--out", default=os.path.join("out", "demo.blend"), help="the .blend to write")
    _common(demo)
    sim = sub.add_parser("simulate", help="closed-loop simulation: the rig follows its action under "
                                          "gravity, loads and pushes; writes a new action")
    sim.add_argument("file", help="a .blend or .bvh file")
    sim.add_argument("--armature", help="the armature object in a .blend (default: the only one)")
    sim.add_argument("--action", help="source action (default: the armature's active action)")
    sim.add_argument("--frames", nargs=2, type=int, metavar=("START", "END"), help="frame range")
    sim.add_argument("--tracking", type=float, default=1.0, help="0 ragdoll .. 1 full tracking (default 1)")
    sim.add_argument("--controller", choices=("inverse_dynamics", "pd"), default="inverse_dynamics")
    sim.add_argument("--balance-assist", type=float, default=1.0,
                     help="share of the pelvis force the feet can't give that is applied anyway (default 1)")
    sim.add_argument("--strength", type=float, default=1.0, help="muscle strength scale (default 1)")
    sim.add_argument("--ground", type=float, help="ground height in metres (default: the lowest "
                                                  "point the feet reach in the motion)")
    sim.add_argument("--load-left", type=float, default=0.0, help="kg carried in the left hand")
    sim.add_argument("--load-right", type=float, default=0.0, help="kg carried in the right hand")
    sim.add_argument("--push", action="append", default=[], metavar="FRAME:BONE:FX,FY,FZ[:SECONDS]",
                     help="a push of the force vector (N, world axes) on a bone; repeatable")
    sim.add_argument("--output", choices=("ACTION", "NLA"), default="ACTION")
    sim.add_argument("--out", default=os.path.join("out", "simulate.blend"), help="the .blend to write")
    _common(sim)
    for name in COMMAND_MODULES:  # each capability module adds its own commands
        module = importlib.import_module(f".{name}", __package__)
        COMMANDS.update(module.add_commands(sub, _common))
    return parser


def _common(p):
    p.add_argument("--mass", type=float, help="total body mass in kg (default 70)")
    p.add_argument("--scale", type=float, help="metres per BVH unit (default: guessed)")
    p.add_argument("--json", action="store_true", help="print one JSON object")


def main(argv=None):
    logging.basicConfig(level=logging.WARNING, format="humananim: %(levelname)s: %(message)s")
    parser = build_parser()
    args = parser.parse_args(argv)
    from ..solver.errors import HumanAnimError
    try:
        with _chatter_to_stderr(), _registered():
            result = COMMANDS[args.command](args)
    except (HumanAnimError, UsageError) as error:
        print(f"humananim {args.command}: error: {error}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(result, indent=1))
    else:
        print(_text_summary(result))
    return 0


@contextlib.contextmanager
def _chatter_to_stderr():
    """Blender's importers print progress on stdout (from C and Python): send it to stderr so
    stdout carries only the summary or the JSON object."""
    sys.stdout.flush()
    saved = os.dup(1)
    os.dup2(2, 1)
    try:
        with contextlib.redirect_stdout(sys.stderr):
            yield
    finally:
        sys.stdout.flush()
        os.dup2(saved, 1)
        os.close(saved)


def blender_command(argv):
    """Handler for `blender --command humananim ...`."""
    try:
        return main(list(argv))
    except SystemExit as stop:  # argparse's --help and usage errors
        return int(stop.code or 0)


@contextlib.contextmanager
def _registered():
    """In the bpy module the add-on is not enabled: register it for the command, and
    unregister after (classes left registered crash bpy 4.2 at exit)."""
    import bpy
    if hasattr(bpy.types.Armature, "humananim"):
        yield
        return
    from .. import register, unregister
    register()
    try:
        yield
    finally:
        unregister()


def cmd_info(args):
    t0 = time.perf_counter()
    obj, scene, imported = _load(args.file, args.armature, args.scale)
    result = rig_summary(obj, scene, args.mass)
    result.update(command="info", file=os.path.abspath(args.file), seconds=round(time.perf_counter() - t0, 3))
    if imported:
        result["bvh_unit"] = imported
    return result


def cmd_demo(args):
    import bpy
    from . import mass_model
    from .armature import skeleton_from_armature
    from .bvh_import import import_bvh
    t0 = time.perf_counter()
    bpy.ops.wm.read_homefile(use_empty=True)
    obj, scale, unit = import_bvh(args.bvh, args.scale)
    scene = bpy.context.scene
    skeleton = skeleton_from_armature(obj, scene, args.mass)
    mass_model.store(obj.data.humananim, skeleton, skeleton.mass, skeleton.com, skeleton.inertia)
    result = rig_summary(obj, scene, args.mass)  # of the source motion, before control adds an action
    out = os.path.abspath(args.out)
    control = demo_control(obj, scene, skeleton, out)
    skirts = demo_cloth(obj, scene, out, args.scale)
    result.update(command="demo", input=os.path.abspath(args.bvh), bvh_unit=unit,
                  wrote=[out] + [path for s in skirts for path in s["wrote"]], picture=control["wrote"][1],
                  control=control, cloth=skirts, seconds=round(time.perf_counter() - t0, 3))
    from .control_cli import text_summary
    result["summary"] = "\n".join(
        [_text_summary(result)] + ["  " + line for line in text_summary(control).splitlines()[:-1]]
        + [f"  cloth: '{s['object']}' on '{s['armature']}', {s['particles']} particles to {s['fine_faces']} "
           f"faces, {s['frames']} frames at {s['timing_ms_per_frame'].get('total_ms', float('nan')):.1f} ms per "
           f"frame, deepest inside the body {s['max_depth_inside_mm']:.1f} mm" for s in skirts])
    return result


DEMO_FRAMES = (1, 200)  # the start of the walk: standing, shuffling (the thesis's method is for double support)
DEMO_LOAD_KG = 5.0  # in each hand
DEMO_PUSH = (120, 15.0)  # frame, N s backwards on the chest


DEMO_HOP = os.path.join(os.path.dirname(__file__), "data", "mocap", "cmu_131_03.bvh")


def demo_cloth(walker, scene, out, scale=None):
    """A generated skirt on the walk and on the hop (imported beside it, 1.5 m to the side), each
    on a skinned capsule body, simulated over the demo frames; point caches beside the .blend."""
    import bpy
    from ..solver.progress import run_to_end
    from . import cloth
    from .bvh_import import import_bvh
    bpy.ops.wm.save_as_mainfile(filepath=out)  # the caches' relative paths need the .blend's folder
    hopper, _, _ = import_bvh(DEMO_HOP, scale)
    hopper.location.x += 1.5
    summaries = []
    for arm in (walker, hopper):
        cloth.add_skirt(arm, scene, name=f"{arm.name}.skirt", frame=DEMO_FRAMES[0])
        props = scene.humananim_cloth
        props.body = cloth.add_capsule_body(arm, scene, name=f"{arm.name}.body")
        props.frame_start, props.frame_end = DEMO_FRAMES
        props.cache_dir = "//" + os.path.splitext(os.path.basename(out))[0] + "_cache"
        summary = run_to_end(cloth.run(scene))
        summary["armature"] = arm.name
        summaries.append(summary)
    scene.frame_set(DEMO_FRAMES[0])
    bpy.ops.wm.save_as_mainfile(filepath=out)
    return summaries


def demo_control(obj, scene, skeleton, out):
    """Dynamic control of the demo clip with a load in both hands and a push on the chest; saves
    the .blend at `out` and a picture beside it."""
    from mathutils import Vector
    from .control_cli import add_impulse_from_vector, control_and_save
    props = scene.humananim_control
    props.frame_start, props.frame_end = DEMO_FRAMES
    props.load_left = props.load_right = DEMO_LOAD_KG
    frame, magnitude = DEMO_PUSH
    backwards = obj.matrix_world.to_3x3() @ Vector((0.0, 1.0, 0.0))  # into the front of the chest
    add_impulse_from_vector(obj, scene, skeleton.roles.bone("chest"), frame, magnitude * backwards.normalized())
    return control_and_save(obj, scene, out, os.path.splitext(out)[0] + ".png")


def cmd_simulate(args):
    import bpy
    from ..solver.progress import run_to_end
    from . import simulation
    t0 = time.perf_counter()
    obj, scene, unit = load_job(args, "humananim_simulation")
    props = scene.humananim_simulation
    props.tracking, props.controller = args.tracking, args.controller.upper()
    props.balance_assist, props.strength_scale = args.balance_assist, args.strength
    props.ground = "MOTION" if args.ground is None else "HEIGHT"
    props.ground_height = args.ground or 0.0
    props.load_left, props.load_right = args.load_left, args.load_right
    scene.humananim.output = args.output
    for text in args.push:
        frame, bone, force, seconds = parse_arrow(text, obj, "--push", 0.1)
        simulation.add_push(obj, scene, bone, frame, force, float(np.linalg.norm(force)), seconds)
    summary = run_to_end(simulation.run(obj, scene))
    out = os.path.abspath(args.out)
    os.makedirs(os.path.dirname(out), exist_ok=True)
    bpy.ops.wm.save_as_mainfile(filepath=out)
    summary.update(command="simulate", file=os.path.abspath(args.file), armature=obj.name, wrote=[out],
                   seconds=round(time.perf_counter() - t0, 3))
    if unit:
        summary["bvh_unit"] = unit
    return summary


def parse_arrow(text, obj, option, default_seconds):
    """FRAME:BONE:FX,FY,FZ[:SECONDS] of --push and --impulse: (frame, bone, vector, seconds)."""
    parts = text.split(":")
    try:
        frame, bone, vector = int(parts[0]), parts[1], np.array([float(v) for v in parts[2].split(",")])
        seconds = float(parts[3]) if len(parts) > 3 else default_seconds
        if len(parts) > 4:
            raise ValueError
    except (IndexError, ValueError):
        raise UsageError(f"{option} {text!r}: expected FRAME:BONE:FX,FY,FZ[:SECONDS]") from None
    if bone not in obj.data.bones:
        raise UsageError(f"{option} {text!r}: no bone named '{bone}'")
    if vector.shape != (3,) or not np.isfinite(vector).all() or not np.linalg.norm(vector) > 0.0:
        raise UsageError(f"{option} {text!r}: the vector needs three finite components FX,FY,FZ, not all zero")
    if seconds < 0.0:
        raise UsageError(f"{option} {text!r}: SECONDS can't be negative")
    return frame, bone, vector, seconds


def load_job(args, props):
    """The file, mass, source action and frame range of a simulate/control command, set on
    the command's settings group: (armature, scene, BVH unit or None)."""
    import bpy
    obj, scene, unit = load_rig(args)
    props = getattr(scene, props)
    if args.action:
        props.action = bpy.data.actions.get(args.action)
        if props.action is None:
            raise UsageError(f"no action named '{args.action}'")
    if args.frames:
        props.frame_start, props.frame_end = args.frames
    return obj, scene, unit


def load_rig(args):
    """A dynamics command's file (a .blend, or a BVH imported into an empty scene) and armature,
    with --mass set on the rig: (armature, scene, BVH unit or None)."""
    obj, scene, unit = _load(args.file, args.armature, args.scale)
    if args.mass:
        obj.data.humananim.total_mass = args.mass
    return obj, scene, unit


def _load(path, armature_name, scale):
    import bpy
    from .bvh_import import import_bvh
    if not os.path.isfile(path):
        raise UsageError(f"no such file: {path}")
    if path.lower().endswith(".fbx"):  # Blender's own FBX importer (the rig layer's bridge)
        from .rig.load import load_fbx
        return load_fbx(path, armature_name)
    if path.lower().endswith(".bvh"):
        bpy.ops.wm.read_homefile(use_empty=True)
        obj, _, unit = import_bvh(path, scale)
        return obj, bpy.context.scene, unit
    try:
        bpy.ops.wm.open_mainfile(filepath=os.path.abspath(path))
    except RuntimeError as error:
        raise UsageError(f"cannot open {os.path.basename(path)}: {str(error).splitlines()[0]}") from None
    armatures = [o for o in bpy.data.objects if o.type == "ARMATURE"]
    if armature_name:
        obj = bpy.data.objects.get(armature_name)
        if obj is None or obj.type != "ARMATURE":
            raise UsageError(f"no armature named '{armature_name}' (armatures: "
                             f"{', '.join(o.name for o in armatures) or 'none'})")
    elif len(armatures) == 1:
        obj = armatures[0]
    else:
        raise UsageError(f"{len(armatures)} armatures in the file: pass --armature "
                         f"({', '.join(o.name for o in armatures)})" if armatures else "no armature in the file")
    scene = obj.users_scene[0] if obj.users_scene else bpy.context.scene
    return obj, scene, None


def rig_summary(obj, scene, total_mass=None):
    """What a rig is to HumanAnim: bones, roles, masses, frames."""
    from ..solver.errors import RigError
    from .actions import scene_fps
    from .armature import detect, skeleton_from_armature
    from .properties import role_overrides
    detection = detect(obj)
    roles = detection.roles.with_overrides(role_overrides(obj.data.humananim))
    result = {"armature": obj.name, "bone_count": len(obj.data.bones),
              "bones": [b.name for b in obj.data.bones], "convention": detection.convention,
              "roles": roles.to_dict(), "missing_roles": roles.missing(), "segments": {}}
    try:
        skeleton = skeleton_from_armature(obj, scene, total_mass, detection=detection)
    except RigError as error:
        result["refused"] = str(error)
    else:
        result["unit_scale_m"] = skeleton.unit_scale
        result["segments"] = {name: {"role": roles.role_of(name), "mass_kg": round(float(m), 4)}
                              for name, m in zip(skeleton.names, skeleton.mass) if m > 0}
        result["total_mass_kg"] = round(skeleton.total_mass, 4)
    action = obj.animation_data.action if obj.animation_data else None
    result["action"] = action.name if action else None
    result["frame_range"] = [float(v) for v in action.frame_range] if action else None
    result["fps"] = round(scene_fps(scene), 4)
    return result


def _text_summary(r):
    if "summary" in r:  # a command that phrases its own summary
        return r["summary"]
    if r["command"] == "simulate":
        return "\n".join([
            f"simulate: '{r['armature']}' followed '{r['source_action']}' for {r['frames']} frames "
            f"({r['simulated_seconds']:.2f} s) in {r['seconds']:.2f} s, {r['real_time_factor']:.2f}x real time",
            f"  tracking error {r['tracking_error_deg_rms']:.2f} deg RMS, peak strength use "
            f"{r['peak_strength_usage']:.2f}, peak balance assist {r['peak_balance_assist_n']:.0f} N",
            f"  wrote action '{r['action']}' and {r['wrote'][0]}"])
    lines = [f"{r['command']}: armature '{r['armature']}', {r['bone_count']} bones, "
             f"roles by {r['convention']}"]
    if r.get("missing_roles"):
        lines.append(f"  missing roles: {', '.join(r['missing_roles'])}")
    if r.get("refused"):
        lines.append(f"  refused: {r['refused']}")
    if r.get("total_mass_kg") is not None:
        lines.append(f"  mass: {r['total_mass_kg']:.1f} kg in {len(r['segments'])} segments")
    if r.get("action"):
        lines.append(f"  action '{r['action']}': frames {r['frame_range'][0]:g}-{r['frame_range'][1]:g} "
                     f"at {r['fps']:g} fps")
    for path in r.get("wrote", []):
        lines.append(f"  wrote {path}")
    lines.append(f"  took {r['seconds']:.2f} s")
    return "\n".join(lines)


COMMANDS = {"info": cmd_info, "demo": cmd_demo, "simulate": cmd_simulate}
# Modules of this package with `add_commands(subparsers, add_common_options) -> {name: run(args)}`;
# `run` returns the summary dict (with "command" and "wrote") and raises HumanAnimError/UsageError.
COMMAND_MODULES = ("sequence_cli", "control_cli", "cloth_cli", "flexible_cli", "walking_cli", "capture_cli",
                   "hands_cli", "synthesis_cli", "batch")
