"""Retarget Motion: a capture (the bundled CMU walk, a Bandai Namco walk) put on the procedural
control rig's controls. Checked on the deform bones as Blender evaluates the new action: planted
feet hold where the source's are planted, no foot goes below the ground, the stride scales with
the legs, the source is untouched; and the command's refusals."""

import os
import subprocess
import sys

import pytest

bpy = pytest.importorskip("bpy")
import numpy as np  # noqa: E402

from conftest import MOCAP  # noqa: E402
from control_rig import build_control_rig  # noqa: E402
from humananim.humananim_addon.bvh_import import import_bvh  # noqa: E402
from humananim.humananim_addon.retarget import job  # noqa: E402
from humananim.humananim_addon.rig.capability import RigView  # noqa: E402
from humananim.humananim_addon.rig import writeback as rig_writeback  # noqa: E402
from humananim.humananim_addon.rig.physical import evaluated_pose, physical_skeleton  # noqa: E402
from humananim.solver import rotations  # noqa: E402
from humananim.solver.cleanup import feet  # noqa: E402

pytestmark = pytest.mark.slow

ROOT = os.path.join(os.path.dirname(__file__), "..", "..")
CMU_WALK = os.path.join(ROOT, "humananim_addon", "data", "mocap", "cmu_131_01.bvh")
BANDAI_WALK = os.path.join(MOCAP, "bandai-namco-1", "dataset-1_walk_normal_002.bvh")
SLIDE_MM, BELOW_MM = 5.0, 1.0


def _shown_feet(obj, action, frames):
    """(foot points {side: (F, k, 3)}, pelvis (F, 3)) of the deform bones as Blender evaluates `action`."""
    scene = bpy.context.scene
    skeleton = physical_skeleton(obj, scene)
    world = np.array(obj.matrix_world) @ evaluated_pose(obj, scene, skeleton, frames, action)
    return feet.foot_points(skeleton, world), world[:, skeleton.role_index("pelvis"), :3, 3]


@pytest.mark.parametrize("clip,frames", [(CMU_WALK, (1, 240)), (BANDAI_WALK, (1, 90))])
def test_a_walk_retargeted_onto_a_control_rig_keeps_its_feet_planted(empty_scene, clip, frames):
    if not os.path.isfile(clip):
        pytest.skip(f"no {clip}")
    source, _, _ = import_bvh(clip)
    source_action = source.animation_data.action
    src_view = RigView(source, empty_scene)
    src_traj = src_view.read(source_action, frames)
    planted = job.source_contacts(src_view.skeleton, src_traj)
    assert all(d.any() for d in planted.values()), "the source walk plants both feet"
    keys_before = {fc.data_path: fc.evaluate(frames[0] + 7) for fc in _fcurves(source_action, source)}
    target = build_control_rig()
    target.animation_data_create()
    bpy.context.view_layer.objects.active = target
    source.select_set(True)
    assert bpy.ops.humananim.retarget_motion(source=source.name, frame_start=frames[0], frame_end=frames[1]) == {"FINISHED"}
    result = target.animation_data.action
    summary = job.stored(target)
    assert result is not None and result.name == summary["action"]
    # the write-back's report: every joint where the solve puts it; every role's turn shown within
    # 1 deg but the IK legs' thighs and shins, whose roll about their own axis the rig's IK chooses
    # (docs/rigs.md: a known limit of the write-back)
    report = summary["mismatch_per_role"]
    assert max(mm for mm, _ in report.values()) < 1.0, report
    assert max(deg for r, (_, deg) in report.items() if r.split(".")[0] not in ("thigh", "shin")) < 1.0, report
    # the retarget turns the IK legs into the plane the IK shows them in: thighs and shins too now
    assert max(deg for _, deg in report.values()) < 0.5, report
    assert set(summary["mismatch_per_role"]) >= {"pelvis", "foot.L", "foot.R", "hand.L", "hand.R", "head"}
    points, pelvis = _shown_feet(target, result, src_traj.frames)
    assert job.held_slide(points, planted) <= SLIDE_MM / 1000
    assert min(float(p[..., 2].min()) for p in points.values()) >= -BELOW_MM / 1000
    # the stride scales with the legs: the pelvis travels the source's path times the leg ratio
    src_pelvis = src_traj.world_frames(src_view.skeleton)[:, src_view.skeleton.role_index("pelvis"), :3, 3]
    travel = np.linalg.norm(pelvis[-1, :2] - pelvis[0, :2]) / np.linalg.norm(src_pelvis[-1, :2] - src_pelvis[0, :2])
    assert np.linalg.norm(src_pelvis[-1, :2] - src_pelvis[0, :2]) > 0.3, "the source walks"
    assert travel == pytest.approx(summary["leg_ratio"], rel=0.05)
    # the source is untouched
    assert source.animation_data.action == source_action
    assert {fc.data_path: fc.evaluate(frames[0] + 7) for fc in _fcurves(source_action, source)} == keys_before


def test_the_ik_legs_follow_the_whole_cmu_walk(empty_scene):
    """The bundled CMU walk (120 fps) at the scene's own frame rate, as the command reads it: over
    frames 1-240 the foot repair holds the left leg straight at the end (frames 234-240), where the
    write-back once placed the knee pole off by up to 90 deg (thigh and shin turned, a QA pop at
    frame 234). Every role as Blender evaluates the deform bones: within 0.5 deg of the retargeted
    pose on every frame; hands and feet within 1 mm, every joint within 1.2 mm (a straight IK leg
    stops a few micrometres short of its full reach, its knee 1.1 mm off the line); and no QA pop
    that the source doesn't have."""
    from humananim.humananim_addon.qa.job import measure_result
    from humananim.humananim_addon.rig import writeback
    source, _, _ = import_bvh(CMU_WALK, update_scene=False)
    target = build_control_rig()
    target.animation_data_create()
    seen = {}
    write = writeback.write_pose_steps

    def spy(obj, scene, skeleton, frames, solved, *a, **k):
        seen.update(skeleton=skeleton, frames=np.asarray(frames), solved=np.array(solved))
        return (yield from write(obj, scene, skeleton, frames, solved, *a, **k))
    from humananim.humananim_addon.rig import capability
    capability.write_pose_steps = spy
    try:
        summary = job.retarget(source, target, empty_scene, frame_range=(1, 240))
    finally:
        capability.write_pose_steps = write
    result = bpy.data.actions[summary["action"]]
    skeleton, frames, solved = seen["skeleton"], seen["frames"], seen["solved"]
    shown = evaluated_pose(target, empty_scene, skeleton, frames, result)
    shown[..., :3, :3] /= np.linalg.norm(shown[..., :3, :3], axis=-2, keepdims=True)
    worst = {}
    for j, name in enumerate(skeleton.names):
        role = skeleton.roles.role_of(name)
        if role is None:
            continue
        rel = np.swapaxes(shown[:, j, :3, :3], -1, -2) @ solved[:, j, :3, :3]
        deg = np.degrees(np.arccos(np.clip((np.trace(rel, axis1=-2, axis2=-1) - 1) / 2, -1, 1)))
        mm = 1000 * np.linalg.norm(shown[:, j, :3, 3] * skeleton.unit_scale - solved[:, j, :3, 3], axis=-1)
        worst[role] = (float(mm.max()), float(deg.max()), float(frames[deg.argmax()]))
    assert max(deg for _, deg, _ in worst.values()) < 0.5, worst
    assert max(mm for r, (mm, _, _) in worst.items() if r.split(".")[0] in ("hand", "foot")) < 1.0, worst
    assert max(mm for mm, _, _ in worst.values()) < 1.2, worst
    assert max(deg for _, deg in summary["mismatch_per_role"].values()) < 0.5, summary["mismatch_per_role"]
    qa = measure_result(target, empty_scene, result, frame_range=(1, 240), store=False)
    own = measure_result(source, empty_scene, source.animation_data.action, frame_range=(1, 240), store=False)
    for kind in ("pop_velocity", "pop_acceleration"):
        mine, theirs = qa["measures"][kind], own["measures"][kind]
        assert mine["passed"] or not theirs["passed"], (kind, mine, theirs)


def _fcurves(action, obj):
    from humananim.humananim_addon.action_api import fcurves_of
    return fcurves_of(action, obj)


def test_retarget_refuses_a_target_without_body_roles(empty_scene):
    from humananim.solver.errors import HumanAnimError
    source, _, _ = import_bvh(CMU_WALK)
    bpy.ops.object.armature_add()
    stick = bpy.context.active_object
    with pytest.raises(HumanAnimError):
        job.retarget(source, stick, empty_scene, frame_range=(1, 10))
    assert stick.animation_data is None or stick.animation_data.action is None


def _cli(*args):
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    return subprocess.run([sys.executable, "-m", "humananim", "retarget", *args], capture_output=True, text=True,
                          env=env, timeout=600)


def test_the_command_refuses_bad_input_with_exit_2(empty_scene, tmp_path):
    build_control_rig()
    scene_file = str(tmp_path / "rig.blend")
    bpy.ops.wm.save_as_mainfile(filepath=scene_file)
    for args, words in (((CMU_WALK, "--to", scene_file, "--armature", "Nobody"), "no armature named 'Nobody'"),
                        ((str(tmp_path / "none.bvh"), "--to", scene_file), "no such file"),
                        ((CMU_WALK, "--to", CMU_WALK), "expected the .blend")):
        r = _cli(*args, "--out", str(tmp_path / "out.blend"))
        assert r.returncode == 2, r.stderr
        ours = [line for line in r.stderr.splitlines() if line.startswith("humananim")]  # not Blender's own log
        assert len(ours) == 1 and words in ours[0] and "Traceback" not in r.stderr, r.stderr
    assert not (tmp_path / "out.blend").exists()


def test_the_command_retargets_a_walk_onto_the_rig(empty_scene, tmp_path):
    import json
    build_control_rig()
    scene_file = str(tmp_path / "rig.blend")
    bpy.ops.wm.save_as_mainfile(filepath=scene_file)
    out = str(tmp_path / "out.blend")
    r = _cli(CMU_WALK, "--to", scene_file, "--armature", "Puppet", "--frames", "1", "40", "--out", out, "--json")
    assert r.returncode == 0, r.stderr
    summary = json.loads(r.stdout)
    assert summary["armature"] == "Puppet" and summary["wrote"] == [os.path.abspath(out)] or os.path.isfile(out)
    assert summary["mismatch_per_role"]["foot.L"][0] < 1.0


def test_the_cmu_walk_onto_a_generated_rigify_rig(generated_rigify_file):
    """Onto Rigify's controls (IK feet, torso, FK spine and arms): a short stretch of the walk (the
    write-back takes about 0.2 s per frame there) with the right foot planted throughout."""
    path, name = generated_rigify_file
    bpy.ops.wm.open_mainfile(filepath=path)
    scene = bpy.context.scene
    target = bpy.data.objects[name]
    source, _, _ = import_bvh(CMU_WALK, update_scene=False)
    frames = (1, 40)
    src_view = RigView(source, scene)
    src_traj = src_view.read(source.animation_data.action, frames)
    planted = job.source_contacts(src_view.skeleton, src_traj)
    assert planted["R"].any(), "the source plants its right foot here"
    summary = job.retarget(source, target, scene, frame_range=frames)
    result = bpy.data.actions[summary["action"]]
    report = summary["mismatch_per_role"]
    assert max(report[r][0] for r in ("foot.L", "foot.R")) < 1.0, report
    points, _ = _shown_feet(target, result, src_traj.frames)
    assert job.held_slide(points, planted) <= SLIDE_MM / 1000
    assert min(float(p[..., 2].min()) for p in points.values()) >= -BELOW_MM / 1000
    # docs/rigs.md: the pelvis, hung from the FK spine, placed through the rig as Blender evaluates
    # it; the knees (elbows) through the tweak controls their deform bones copy, wherever Rigify's
    # stretchy IK puts its chain; the thighs and upper arms rolled by theirs
    body = ("pelvis", "spine", "chest", "neck", "head") + tuple(
        f"{r}.{s}" for s in "LR" for r in ("thigh", "shin", "foot", "toe", "clavicle", "upper_arm", "forearm", "hand"))
    assert max(report[r][0] for r in body) < 1.0, report
    assert max(report[r][1] for r in body if not r.startswith("forearm")) < 0.5, report
    # the fingers (CMU has a thumb and one finger bone a hand): the first segments, which Rigify
    # only swings from the palm (a Stretch To), retargeted with the roll the rig gives them (were
    # 178 and 74 deg off at the thumbs, 17 deg at the index fingers)
    fingers = [r for r in report if r.split(".")[0] in ("thumb", "index", "middle", "ring", "pinky")]
    assert {"thumb.L", "thumb.R", "index.L", "index.R"} <= set(fingers), report
    assert max(report[r][0] for r in fingers) < 1.0, report
    assert max(report[r][1] for r in fingers) < 0.5, report
    # the hands follow the forearms as the source's do (its wrists are zero-length joints, whose
    # axis the importer points back up the forearm): the hand as Blender shows it never folded
    skel = physical_skeleton(target, scene)
    shown = evaluated_pose(target, scene, skel, src_traj.frames, result)
    for s in "LR":
        arm, hand = (skel.role_index(f"{r}.{s}") for r in ("forearm", "hand"))
        a, h = shown[:, arm, :3, 1], shown[:, hand, :3, 1]
        cos = np.sum(a * h, axis=-1) / (np.linalg.norm(a, axis=-1) * np.linalg.norm(h, axis=-1))
        assert np.degrees(np.arccos(np.clip(cos, -1, 1))).max() < 60.0
    # the controls settled through the rig that the animator turns about one axis only (Rigify's
    # knee and elbow tweaks turn about Y) keyed with that turn only: placed freely, the forearm
    # tweaks took up to 74 deg about their locked X here and drifted frame after frame, until on the
    # whole walk (frames 1-1000) Rigify showed the forearms 179.6 deg turned about their own axes
    plan = rig_writeback.plan_controls(target, skel)
    settled = [target.pose.bones[h.control] for h in plan.handles if h.kind == "settle"]
    one_axis = [pb for pb in settled if sum(not lock for lock in pb.lock_rotation) == 1]
    assert {"forearm_tweak.L", "forearm_tweak.R"} <= {pb.name for pb in one_axis}
    # a pole-less IK chain's top (Rigify's upper_arm_ik) isn't turned again each frame by the
    # previous frame's turn: the left one spun 5 deg a frame (190 deg over these 40 frames)
    tops = [target.pose.bones[h.control] for h in plan.handles if h.kind == "twist"]
    assert tops
    firsts = {}
    for f in (src_traj.frames[0], src_traj.frames[len(src_traj.frames) // 2], src_traj.frames[-1]):
        scene.frame_set(int(f))
        for pb in tops:
            turn = np.array(pb.matrix_basis)[:3, :3]
            first = firsts.setdefault(pb.name, turn)
            cos = (np.trace(first.T @ turn) - 1.0) / 2.0
            assert np.degrees(np.arccos(np.clip(cos, -1, 1))) < 30.0, (f, pb.name)
        for pb in one_axis:
            q = rotations.from_matrix(np.array(pb.matrix_basis)[:3, :3])
            locked = [q[1 + i] for i in range(3) if pb.lock_rotation[i]]
            assert np.degrees(2 * np.arcsin(np.linalg.norm(locked))) < 1e-3, (f, pb.name, q)
    worst = {r: report[r] for r in ("forearm.L", "forearm.R") if report[r][1] >= 0.5}
    if worst:  # the forearm's tweak is blended into its own aim: 0.3-0.5 deg at worst
        pytest.xfail(f"Rigify shows these roles off the retargeted pose: {worst}")


def test_a_zero_length_source_joint_points_to_its_descendants(empty_scene):
    """CMU's wrists have their hand bone starting at their own head: the importer gives them an axis
    of its own choosing (up the forearm in Blender 5.0); the retarget takes their direction from
    the finger bones beyond them."""
    source, _, _ = import_bvh(CMU_WALK, update_scene=False)
    skel = RigView(source, bpy.context.scene).skeleton
    for s in ("Left", "Right"):
        wrist, elbow = skel.index(f"{s}Wrist"), skel.index(f"{s}Elbow")
        forearm = skel.rest[wrist, :3, 3] - skel.rest[elbow, :3, 3]
        d = job._direction(skel, skel.rest, wrist, None)
        assert np.dot(d, forearm / np.linalg.norm(forearm)) > 0.9
