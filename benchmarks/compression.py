"""Key compression: HumanAnim's Hermite key reduction and pyramid compression beside Blender's own
Decimate (error mode) and Clean, on the same CMU clip, at matched largest error, in one run.

For each Blender setting, Blender's operator runs on the imported action (Graph Editor context in
background mode: the home file's window, one area switched to the Graph Editor); its largest
error is measured on every frame (degrees on rotation channels, centimetres on location channels,
and at every bone's tail and 10 cm beyond it); then HumanAnim's methods run with exactly those
largest errors as their per-frame tolerances, so every method is at or under Blender's error.
The Hermite keys are also written into the action as Blender keyframes and evaluated by Blender,
to check that Blender plays them exactly as computed.

Keeping planted feet (the Compress command's --feet-mm, default 2.5 mm): HumanAnim's whole
Compress command (humananim_addon.sequence.compress, Hermite keys, 0.5 deg / 0.5 cm) on each clip
as Blender's importer reads it, three ways in turn in the same run: without the feet, with the
legs' tolerance scale searched on the measured errors (key_reduction.scale_to_error, the
command's), and with it found by halving five times (key_reduction.fit_to_error, each step
reducing the legs' channels again). Each is timed in CPU seconds of the process (the command runs on
one thread; a loaded host stretches wall time far more), the fastest of --repeat, with its key count
and planted-foot error; --feet-clip adds clips (e.g. the Bandai Namco corpus beside the repo).

Run with a Python that has the bpy module:  python benchmarks/compression.py [--json] [--clip FILE]
[--feet-clip FILE] [--feet-only]
(--json prints one object and writes benchmarks/results/compression.json; see machine.py).
"""

import argparse
import os
import sys
import tempfile
import time

os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="humananim-bench-"))

import bpy  # noqa: E402
import numpy as np  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from machine import claim, emit, result  # noqa: E402

from humananim.solver import rotations  # noqa: E402
from humananim.solver.sequence import error_measures, key_reduction, pyramid_compression  # noqa: E402
from humananim.solver.skeleton import Skeleton  # noqa: E402
from humananim.solver.trajectories import Trajectories  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
CLIPS = [os.path.join(HERE, "..", "..", "shared", "data", "mocap", n) for n in ("cmu_131_01.bvh", "cmu_131_03.bvh")]
CLIPS = [c if os.path.exists(c) else os.path.join("/work/shared/data/mocap", os.path.basename(c)) for c in CLIPS]
DECIMATE_MARGINS = (0.005, 0.01, 0.02)
CLEAN_THRESHOLDS = (0.002, 0.005)


def fcurves_of(obj):
    action = obj.animation_data.action
    if hasattr(action, "fcurves") and len(getattr(action, "fcurves", ())):
        return list(action.fcurves)
    from bpy_extras import anim_utils
    return list(anim_utils.action_get_channelbag_for_slot(action, obj.animation_data.action_slot).fcurves)


def quietly(fn, *args, **kw):
    """Run fn with the process's stdout sent to stderr (Blender's importer prints progress)."""
    sys.stdout.flush()
    saved = os.dup(1)
    os.dup2(2, 1)
    try:
        return fn(*args, **kw)
    finally:
        sys.stdout.flush()
        os.dup2(saved, 1)
        os.close(saved)


def import_clip(path):
    quietly(bpy.ops.wm.read_homefile)
    for o in list(bpy.data.objects):
        bpy.data.objects.remove(o)
    quietly(bpy.ops.import_anim.bvh, filepath=path, rotate_mode="NATIVE")
    obj = bpy.context.object
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj
    return obj


def graph_editor():
    win = bpy.context.window_manager.windows[0]
    area = max(win.screen.areas, key=lambda a: a.width * a.height)
    area.type = "GRAPH_EDITOR"
    area.spaces.active.dopesheet.show_only_selected = False
    region = next(r for r in area.regions if r.type == "WINDOW")
    return dict(window=win, area=area, region=region)


def read_keys(fc):
    n = len(fc.keyframe_points)
    co = np.empty(2 * n)
    fc.keyframe_points.foreach_get("co", co)
    return co.reshape(n, 2)


def restore(fcs, originals):
    for fc, co in zip(fcs, originals):
        fc.keyframe_points.clear()
        fc.keyframe_points.add(len(co))
        fc.keyframe_points.foreach_set("co", co.ravel())
        for kp in fc.keyframe_points:
            kp.interpolation = "LINEAR"
        fc.update()


def write_keys(fcs, keys_list):
    for fc, k in zip(fcs, keys_list):
        fc.keyframe_points.clear()
        fc.keyframe_points.add(len(k))
        kps = fc.keyframe_points
        for kp, interp in zip(kps, k.interpolation):
            kp.interpolation = interp
            kp.handle_left_type = kp.handle_right_type = "FREE"
        kps.foreach_set("co", np.column_stack((k.times, k.values)).ravel())
        kps.foreach_set("handle_left", k.left.ravel())
        kps.foreach_set("handle_right", k.right.ravel())
        fc.update()


def sample(fcs, frames):
    return np.array([[fc.evaluate(f) for fc in fcs] for f in frames])


def skeleton_of(obj):
    bones = list(obj.data.bones)
    index = {b.name: i for i, b in enumerate(bones)}
    rest = np.array([np.array(b.matrix_local) for b in bones])
    J = len(bones)
    return Skeleton(names=[b.name for b in bones], parents=[index[b.parent.name] if b.parent else -1 for b in bones],
                    rest=rest, lengths=np.array([b.length for b in bones]), connected=np.zeros(J, bool),
                    dof=np.ones((J, 3), bool), limits=np.tile([-np.inf, np.inf], (J, 3, 1)), mass=np.ones(J),
                    com=np.zeros((J, 3)), inertia=np.tile(np.eye(3), (J, 1, 1)))


class Motion:
    """Maps the action's F-curve samples (F, C) to Trajectories of the armature's skeleton."""

    def __init__(self, obj, fcs, frames, fps):
        self.obj, self.frames, self.fps = obj, frames, fps
        self.skeleton = skeleton_of(obj)
        self.slots = []
        for c, fc in enumerate(fcs):
            name = fc.data_path.split('"')[1]
            prop = fc.data_path.rsplit(".", 1)[1]
            self.slots.append((self.skeleton.index(name), prop, fc.array_index))
        self.kinds = np.array(["location" if p == "location" else "rotation" for _, p, _ in self.slots])

    def trajectories(self, values):
        F, J = len(values), self.skeleton.joint_count
        euler = np.zeros((F, J, 3))
        loc = np.zeros((F, J, 3))
        for c, (j, prop, i) in enumerate(self.slots):
            (loc if prop == "location" else euler)[:, j, i] = values[:, c]
        q = np.stack([rotations.from_euler(euler[:, j], self.obj.pose.bones[j].rotation_mode)
                      for j in range(J)], axis=1)
        return Trajectories(self.frames, self.fps, q, loc, np.array(self.obj.matrix_world))

    def errors(self, values, reference):
        rot = self.kinds == "rotation"
        d = np.abs(values - reference).max(axis=0)
        tail = error_measures.tail_error(self.skeleton, self.trajectories(reference), self.trajectories(values))
        return {"max_error_deg": float(np.degrees(d[rot].max())), "max_error_cm": float(100 * d[~rot].max()),
                "tail_error_cm": tail.tail_cm, "tail_10cm_error_cm": tail.point_cm}


def at_tail_error(motion, frames, orig, tol, target_cm):
    """Hermite reduction whose error 10 cm beyond the bone tails is at most `target_cm`."""
    def measure(keys):
        return motion.errors(key_reduction.evaluate_channels(keys, frames), orig)["tail_10cm_error_cm"]
    keys, scale, _ = key_reduction.fit_to_error(
        lambda scale: key_reduction.reduce_channels(frames, orig, tol * scale), measure, target_cm)
    return keys, motion.errors(key_reduction.evaluate_channels(keys, frames), orig), scale


def run_clip(path, repeat):
    obj = import_clip(path)
    ctx = graph_editor()
    fcs = fcurves_of(obj)
    originals = [read_keys(fc) for fc in fcs]
    frames = originals[0][:, 0]
    orig = np.stack([co[:, 1] for co in originals], axis=1)
    fps = bpy.context.scene.render.fps / bpy.context.scene.render.fps_base
    motion = Motion(obj, fcs, frames, fps)
    rot = motion.kinds == "rotation"
    F, C = orig.shape
    per_unit = 1000.0 / F * 60.0 / C  # scale a time to 1000 frames x 60 channels
    rows = []
    settings = [("decimate", m) for m in DECIMATE_MARGINS] + [("clean", t) for t in CLEAN_THRESHOLDS]
    for op, arg in settings:
        with bpy.context.temp_override(**ctx):
            bpy.ops.graph.select_all(action="SELECT")
            t0 = time.perf_counter()
            if op == "decimate":
                bpy.ops.graph.decimate(mode="ERROR", remove_error_margin=arg)
            else:
                bpy.ops.graph.clean(threshold=arg, channels=False)
            blender_s = time.perf_counter() - t0
        blender_keys = sum(len(fc.keyframe_points) for fc in fcs)
        blender = motion.errors(sample(fcs, frames), orig)
        restore(fcs, originals)
        # HumanAnim at Blender's largest errors (radians and metres per channel)
        tol = np.where(rot, np.radians(blender["max_error_deg"]), blender["max_error_cm"] / 100.0)
        best = np.inf
        for _ in range(repeat):
            t0 = time.perf_counter()
            keys = key_reduction.reduce_channels(frames, orig, tol)
            best = min(best, time.perf_counter() - t0)
        hermite = motion.errors(key_reduction.evaluate_channels(keys, frames), orig)
        write_keys(fcs, keys)
        in_blender = sample(fcs, frames)
        between = np.linspace(frames[0], frames[-1], 4 * F)
        blender_between = np.array([[fc.evaluate(f) for fc in fcs] for f in between[::7]])
        ours_between = key_reduction.evaluate_channels(keys, between[::7])
        diff = np.maximum(np.abs(in_blender - key_reduction.evaluate_channels(keys, frames)).max(axis=0),
                          np.abs(blender_between - ours_between).max(axis=0))
        restore(fcs, originals)
        t0 = time.perf_counter()
        pkeys, _ = pyramid_compression.pyramid_keys(frames, orig, tol)
        pyr_s = time.perf_counter() - t0
        pyr = motion.errors(key_reduction.evaluate_channels(pkeys, frames), orig)
        rows.append({
            "clip": os.path.basename(path), "blender_op": op, "blender_setting": arg,
            "frames": F, "channels": C, "input_keys": int(orig.size),
            "blender_keys": blender_keys, **{f"blender_{k}": v for k, v in blender.items()},
            "blender_ms_per_1000f_60ch": 1e3 * blender_s * per_unit,
            "hermite_keys": sum(len(k) for k in keys), **{f"hermite_{k}": v for k, v in hermite.items()},
            "hermite_ms_per_1000f_60ch": 1e3 * best * per_unit,
            "hermite_blender_playback_max_diff_deg": float(np.degrees(diff[rot].max())),
            "hermite_blender_playback_max_diff_cm": float(100 * diff[~rot].max()),
            "pyramid_keys": sum(len(k) for k in pkeys), **{f"pyramid_{k}": v for k, v in pyr.items()},
            "pyramid_ms_per_1000f_60ch": 1e3 * pyr_s * per_unit,
        })
        rows[-1]["hermite_keys_vs_blender"] = rows[-1]["hermite_keys"] / blender_keys
        # the same largest error at 10 cm beyond the bone tails, not only per channel
        mkeys, merr, scale = at_tail_error(motion, frames, orig, tol, blender["tail_10cm_error_cm"])
        rows[-1].update({"hermite_matched_tail_keys": sum(len(k) for k in mkeys),
                         "hermite_matched_tail_tolerance_scale": scale,
                         **{f"hermite_matched_tail_{k}": v for k, v in merr.items()}})
        rows[-1]["hermite_matched_tail_keys_vs_blender"] = rows[-1]["hermite_matched_tail_keys"] / blender_keys
    return rows


FEET_MM = 2.5


def run_feet(path, repeat):
    """The Compress command on one clip without the feet, with the scale searched on the errors
    and with it halved: (seconds, keys, ratio, planted-foot error mm, tolerance scale) each."""
    import importlib
    from humananim.humananim_addon import sequence
    command = importlib.import_module("humananim.humananim_addon.sequence.compress")
    obj = import_clip(path)
    scene = bpy.context.scene
    source = obj.animation_data.action
    sel = sequence.select_channels(obj, scene, source)
    ways = {"none": (0.0, key_reduction.scale_to_error), "errors": (FEET_MM, key_reduction.scale_to_error),
            "halving": (FEET_MM, key_reduction.fit_to_error)}
    row = {"clip": os.path.basename(path), "frames": int(len(sequence.action_frames(source)))}
    best = dict.fromkeys(ways, np.inf)
    for _ in range(repeat):
        for name, (feet_mm, search) in ways.items():  # in turn, so that load changes hit all three alike
            command.FEET_SEARCH = search
            try:
                t0 = time.process_time()
                s = quietly(sequence.compress, obj, scene, source, sel, feet_mm=feet_mm)
                best[name] = min(best[name], time.process_time() - t0)
            finally:
                command.FEET_SEARCH = key_reduction.scale_to_error
            row.update({f"{name}_keys": s["keys_after"], f"{name}_ratio": s["ratio"],
                        f"{name}_feet_error_mm": s.get("feet_error_mm"), f"{name}_scale": s.get("feet_tolerance_scale")})
    row.update({f"{name}_s": round(best[name], 3) for name in ways})
    return row


def feet_summary(rows):
    total = {name: sum(r[f"{name}_s"] for r in rows) for name in ("none", "errors", "halving")}
    keys = {name: sum(r[f"{name}_keys"] for r in rows) for name in ("errors", "halving")}
    return {"feet_clips": [r["clip"] for r in rows], "feet_rows": rows,
            "feet_errors_vs_none_time": total["errors"] / total["none"],
            "feet_halving_vs_none_time": total["halving"] / total["none"],
            "feet_errors_vs_halving_time": total["errors"] / total["halving"],
            "feet_errors_vs_halving_keys": keys["errors"] / keys["halving"],
            "feet_max_error_mm": max(r["errors_feet_error_mm"] or 0.0 for r in rows)}


def feet_claims(s):
    return [
        claim(f"Compress keeping planted feet ({FEET_MM} mm), scale searched on the errors: time against without "
              "the feet", s["feet_errors_vs_none_time"], "x", None, None),
        claim(f"Compress keeping planted feet ({FEET_MM} mm), scale halved five times: time against without the "
              "feet", s["feet_halving_vs_none_time"], "x", None, None),
        claim("Compress keeping planted feet: time, scale searched on the errors against halved, same clips in the "
              "same run", s["feet_errors_vs_halving_time"], "ratio", "faster than halving (< 1)",
              s["feet_errors_vs_halving_time"] < 1.0),
        claim("Compress keeping planted feet: keys, scale searched on the errors against halved",
              s["feet_errors_vs_halving_keys"], "ratio", "within 2 %", abs(s["feet_errors_vs_halving_keys"] - 1) <= 0.02),
        claim("Compress keeping planted feet: largest planted-foot error, scale searched on the errors",
              s["feet_max_error_mm"], "mm", f"at most {FEET_MM} mm", s["feet_max_error_mm"] <= FEET_MM),
    ]


def summary(rows):
    dec = [r for r in rows if r["blender_op"] == "decimate" and r["blender_setting"] == 0.01]
    cln = [r for r in rows if r["blender_op"] == "clean" and r["blender_setting"] == 0.005]
    s = {}
    for name, sel in (("decimate", dec), ("clean", cln)):
        s[f"blender_{name}_keys"] = sum(r["blender_keys"] for r in sel)
        s[f"hermite_keys_at_{name}_error"] = sum(r["hermite_keys"] for r in sel)
        s[f"pyramid_keys_at_{name}_error"] = sum(r["pyramid_keys"] for r in sel)
        s[f"blender_{name}_max_error_deg"] = max(r["blender_max_error_deg"] for r in sel)
        s[f"blender_{name}_max_error_cm"] = max(r["blender_max_error_cm"] for r in sel)
        s[f"hermite_at_{name}_max_error_deg"] = max(r["hermite_max_error_deg"] for r in sel)
        s[f"hermite_at_{name}_max_error_cm"] = max(r["hermite_max_error_cm"] for r in sel)
        s[f"blender_{name}_tail_10cm_error_cm"] = max(r["blender_tail_10cm_error_cm"] for r in sel)
        s[f"hermite_at_{name}_tail_10cm_error_cm"] = max(r["hermite_tail_10cm_error_cm"] for r in sel)
        s[f"hermite_keys_at_{name}_tail_error"] = sum(r["hermite_matched_tail_keys"] for r in sel)
        s[f"hermite_at_{name}_tail_error_keys_ratio"] = (s[f"hermite_keys_at_{name}_tail_error"]
                                                        / s[f"blender_{name}_keys"])
    s["hermite_keys"] = s["hermite_keys_at_decimate_error"]
    s["blender_decimate_keys_ratio_hermite"] = s["hermite_keys"] / s["blender_decimate_keys"]
    s["hermite_max_error_deg"] = s["hermite_at_decimate_max_error_deg"]
    s["hermite_max_error_cm"] = s["hermite_at_decimate_max_error_cm"]
    s["hermite_ms_per_1000f_60ch"] = float(np.median([r["hermite_ms_per_1000f_60ch"] for r in rows]))
    s["pyramid_ms_per_1000f_60ch"] = float(np.median([r["pyramid_ms_per_1000f_60ch"] for r in rows]))
    s["blender_decimate_ms_per_1000f_60ch"] = float(np.median(
        [r["blender_ms_per_1000f_60ch"] for r in rows if r["blender_op"] == "decimate"]))
    s["blender_clean_ms_per_1000f_60ch"] = float(np.median(
        [r["blender_ms_per_1000f_60ch"] for r in rows if r["blender_op"] == "clean"]))
    for unit in ("deg", "cm"):
        key = f"hermite_blender_playback_max_diff_{unit}"
        s[key] = max(r[key] for r in rows)
    return s


def claims(s):
    """The figures RESULTS.md shows: keys against Blender's at the same error, and the times."""
    same_error = "at the largest per-channel error of Blender's"
    return [
        claim(f"Hermite key reduction: keys against Decimate's (margin 0.01) {same_error}",
              s["blender_decimate_keys_ratio_hermite"],
              "ratio", "fewer keys than Decimate (< 1)", s["blender_decimate_keys_ratio_hermite"] < 1),
        claim("Hermite key reduction: keys against Decimate's at Decimate's largest error 10 cm beyond the bone "
              "tails", s["hermite_at_decimate_tail_error_keys_ratio"], "ratio", "fewer keys than Decimate (< 1)",
              s["hermite_at_decimate_tail_error_keys_ratio"] < 1),
        claim(f"Hermite key reduction: keys against Clean's (threshold 0.005) {same_error}",
              s["hermite_keys_at_clean_error"] / s["blender_clean_keys"], "ratio", None, None),
        claim("Hermite key reduction against Blender's Decimate: time ratio, the same clips in the same run",
              s["blender_decimate_ms_per_1000f_60ch"] / s["hermite_ms_per_1000f_60ch"], "x faster", None, None),
        claim("Hermite key reduction: time per 1000 frames x 60 channels", s["hermite_ms_per_1000f_60ch"], "ms",
              None, None),
        claim("Blender's Decimate: time per 1000 frames x 60 channels", s["blender_decimate_ms_per_1000f_60ch"],
              "ms", None, None),
        claim("Pyramid compression: time per 1000 frames x 60 channels", s["pyramid_ms_per_1000f_60ch"], "ms",
              None, None),
        claim("Hermite keys as Blender plays them against as computed, on and between frames",
              s["hermite_blender_playback_max_diff_deg"], "deg", None, None),
    ]


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--clip", action="append", help="BVH file (default: both CMU clips)")
    parser.add_argument("--json", action="store_true")
    parser.add_argument("--repeat", type=int, default=1)
    parser.add_argument("--feet-clip", action="append", default=[], help="more BVH files for the planted feet")
    parser.add_argument("--feet-only", action="store_true", help="only the planted feet's timing")
    args = parser.parse_args()
    import humananim
    humananim.register()  # the Compress command reads the rig's role settings
    feet = feet_summary([run_feet(clip, args.repeat) for clip in (args.clip or CLIPS) + args.feet_clip])
    rows = []
    for clip in ([] if args.feet_only else args.clip or CLIPS):
        rows += run_clip(clip, args.repeat)
    figures = {"rows": rows, **summary(rows)} if rows else {}
    if args.json:
        emit(result("compression", (claims(figures) if rows else []) + feet_claims(feet),
                    clips=sorted({r["clip"] for r in rows}), **figures, **feet))
        return 0
    print(f"{'clip':30} {'frames':>6} | {'no feet s':>9} | {'errors s':>8} {'keys':>6} {'mm':>5} {'scale':>6} | "
          f"{'halving s':>9} {'keys':>6} {'mm':>5} {'scale':>6}")
    for r in feet["feet_rows"]:
        print(f"{r['clip'][:30]:30} {r['frames']:6d} | {r['none_s']:9.2f} | {r['errors_s']:8.2f} {r['errors_keys']:6d} "
              f"{r['errors_feet_error_mm'] or 0:5.2f} {r['errors_scale'] or 1:6.3f} | {r['halving_s']:9.2f} "
              f"{r['halving_keys']:6d} {r['halving_feet_error_mm'] or 0:5.2f} {r['halving_scale'] or 1:6.3f}")
    print(f"keeping feet: {feet['feet_errors_vs_none_time']:.2f}x the time without (halving: "
          f"{feet['feet_halving_vs_none_time']:.2f}x); on the errors / halving: time "
          f"{feet['feet_errors_vs_halving_time']:.2f}, keys {feet['feet_errors_vs_halving_keys']:.3f}\n")
    if not rows:
        return 0
    head = (f"{'clip':15} {'Blender':16} {'keys':>6} {'deg':>6} {'cm':>6} {'tail+10':>7} | "
            f"{'Hermite':>7} {'deg':>6} {'cm':>6} {'tail+10':>7} {'ratio':>5} | {'Pyramid':>7} {'deg':>6} {'cm':>6}")
    print(head)
    print("-" * len(head))
    for r in rows:
        print(f"{r['clip'][:15]:15} {r['blender_op'] + ' ' + str(r['blender_setting']):16} "
              f"{r['blender_keys']:6d} {r['blender_max_error_deg']:6.3f} {r['blender_max_error_cm']:6.3f} "
              f"{r['blender_tail_10cm_error_cm']:7.3f} | {r['hermite_keys']:7d} {r['hermite_max_error_deg']:6.3f} "
              f"{r['hermite_max_error_cm']:6.3f} {r['hermite_tail_10cm_error_cm']:7.3f} "
              f"{r['hermite_keys_vs_blender']:5.2f} | {r['pyramid_keys']:7d} {r['pyramid_max_error_deg']:6.3f} "
              f"{r['pyramid_max_error_cm']:6.3f}")
    print("\nat the same largest error 10 cm beyond the bone tails (Hermite tolerance scaled down):")
    for r in rows:
        print(f"{r['clip'][:15]:15} {r['blender_op'] + ' ' + str(r['blender_setting']):16} "
              f"Blender {r['blender_keys']:6d} keys, {r['blender_tail_10cm_error_cm']:6.3f} cm | Hermite "
              f"{r['hermite_matched_tail_keys']:6d} keys, {r['hermite_matched_tail_tail_10cm_error_cm']:6.3f} cm, "
              f"{r['hermite_matched_tail_max_error_deg']:5.3f} deg  ratio {r['hermite_matched_tail_keys_vs_blender']:4.2f}")
    print(f"input keys per clip: {rows[0]['input_keys']} ({rows[0]['frames']} frames x {rows[0]['channels']} F-curves)")
    print("ms per 1000 frames x 60 channels: "
          f"Hermite {figures['hermite_ms_per_1000f_60ch']:.0f}, pyramid {figures['pyramid_ms_per_1000f_60ch']:.0f}, "
          f"Blender Decimate {figures['blender_decimate_ms_per_1000f_60ch']:.0f}, "
          f"Clean {figures['blender_clean_ms_per_1000f_60ch']:.1f}")
    print("Hermite keys played back by Blender (float32) vs computed, on and between frames: "
          f"{figures['hermite_blender_playback_max_diff_deg']:.1e} deg, "
          f"{figures['hermite_blender_playback_max_diff_cm']:.1e} cm")
    return 0


if __name__ == "__main__":
    sys.exit(main())
