#!/usr/bin/env python3
"""Retarget Motion onto a generated Rigify rig beside Blender's own way, in one run.

    python benchmarks/retarget.py                 # 1,000 frames of the bundled CMU walk (cmu_131_01)
    python benchmarks/retarget.py --frames 30     # fewer (a quick check)
    python benchmarks/retarget.py --json          # one JSON object, also benchmarks/results/retarget.json

Runs in the bpy module (Blender 5.0 or 4.2). The rig: Rigify's human metarig generated (Rigify's
IK legs, torso, FK spine and arms). Both ways start from the walk imported with Blender's BVH
importer into the rig's scene:
- HumanAnim: humananim_addon.retarget.job.retarget (rotations per body role relative to each rig's
  rest pose, root scaled by leg length, feet planted, written to the controls the write-back's plan
  finds);
- Blender's own way: on each of the same controls a Copy Rotation constraint (world space, the
  rest offset kept: "Before Original") to the source's bone of the same role, plus Copy Location
  (world, offset kept) on the torso and the IK foot controls; then Bake Action (visual keying,
  constraints cleared) over the frames.
Measured: the seconds each takes, and on the deform bones as Blender evaluates each result the
largest slide of the point a planted foot stands on (the ball, else the toe tip) where the source's
foot is planted, and the lowest foot point (mm above the ground).
"""

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT.parent))
sys.path.insert(0, str(ROOT / "benchmarks"))
os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="humananim-user-"))

import bpy  # noqa: E402
import numpy as np  # noqa: E402

from machine import claim, emit, result  # noqa: E402

CMU_WALK = ROOT / "humananim_addon" / "data" / "mocap" / "cmu_131_01.bvh"


def rigify_rig():
    import addon_utils
    addon_utils.enable("rigify", default_set=True)
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.object.armature_human_metarig_add()
    bpy.ops.pose.rigify_generate()
    return bpy.context.active_object


def held_slide_and_lowest(obj, action, frames, planted):
    from humananim.humananim_addon.rig.physical import evaluated_pose, physical_skeleton
    from humananim.humananim_addon.retarget.job import held_slide
    from humananim.solver.cleanup import feet
    scene = bpy.context.scene
    skeleton = physical_skeleton(obj, scene)
    world = np.array(obj.matrix_world) @ evaluated_pose(obj, scene, skeleton, frames, action)
    points = feet.foot_points(skeleton, world)
    return 1000 * held_slide(points, planted), 1000 * min(float(p[..., 2].min()) for p in points.values())


def blender_way(source, target, frames):
    """Copy Rotation / Copy Location constraints on the controls, then Bake Action (visual keying)."""
    from humananim.humananim_addon.retarget.job import role_pairs
    from humananim.humananim_addon.rig.capability import RigView
    from humananim.humananim_addon.rig.writeback import plan_controls
    scene = bpy.context.scene
    src, tgt = RigView(source, scene).skeleton, RigView(target, scene).skeleton
    to_source = {b: a for a, b, _, _ in role_pairs(src, tgt)}
    plan = plan_controls(target, tgt, False)
    t0 = time.perf_counter()
    for h in plan.handles:
        if h.kind != "carry" or h.joint not in to_source:
            continue
        pb = target.pose.bones[h.control]
        bone = src.names[to_source[h.joint]]
        c = pb.constraints.new("COPY_ROTATION")
        c.target, c.subtarget, c.mix_mode = source, bone, "BEFORE"
        if h.joint == tgt.role_index("pelvis") or h.chain:
            c = pb.constraints.new("COPY_LOCATION")
            c.target, c.subtarget, c.use_offset = source, bone, True
    bpy.context.view_layer.objects.active = target
    bpy.ops.object.mode_set(mode="POSE")
    bpy.ops.pose.select_all(action="DESELECT")
    for name in plan.controls:  # selection lives on the pose bone from Blender 5.0, on the bone before
        pb = target.pose.bones[name]
        (pb if hasattr(pb, "select") else target.data.bones[name]).select = True
    bpy.ops.nla.bake(frame_start=int(frames[0]), frame_end=int(frames[1]), only_selected=True, visual_keying=True,
                     clear_constraints=True, bake_types={"POSE"})
    bpy.ops.object.mode_set(mode="OBJECT")
    return time.perf_counter() - t0, target.animation_data.action


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=1000, help="frames of the walk retargeted (default 1000)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    import humananim
    humananim.register()
    from humananim.humananim_addon.bvh_import import import_bvh
    from humananim.humananim_addon.retarget import job
    from humananim.humananim_addon.rig.capability import RigView
    target = rigify_rig()
    scene = bpy.context.scene
    source, _, _ = import_bvh(str(CMU_WALK), update_scene=False)
    frames = (1, args.frames)
    src_view = RigView(source, scene)
    src_traj = src_view.read(source.animation_data.action, frames)
    planted = job.source_contacts(src_view.skeleton, src_traj)
    t0 = time.perf_counter()
    summary = job.retarget(source, target, scene, frame_range=frames)
    ours_s = time.perf_counter() - t0
    ours = held_slide_and_lowest(target, bpy.data.actions[summary["action"]], src_traj.frames, planted)
    target.animation_data.action = None
    theirs_s, baked = blender_way(source, target, frames)
    theirs = held_slide_and_lowest(target, baked, src_traj.frames, planted)
    n = len(src_traj.frames)
    claims = [
        claim(f"seconds to retarget {n} frames of a walk onto a generated Rigify rig (HumanAnim)", ours_s, "s"),
        claim(f"seconds for Blender's own way (constraints + Bake Action, visual keying), {n} frames", theirs_s, "s"),
        claim("HumanAnim's time / Blender's own way's", ours_s / theirs_s, "x"),
        claim("planted-foot slide, HumanAnim (deform bones as Blender evaluates them)", ours[0], "mm", "<= 5",
              ours[0] <= 5.0),
        claim("planted-foot slide, Blender's own way", theirs[0], "mm"),
        claim("lowest foot point above the ground, HumanAnim", ours[1], "mm", ">= -1", ours[1] >= -1.0),
        claim("lowest foot point above the ground, Blender's own way", theirs[1], "mm"),
    ]
    out = result("retarget", claims, frames=n, clip=CMU_WALK.name, leg_ratio=summary["leg_ratio"],
                 mismatch_mm=summary.get("mismatch_mm"), mismatch_deg=summary.get("mismatch_deg"))
    if args.json:
        emit(out)
    else:
        for c in claims:
            print(f"{c['claim']}: {c['value']:.3g} {c['unit']}")
    import addon_utils
    addon_utils.disable("rigify", default_set=True)
    humananim.unregister()


if __name__ == "__main__":
    main()
