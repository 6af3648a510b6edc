"""The batch command line: `python -m humananim <command>` and `blender --command humananim <command>`.

Every command prints a short summary, or with --json one JSON object of what it did, where it
wrote and what it measured. A user mistake is one line on stderr and exit status 2."""

import importlib
import contextlib
import json
import logging
import math
import os
import sys
import time

import numpy as np

from .arguments import (COUNT, FINITE, FRACTION, FRAME, NON_NEGATIVE, POSITIVE, OneLineParser, UsageError,  # noqa: F401
                        add_common, add_input, add_out, fail, number, one_line)

DEFAULT_CLIP = os.path.join(os.path.dirname(__file__), "data", "mocap", "cmu_131_01.bvh")
log = logging.getLogger(__name__)


def build_parser():
    parser = OneLineParser(prog="humananim", description="HumanAnim batch jobs")
    sub = parser.add_subparsers(dest="command", required=True, metavar="command")
    info = sub.add_parser("info", help="bones, body roles, segment masses, frames of a rig")
    add_input(info, help="a .blend or .bvh file")
    add_common(info)
    demo = sub.add_parser("demo", help="import the bundled CMU clip, build the body model, save a .blend")
    demo.add_argument("--bvh", default=DEFAULT_CLIP, help="motion to import (default: bundled CMU 131_01)")
    add_out(demo, "demo.blend")
    add_common(demo)
    for name in COMMAND_MODULES:  # each capability module adds its own commands
        module = importlib.import_module(f".{name}", __package__)
        COMMANDS.update(module.add_commands(sub, add_common))
    return parser


def main(argv=None):
    logging.basicConfig(level=logging.WARNING, format="humananim: %(levelname)s: %(message)s")
    parser = build_parser()
    args = parser.parse_args(argv)
    from ..solver.errors import HumanAnimError
    name = f"humananim {args.command}"
    try:
        check_writable(args)
        with _chatter_to_stderr(), _registered():
            result = COMMANDS[args.command](args)
            if "qa" not in result:
                result["qa"] = qa_of_result(result)
    except (HumanAnimError, UsageError) as error:
        return fail(name, error)
    qa = result["qa"]
    for line in qa.get("warnings", []):
        print(f"{name}: warning: QA: {line}", file=sys.stderr)
    if args.json:
        print(json.dumps(result, indent=1))
    else:
        print(_text_summary(result) + "\n" + qa_text(qa))
    return 3 if getattr(args, "strict", False) and qa.get("passed") is False else 0


def check_writable(args):
    """--out and --picture can be written (checked before the work, so a long job does not end
    in an error): the nearest existing folder on the way must be writable."""
    for option in ("out", "picture"):
        path = getattr(args, option, None)
        if not path:
            continue
        path = os.path.abspath(path)
        if os.path.isdir(path):
            raise UsageError(f"--{option} {path}: is a folder, expected a file name")
        folder = os.path.dirname(path)
        while not os.path.exists(folder):
            folder = os.path.dirname(folder)
        if not os.path.isdir(folder) or not os.access(folder, os.W_OK | os.X_OK):
            raise UsageError(f"--{option} {path}: cannot write there ({folder} is not a writable folder)")


def write_atomically(out, write):
    """Call write(temporary path) for a file beside `out`, then rename it over `out`: a command
    that fails leaves nothing half-written and an older `out` as it was."""
    out = os.path.abspath(out)
    folder, base = os.path.split(out)
    try:
        os.makedirs(folder, exist_ok=True)
    except OSError as error:
        raise UsageError(f"cannot write {out}: {error.strerror}") from None
    stem, ext = os.path.splitext(base)
    tmp = os.path.join(folder, f".{stem}.{os.getpid()}.tmp{ext}")
    try:
        write(tmp)
        os.replace(tmp, out)
    except (OSError, RuntimeError) as error:
        raise UsageError(f"cannot write {out}: {getattr(error, 'strerror', None) or one_line(error)}") from None
    finally:
        for leftover in (tmp, tmp + "1"):  # and Blender's backup of an earlier save
            if os.path.exists(leftover):
                os.remove(leftover)
    return out


def save_blend(out, summary=None, obj=None, ground=None):
    """Save the session's .blend at `out` (atomically). With the command's `summary` and armature
    `obj`, first measure the result (the motion QA: summary["qa"], also stored on the object)."""
    if summary is not None:
        summary["qa"] = qa_of_result(summary, obj, ground)
    return write_atomically(out, _save_mainfile)


def _save_mainfile(path):
    import bpy
    bpy.ops.wm.save_as_mainfile(filepath=path)


_SOURCE_DIGESTS = {}  # {action name: digest} when the command's file was loaded


def qa_of_result(summary, obj=None, ground=None):
    """The motion QA of a command's result (its `armature` and new `action`), stored on the
    armature; a result that is not an armature's motion says so."""
    import bpy
    from .qa import job as qa
    obj = obj or bpy.data.objects.get(summary.get("armature") or "")
    if obj is None or obj.type != "ARMATURE" or not summary.get("action"):
        return qa.not_measured("this command's result is not a new action on an armature")
    scene = obj.users_scene[0] if obj.users_scene else bpy.context.scene
    return qa.measure_summary(obj, scene, summary, _SOURCE_DIGESTS, ground)


def qa_text(report):
    from ..solver.qa import text
    if report.get("measures"):
        return text(report)
    if report.get("passed") is None:
        return f"QA: not measured ({report.get('note', '')})"
    state = "passed" if report["passed"] else f"{len(report['warnings'])} WARNING(S)"  # an aggregate (batch)
    return "\n".join([f"QA {state} ({report.get('note', '')})"] + [f"  WARNING: {w}" for w in report["warnings"]])


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
    result["qa"] = source_qa(obj, scene)
    height = result["qa"].get("measures", {}).get("figure_height", {}).get("value")
    result["figure_height_m"] = height if height is not None else obj.get("humananim_figure_height_m")
    result.update(command="info", file=os.path.abspath(args.file), seconds=round(time.perf_counter() - t0, 3))
    if imported:
        result["bvh_unit"] = imported
    return result


def source_qa(obj, scene):
    """The motion QA of the armature's own action (no input to compare with): its height, floor,
    NaN, pops against the absolute caps."""
    from .qa import job as qa
    action = obj.animation_data.action if obj.animation_data else None
    if action is None:
        return qa.not_measured("the armature has no action")
    from ..solver.errors import HumanAnimError
    try:
        return qa.measure_result(obj, scene, action, store=False)
    except HumanAnimError as error:
        return qa.not_measured(str(error))


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
    picture = demo_picture(obj, scene, control, skirts, out)
    result.update(command="demo", input=os.path.abspath(args.bvh), bvh_unit=unit,
                  wrote=[out] + [path for s in skirts for path in s["wrote"]], picture=picture,
                  control=control, cloth=skirts, qa=control["qa"], seconds=round(time.perf_counter() - t0, 3))
    from .motion_control.cli import text_summary
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
    from .cloth import job as cloth
    from .bvh_import import import_bvh
    save_blend(out)  # the caches' relative paths need the .blend's folder
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
    save_blend(out)
    return summaries


def demo_control(obj, scene, skeleton, out):
    """Dynamic control of the demo clip with a load in both hands and a push on the chest; saves
    the .blend at `out` and a picture beside it."""
    from mathutils import Vector
    from .motion_control.cli import add_impulse_from_vector, control_and_save
    props = scene.humananim_control
    props.frame_start, props.frame_end = DEMO_FRAMES
    props.load_left = props.load_right = DEMO_LOAD_KG
    frame, magnitude = DEMO_PUSH
    backwards = obj.matrix_world.to_3x3() @ Vector((0.0, 1.0, 0.0))  # into the front of the chest
    add_impulse_from_vector(obj, scene, skeleton.roles.bone("chest"), frame, magnitude * backwards.normalized())
    return control_and_save(obj, scene, out)


def demo_picture(obj, scene, control, skirts, out):
    """The controlled walk over its input with its loads, push and skirt, beside the .blend."""
    import bpy
    from .motion_control import overlay
    from .motion_control.cli import _title
    garments = [bpy.data.objects[s["object"]] for s in skirts if s["armature"] == obj.name]

    def render(path):
        control["picture_frames"] = overlay.render_result(obj, scene, control["action"], path,
                                                          title=_title(control), garments=garments)
    picture = write_atomically(os.path.splitext(out)[0] + ".png", render)
    control["wrote"].append(picture)
    return picture


def parse_arrow(text, obj, option, default_seconds):
    """FRAME:BONE:FX,FY,FZ[:SECONDS] of --push and --impulse: (frame, bone, vector, seconds).

    BONE may hold any characters, colons included (`10:mixamorig:Spine2:0,-30,0`): the frame is
    the first field, the vector (three numbers with commas) and the seconds the last ones, and
    everything between is the bone. A bone may also be put in double quotes
    (`10:"mixamorig:Spine2":0,-30,0`); quote the whole argument for the shell."""
    form = "expected FRAME:BONE:FX,FY,FZ[:SECONDS]"
    head, sep, rest = text.partition(":")
    parts = rest.rsplit(":", 2)
    if not sep or len(parts) < 2:
        raise UsageError(f"{option} {text!r}: {form}")
    seconds = None
    if len(parts) == 3 and "," not in parts[2]:  # a SECONDS field after the vector
        seconds = parts[2]
        bone, vector = parts[0], parts[1]
    else:
        bone, vector = ":".join(parts[:-1]), parts[-1]
    if len(bone) >= 2 and bone[0] == bone[-1] == '"':
        bone = bone[1:-1]
    try:
        frame = int(head)
        vector = np.array([float(v) for v in vector.split(",")])
        seconds = default_seconds if seconds is None else float(seconds)
    except ValueError:
        raise UsageError(f"{option} {text!r}: {form}") from None
    if bone not in obj.data.bones:
        raise UsageError(f"{option} {text!r}: no bone named '{bone}'")
    if vector.shape != (3,) or not np.isfinite(vector).all() or not np.linalg.norm(vector) > 0.0:
        raise UsageError(f"{option} {text!r}: the vector needs three finite components FX,FY,FZ, not all zero")
    if not (math.isfinite(seconds) and seconds >= 0.0):
        raise UsageError(f"{option} {text!r}: SECONDS must be a finite number >= 0")
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
        if min(args.frames) < 1:  # 0 means "the action's own" to the settings
            raise UsageError(f"--frames {args.frames[0]} {args.frames[1]}: frames start at 1")
    from . import validation
    validation.frame_range(props, validation.source_action(obj, props))
    return obj, scene, unit


def set_loads_and_ground(args, props):
    """The options arguments.add_loads, add_strength and add_ground_height give, set on a job's
    settings (a forces.LoadsAndPushes group)."""
    props.load_left, props.load_right = args.load_left, args.load_right
    props.strength_scale = args.strength
    props.ground = "MOTION" if args.ground is None else "HEIGHT"
    props.ground_height = args.ground or 0.0


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
        _remember_sources()
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
    _remember_sources()
    return obj, scene, None


def _remember_sources():
    from .qa.job import digest_actions
    _SOURCE_DIGESTS.clear()
    _SOURCE_DIGESTS.update(digest_actions())


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
    lines = [f"{r['command']}: armature '{r['armature']}', {r['bone_count']} bones, "
             f"roles by {r['convention']}"]
    if r.get("missing_roles"):
        lines.append(f"  missing roles: {', '.join(r['missing_roles'])}")
    if r.get("refused"):
        lines.append(f"  refused: {r['refused']}")
    if r.get("total_mass_kg") is not None:
        lines.append(f"  mass: {r['total_mass_kg']:.1f} kg in {len(r['segments'])} segments")
    if r.get("figure_height_m") is not None:
        unit = f" (BVH unit: {r['bvh_unit']})" if r.get("bvh_unit") else ""
        lines.append(f"  figure height: {r['figure_height_m']:.2f} m{unit}")
    if r.get("action"):
        lines.append(f"  action '{r['action']}': frames {r['frame_range'][0]:g}-{r['frame_range'][1]:g} "
                     f"at {r['fps']:g} fps")
    for path in r.get("wrote", []):
        lines.append(f"  wrote {path}")
    lines.append(f"  took {r['seconds']:.2f} s")
    return "\n".join(lines)


COMMANDS = {"info": cmd_info, "demo": cmd_demo}
# Modules of this package with `add_commands(subparsers, add_common_options) -> {name: run(args)}`;
# `run` returns the summary dict (with "command" and "wrote") and raises HumanAnimError/UsageError.
COMMAND_MODULES = ("simulation.cli", "sequence.cli", "motion_control.cli", "cloth.cli", "flexible.cli", "walking.cli", "capture.cli",
                   "hands.cli", "synthesis.cli", "cleanup.cli", "retarget.cli", "batch")
