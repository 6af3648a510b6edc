"""Batch commands for keyframe sequences: filter, blend, compress, warp.

Each reads a .blend (--armature, --action) or a .bvh, runs the same bridge code as the
operators, saves a .blend (--out) and prints a summary (--json: one object)."""

import os
import time

from ..arguments import COUNT, FINITE, NON_NEGATIVE, POSITIVE, UsageError, add_input, number


def _inputs(p, out):
    add_input(p)
    p.add_argument("--action", help="source action (default: the armature's active action)")
    p.add_argument("--bones", help="comma-separated bones to process (default: every channel)")
    p.add_argument("--replace", action="store_true", help="rewrite the source action instead of writing a new one")
    p.add_argument("--out", default=os.path.join("out", out), help="the .blend to write")


def add_commands(sub, add_common_options):
    f = sub.add_parser("filter", help="motion equalizer: a gain per frequency band, or remove jitter")
    _inputs(f, "filter.blend")
    f.add_argument("--gains", help="comma-separated gains, finest band first, the mean pose last (e.g. 0,0.5,1,1.5,1,1)")
    f.add_argument("--levels", type=COUNT, help="pyramid levels (default: one fewer than the gains, or 5)")
    f.add_argument("--denoise-hz", type=POSITIVE,
                   help="low-pass at this frequency instead (Hz, below the clip's Nyquist: half its frame rate)")
    add_common_options(f)
    b = sub.add_parser("blend", help="multiresolution blend of the action and a second one")
    _inputs(b, "blend.blend")
    b.add_argument("--with", dest="second", required=True,
                   help="the second action: its name in the file, or a .bvh or .blend file with it")
    b.add_argument("--with-action", help="which action of a --with .blend (default: the first)")
    b.add_argument("--start", type=FINITE, help="frame of the first action where the second starts "
                                               "(default: its last frame minus the window)")
    b.add_argument("--window", type=number(0, integer=True), default=12, help="transition frames (0: the whole overlap; default 12)")
    b.add_argument("--method", choices=("multiresolution", "weighted"), default="multiresolution")
    b.add_argument("--mask", choices=("window", "gaussian"), default="window")
    add_common_options(b)
    c = sub.add_parser("compress", help="fewer keys within degrees and centimetres on every frame")
    _inputs(c, "compress.blend")
    c.add_argument("--degrees", type=POSITIVE, default=0.5, help="largest rotation error (default 0.5)")
    c.add_argument("--cm", type=POSITIVE, default=0.5, help="largest location error in cm (default 0.5)")
    c.add_argument("--value", type=POSITIVE, default=1e-3, help="largest error of other curves (default 0.001)")
    c.add_argument("--tail-cm", type=NON_NEGATIVE, default=0.0,
                   help="also keep bone tails and points 10 cm beyond them within this many cm (default: off)")
    c.add_argument("--feet-mm", type=NON_NEGATIVE, default=None,
                   help="keep planted feet within this many mm of the source (the legs' tolerances are tightened "
                        "where needed; default 2.5, half the motion QA's slide margin; 0: off)")
    c.add_argument("--method", choices=("hermite", "pyramid"), default="hermite")
    add_common_options(c)
    w = sub.add_parser("warp", help="time warp through OLD:NEW frame pairs (or the file's warp markers)")
    _inputs(w, "warp.blend")
    w.add_argument("--map", action="append", default=[], metavar="OLD:NEW[,OLD:NEW]",
                   help="what happened at frame OLD now happens at NEW; repeatable")
    w.add_argument("--markers", action="store_true", help="also use markers named 'warp:<old frame>'")
    w.add_argument("--move-ends", action="store_true", help="do not pin the first and last frames")
    w.add_argument("--resample", action="store_true", help="key every frame instead of moving the keys")
    add_common_options(w)
    return {"filter": cmd_filter, "blend": cmd_blend, "compress": cmd_compress, "warp": cmd_warp}


def _prepare(args):
    import bpy
    from .. import action_api, sequence
    from ..cli import _load
    obj, scene, unit = _load(args.file, args.armature, args.scale)
    ad = obj.animation_data
    if args.action:
        action = bpy.data.actions.get(args.action)
        if action is None:
            raise UsageError(f"no action named '{args.action}'")
        action_api.assign_action(obj, action, action_api.object_slot(action, obj))
    else:
        action = ad.action if ad else None
        if action is None:
            raise UsageError(f"'{obj.name}' has no active action: pass --action")
    if args.bones:
        bones = [b.strip() for b in args.bones.split(",") if b.strip()]
        unknown = [b for b in bones if b not in obj.data.bones]
        if unknown:
            raise UsageError(f"no bone named {', '.join(repr(b) for b in unknown)}")
        sel = sequence.select_channels(obj, scene, action, "BONES", bones)
    else:
        sel = sequence.select_channels(obj, scene, action, "ALL")
    _at_least_two_frames(action, obj)
    return obj, scene, action, sel, unit


def _at_least_two_frames(action, obj):
    from .. import action_api
    keys = {round(k.co[0], 6) for fc in action_api.fcurves_of(action, obj) for k in fc.keyframe_points}
    if len(keys) < 2:
        raise UsageError(f"'{action.name}' has {len(keys)} keyed frame{'s' if len(keys) != 1 else ''}: "
                         "at least 2 are needed")


def _save(args, summary, t0, unit):
    from ..cli import save_blend
    out = save_blend(args.out, summary)
    summary.update(file=os.path.abspath(args.file), wrote=[out], seconds=round(time.perf_counter() - t0, 3))
    if unit:
        summary["bvh_unit"] = unit
    summary["summary"] = "\n".join(_lines(summary) + [f"  wrote {out}", f"  took {summary['seconds']:.2f} s"])
    return summary


def _lines(s):
    where = "in place" if s["replaced"] else f"new action '{s['action']}'"
    head = f"{s['command']}: '{s['armature']}' action '{s['source_action']}', {s['curves']} curves -> {where}"
    lines = [head]
    if s.get("selection_note"):
        lines.append(f"  {s['selection_note']}")
    if s["command"] == "filter":
        lines.append(f"  low-pass at {s['cutoff_hz']:g} Hz ({s['fps']:g} fps clip)" if s["gains"] is None else
                     f"  gains {', '.join(f'{g:g}' for g in s['gains'])} on bands {', '.join(s['bands'])}")
        lines.append(f"  largest change {s['largest_change_deg']:.3f} deg, {s['largest_change_cm']:.3f} cm "
                     f"in {s['ms']:.0f} ms")
    elif s["command"] == "blend":
        t = s["transition"]
        lines.append(f"  then '{s['action_b']}' from frame {s['start']:g} ({s['method']}), transition "
                     + (f"{t[0]:g}-{t[1]:g}" if t else "none") + f", frames {s['frames'][0]:g}-{s['frames'][1]:g}")
    elif s["command"] == "compress":
        lines.append(f"  {s['keys_before']} -> {s['keys_after']} keys ({s['ratio']:g}x) in {s['ms']:.0f} ms")
        lines.append(f"  largest error {s['max_error_deg']:.3f} deg (tolerance {s['tolerance_deg']:g}), "
                     f"{s['max_error_cm']:.3f} cm (tolerance {s['tolerance_cm']:g})")
        if "tail_error_cm" in s:
            lines.append(f"  bone tails {s['tail_error_cm']:.3f} cm ({s['tail_error_bone']}), 10 cm beyond "
                         f"{s['tail_10cm_error_cm']:.3f} cm ({s['tail_10cm_error_bone']})")
    elif s["command"] == "warp":
        lines.append("  " + ", ".join(f"{o:g}->{n:g}" for o, n in s["constraints"])
                     + f"; frames {s['frames'][0]:g}-{s['frames'][1]:g}, {s['keys']} keys")
    return lines


def cmd_filter(args):
    from .. import sequence
    t0 = time.perf_counter()
    obj, scene, action, sel, unit = _prepare(args)
    gains = None
    if args.gains:
        try:
            gains = [FINITE(v) for v in args.gains.split(",")]
        except Exception:
            raise UsageError(f"--gains {args.gains!r}: expected finite numbers separated by commas") from None
        if len(gains) < 2:
            raise UsageError("--gains needs at least two values (a band and the mean)")
    elif args.denoise_hz is None:
        raise UsageError("give --gains or --denoise-hz")
    levels = args.levels or (len(gains) - 1 if gains else 5)
    summary = sequence.equalize(obj, scene, action, sel, gains=gains, levels=levels, cutoff_hz=args.denoise_hz,
                                replace=args.replace)
    return _save(args, summary, t0, unit)


def _second_action(args, obj):
    import bpy
    from ..bvh_import import import_bvh
    name = args.second
    action = bpy.data.actions.get(name)
    if action is not None:
        return action
    if not os.path.isfile(name):
        raise UsageError(f"--with {name!r}: no action of that name and no such file")
    if name.lower().endswith(".bvh"):
        active = bpy.context.view_layer.objects.active
        other, _, _ = import_bvh(name, args.scale)
        action = other.animation_data.action
        action.use_fake_user = True
        bpy.data.objects.remove(other)
        bpy.context.view_layer.objects.active = active
        return action
    with bpy.data.libraries.load(os.path.abspath(name)) as (src, dst):
        names = list(src.actions)
        if not names:
            raise UsageError(f"--with {name!r}: no actions in the file")
        pick = args.with_action or names[0]
        if pick not in names:
            raise UsageError(f"--with-action {pick!r}: not in {os.path.basename(name)} ({', '.join(names)})")
        dst.actions = [pick]
    action = dst.actions[0]
    action.use_fake_user = True
    return action


def cmd_blend(args):
    from .. import sequence
    t0 = time.perf_counter()
    obj, scene, action, sel, unit = _prepare(args)
    second = _second_action(args, obj)
    start = args.start if args.start is not None else action.frame_range[1] - args.window
    summary = sequence.blend(obj, scene, action, second, start, args.window, args.method.upper(), args.mask.upper(),
                             sel=sel, replace=args.replace)
    return _save(args, summary, t0, unit)


def cmd_compress(args):
    from .. import sequence
    t0 = time.perf_counter()
    obj, scene, action, sel, unit = _prepare(args)
    summary = sequence.compress(obj, scene, action, sel, args.degrees, args.cm, args.value, args.method.upper(),
                                args.replace, args.tail_cm,
                                sequence.FEET_MM if args.feet_mm is None else args.feet_mm)
    return _save(args, summary, t0, unit)


def cmd_warp(args):
    from ...solver.errors import MotionError
    from .. import sequence
    t0 = time.perf_counter()
    obj, scene, action, sel, unit = _prepare(args)
    try:
        pairs = [p for text in args.map for p in sequence.parse_map(text)]
    except MotionError as error:
        raise UsageError(str(error)) from None
    if args.markers:
        pairs += sequence.marker_constraints(scene, action)
    if not pairs:
        raise UsageError("give --map OLD:NEW pairs (or --markers with 'warp:<old frame>' markers in the file)")
    summary = sequence.warp(obj, scene, action, sel, pairs, keep_ends=not args.move_ends, resample=args.resample,
                            replace=args.replace)
    return _save(args, summary, t0, unit)
