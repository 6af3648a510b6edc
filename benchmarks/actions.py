"""Reading and writing actions: HumanAnim's bridge beside Blender's own Bake Action, same clip, same run.

Run with a Python that has the bpy module:  python benchmarks/actions.py [--json] [--clip FILE]

Wall milliseconds (best of 3 runs; one for the depsgraph read and Blender's bake) of reading the
clip's action from its F-curves and through the depsgraph, writing it to a new action, and
HumanAnim's bake (depsgraph read + write) beside Blender's Bake Action with visual keying on the
same armature and frames. The claim is the ratio of the two bakes, measured in the same run.
`--json` prints one object and writes benchmarks/results/actions.json (machine.py's contract).
"""

import argparse
import os
import sys
import tempfile
import time

os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="humananim-bench-"))

import bpy  # noqa: E402

import humananim  # noqa: E402
from humananim.humananim_addon import actions  # noqa: E402
from humananim.humananim_addon.armature import skeleton_from_armature  # noqa: E402
from humananim.humananim_addon.bvh_import import import_bvh  # noqa: E402
from machine import claim, emit, result  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
DEFAULT_CLIP = os.path.join(HERE, "..", "humananim_addon", "data", "mocap", "cmu_131_01.bvh")


def best_of(n, fn):
    times = []
    for _ in range(n):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--clip", default=DEFAULT_CLIP)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    humananim.register()
    bpy.ops.wm.read_homefile(use_empty=True)
    obj, _, _ = import_bvh(args.clip)
    scene = bpy.context.scene
    source = obj.animation_data.action
    skeleton = skeleton_from_armature(obj, scene)
    frames = actions.sample_frames(source, obj)
    n_frames, n_bones = len(frames), skeleton.joint_count

    read_fc = best_of(3, lambda: actions.read_action(obj, scene, skeleton, exact=False))
    read_dg = best_of(1, lambda: actions.read_action(obj, scene, skeleton, exact=True))
    traj = actions.read_action(obj, scene, skeleton, exact=False)

    def write():
        actions.write_action(obj, skeleton, traj, "bench", "ACTION", source)
        obj.animation_data.action = source
    write_s = best_of(3, write)

    def blender_bake():
        bpy.context.view_layer.objects.active = obj
        obj.select_set(True)
        bpy.ops.object.mode_set(mode="POSE")
        bpy.ops.pose.select_all(action="SELECT")
        bpy.ops.nla.bake(frame_start=int(frames[0]), frame_end=int(frames[-1]), only_selected=False,
                         visual_keying=True, use_current_action=False, bake_types={"POSE"})
        bpy.ops.object.mode_set(mode="OBJECT")
        obj.animation_data.action = source
    bake_s = best_of(1, blender_bake)

    figures = {
        "frames": n_frames, "bones": n_bones,
        "read_fcurves_ms": 1e3 * read_fc, "read_depsgraph_ms": 1e3 * read_dg,
        "write_action_ms": 1e3 * write_s,
        "humananim_bake_ms": 1e3 * (read_dg + write_s),
        "blender_bake_action_ms": 1e3 * bake_s,
        "read_fcurves_us_per_frame": 1e6 * read_fc / n_frames,
    }
    figures["bake_speedup_vs_blender"] = figures["blender_bake_action_ms"] / figures["humananim_bake_ms"]
    if args.json:
        emit(result("actions", [
            claim("HumanAnim bake (depsgraph read + new action) speed-up over Blender's Bake Action, same clip",
                  figures["bake_speedup_vs_blender"], "x"),
            claim("HumanAnim bake of the clip", figures["humananim_bake_ms"], "ms wall"),
            claim("reading an action from its F-curves, per frame", figures["read_fcurves_us_per_frame"], "us wall"),
        ], clip=os.path.basename(args.clip), **{k: round(v, 4) if isinstance(v, float) else v
                                               for k, v in figures.items()}))
    else:
        print(f"{os.path.basename(args.clip)}: {n_frames} frames x {n_bones} bones")
        print(f"  read, F-curves       {figures['read_fcurves_ms']:8.1f} ms")
        print(f"  read, depsgraph      {figures['read_depsgraph_ms']:8.1f} ms")
        print(f"  write new action     {figures['write_action_ms']:8.1f} ms")
        print(f"  HumanAnim bake       {figures['humananim_bake_ms']:8.1f} ms (depsgraph read + write)")
        print(f"  Blender Bake Action  {figures['blender_bake_action_ms']:8.1f} ms (visual keying)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
