"""Retarget Motion from every kind of source the issue names (issue 25, item 3): an FBX file made
with Blender's own exporter (through the operator and the command line), another armature in the
scene (the source picked from the selection; one of several armatures of an FBX file), a take
recorded by Live Capture; and the one-line refusals of sources that can't be retargeted. All onto
the procedural control rig, judged on its deform bones as Blender evaluates the new action: planted
feet hold where the source plants them, no foot goes below the ground, the stride scales with the
legs; and the same motion through FBX gives the same result as through BVH."""

import json
import os
import subprocess
import sys
import time
from types import SimpleNamespace

import pytest

bpy = pytest.importorskip("bpy")
import numpy as np  # noqa: E402

from control_rig import build_control_rig, build_mixamo_style  # noqa: E402
from humananim.humananim_addon.bvh_import import import_bvh  # noqa: E402
from humananim.humananim_addon.retarget import job  # noqa: E402
from humananim.humananim_addon.rig.capability import RigView  # noqa: E402
from humananim.humananim_addon.rig.load import import_fbx  # noqa: E402
from humananim.humananim_addon.rig.physical import evaluated_pose, physical_skeleton  # noqa: E402
from humananim.solver.cleanup import feet  # noqa: E402

pytestmark = pytest.mark.slow

ROOT = os.path.join(os.path.dirname(__file__), "..", "..")
CMU_WALK = os.path.join(ROOT, "humananim_addon", "data", "mocap", "cmu_131_01.bvh")
SLIDE_MM, BELOW_MM = 5.0, 1.0
FRAMES = (301, 340)  # of the BVH walk at the scene's 24 fps (it sets out slowly before); through FBX a frame later
# the bpy 4.2 module crashes at exit once Blender's FBX importer has run (tests/addon/test_rig_fbx.py)
FBX_CLI_CRASHES = bpy.app.version < (4, 3, 0)


# --- the sources ---------------------------------------------------------------------------------
def _key_rest_on_frame_zero(obj):
    """A key of every bone at rest on frame 0: Blender's FBX exporter writes the pose shown at
    export as the file's rest, so the file gets the BVH's own rest (as a capture's FBX has its
    T-pose), not a stride of the walk."""
    for pb in obj.pose.bones:
        pb.matrix_basis.identity()
        pb.location = (0.0, 0.0, 0.0)
        pb.rotation_quaternion = (1.0, 0.0, 0.0, 0.0)
        pb.rotation_euler = (0.0, 0.0, 0.0)
        pb.keyframe_insert("location", frame=0)
        pb.keyframe_insert("rotation_quaternion" if pb.rotation_mode == "QUATERNION" else "rotation_euler", frame=0)


def _export(objects, path, last_frame, first=0):
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = first, last_frame
    scene.frame_set(first)
    bpy.ops.object.select_all(action="DESELECT")
    for o in objects:
        o.select_set(True)
    bpy.context.view_layer.objects.active = objects[0]
    bpy.ops.export_scene.fbx(filepath=str(path), use_selection=True, object_types={"ARMATURE", "MESH"},
                             bake_anim=True, bake_anim_use_all_actions=False, bake_anim_use_nla_strips=False,
                             add_leaf_bones=True)
    return str(path)


@pytest.fixture(scope="module")
def sources(tmp_path_factory):
    """{kind: path}: the CMU walk as FBX ("walk"; "posed": exported on its frame 1 without the
    rest key, so the file's rest is the walk's first pose), the walk beside a Mixamo-style armature in one
    FBX ("two"), a mesh only ("mesh"), a keyed armature of two bones named for no body role
    ("stick"), and the control rig alone in a .blend at 24 fps ("rig"), at 30 fps ("rig30")."""
    folder = tmp_path_factory.mktemp("sources")
    out = {}
    bpy.ops.wm.read_homefile(use_empty=True)
    walk, _, _ = import_bvh(CMU_WALK, update_scene=False)
    out["posed"] = _export([walk], folder / "posed.fbx", FRAMES[1] + 1, first=1)
    _key_rest_on_frame_zero(walk)
    out["walk"] = _export([walk], folder / "walk.fbx", FRAMES[1] + 1)
    other = build_mixamo_style(fingers=False)
    out["two"] = _export([walk, other], folder / "two.fbx", FRAMES[1] + 1)
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.mesh.primitive_cube_add()
    bpy.context.active_object.keyframe_insert("location", frame=1)
    out["mesh"] = _export([bpy.context.active_object], folder / "mesh.fbx", 10)
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.object.armature_add()
    stick = bpy.context.active_object
    bpy.ops.object.mode_set(mode="EDIT")
    bone = stick.data.edit_bones.new("Twig")
    bone.head, bone.tail, bone.parent = (0, 0, 1), (0, 0, 2), stick.data.edit_bones["Bone"]
    bpy.ops.object.mode_set(mode="OBJECT")
    for f, angle in ((1, 0.0), (10, 0.5)):
        stick.pose.bones["Twig"].rotation_quaternion = (np.cos(angle), np.sin(angle), 0.0, 0.0)
        stick.pose.bones["Twig"].keyframe_insert("rotation_quaternion", frame=f)
    out["stick"] = _export([stick], folder / "stick.fbx", 10)
    bpy.ops.wm.read_homefile(use_empty=True)
    build_control_rig()
    out["rig"] = str(folder / "rig.blend")
    bpy.ops.wm.save_as_mainfile(filepath=out["rig"])
    scene = bpy.context.scene
    scene.render.fps, scene.frame_start, scene.frame_end, scene.frame_current = 30, 5, 77, 9
    out["rig30"] = str(folder / "rig30.blend")
    bpy.ops.wm.save_as_mainfile(filepath=out["rig30"])
    return out


def _target():
    target = build_control_rig()
    target.animation_data_create()
    return target


def _shown(obj, action, frames):
    """(skeleton, world pose (F, J, 4, 4)) of the deform bones as Blender evaluates `action`."""
    scene = bpy.context.scene
    skeleton = physical_skeleton(obj, scene)
    return skeleton, np.array(obj.matrix_world) @ evaluated_pose(obj, scene, skeleton, frames, action)


def _planted(source, action, frames):
    view = RigView(source, bpy.context.scene)
    traj = view.read(action, frames)
    return view, traj, job.source_contacts(view.skeleton, traj)


def _check_feet_and_stride(target, summary, source, frames):
    """The result on the deform bones: planted points held, nothing below the ground, the pelvis's
    travel the source's times the leg ratio. Returns the shown (skeleton, world pose)."""
    view, traj, planted = _planted(source, bpy.data.actions[summary["source_motion"]], frames)
    assert any(d.any() for d in planted.values()), "the source plants a foot"
    skeleton, world = _shown(target, bpy.data.actions[summary["action"]], traj.frames)
    points = feet.foot_points(skeleton, world)
    assert job.held_slide(points, planted) <= SLIDE_MM / 1000
    assert min(float(p[..., 2].min()) for p in points.values()) >= -BELOW_MM / 1000
    src_pelvis = traj.world_frames(view.skeleton)[:, view.skeleton.role_index("pelvis"), :3, 3]
    pelvis = world[:, skeleton.role_index("pelvis"), :3, 3]
    src_travel = np.linalg.norm(src_pelvis[-1, :2] - src_pelvis[0, :2])
    assert src_travel > 0.15, "the source moves on"
    travel = np.linalg.norm(pelvis[-1, :2] - pelvis[0, :2])
    assert travel / src_travel == pytest.approx(summary["leg_ratio"], rel=0.05)
    # the figure the user is shown measures every planted point, the toe tip too while the ball is down
    assert summary["planted_slide_mm"] <= SLIDE_MM and summary["lowest_foot_mm"] >= -BELOW_MM
    return skeleton, world


def _angle_deg(a, b):
    a = a[..., :3, :3] / np.linalg.norm(a[..., :3, :3], axis=-2, keepdims=True)
    b = b[..., :3, :3] / np.linalg.norm(b[..., :3, :3], axis=-2, keepdims=True)
    cos = (np.trace(np.swapaxes(a, -1, -2) @ b, axis1=-2, axis2=-1) - 1.0) / 2.0
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


# --- 1. an FBX file ------------------------------------------------------------------------------
def test_the_walk_through_fbx_retargets_as_through_bvh(empty_scene, sources):
    """The FBX import as the source of the operator; the BVH import of the same walk through the
    job: the deform bones land within a millimetre and a degree of each other on every frame."""
    bvh, _, _ = import_bvh(CMU_WALK, update_scene=False)
    fbx = import_fbx(sources["walk"])
    shift = int(round(fbx.animation_data.action.frame_range[0]))  # the rest key's frame 0, shown on 1
    assert shift == 1
    target = _target()
    from_bvh = job.retarget(bvh, target, empty_scene, frame_range=FRAMES)
    bvh_shown = _check_feet_and_stride(target, from_bvh, bvh, FRAMES)[1]
    fbx_frames = (FRAMES[0] + shift, FRAMES[1] + shift)
    bpy.ops.object.select_all(action="DESELECT")
    bpy.context.view_layer.objects.active = target
    assert bpy.ops.humananim.retarget_motion(source=fbx.name, frame_start=fbx_frames[0],
                                             frame_end=fbx_frames[1]) == {"FINISHED"}
    from_fbx = job.stored(target)
    assert from_fbx["source"] == fbx.name and target.animation_data.action.name == from_fbx["action"]
    assert from_fbx["roles_mapped"] == from_bvh["roles_mapped"]
    assert "source_rest_warning" not in from_fbx and "source_rest_warning" not in from_bvh
    assert from_fbx["leg_ratio"] == pytest.approx(from_bvh["leg_ratio"], abs=1e-3)
    fbx_shown = _check_feet_and_stride(target, from_fbx, fbx, fbx_frames)[1]
    gap_mm = 1000 * np.linalg.norm(fbx_shown[..., :3, 3] - bvh_shown[..., :3, 3], axis=-1)
    # what the FBX round trip itself loses (the exporter's curve simplification, float32): the
    # sources' own joints through FBX and through BVH
    fbx_skeleton, fbx_source = _shown(fbx, None, np.arange(fbx_frames[0], fbx_frames[1] + 1))
    bvh_skeleton, bvh_source = _shown(bvh, None, np.arange(FRAMES[0], FRAMES[1] + 1))
    lost = max(1000 * np.linalg.norm(fbx_source[:, fbx_skeleton.index(n), :3, 3] - bvh_source[:, j, :3, 3],
                                     axis=-1).max() for j, n in enumerate(bvh_skeleton.names))
    print(f"FBX against BVH: sources {lost:.2f} mm apart, results {gap_mm.max():.2f} mm "
          f"(mean {gap_mm.mean():.2f}), {_angle_deg(fbx_shown, bvh_shown).max():.2f} deg")
    assert lost < 5.0, "the FBX round trip keeps the walk"
    # the retarget adds nothing to it: the results differ no more than the sources, scaled to the legs
    assert gap_mm.max() <= from_bvh["leg_ratio"] * lost + 0.5 and gap_mm.mean() < 1.0
    assert _angle_deg(fbx_shown, bvh_shown).max() < 1.0
    assert bvh.animation_data.action.name == from_bvh["source_motion"]  # the sources keep their actions
    assert fbx.animation_data.action.name == from_fbx["source_motion"]


def _posed_source(sources):
    """(the BVH walk, the "posed" FBX walk, its frames): the same motion, one with a T-pose rest,
    the other with the capture's first pose as its rest."""
    bvh, _, _ = import_bvh(CMU_WALK, update_scene=False)
    fbx = import_fbx(sources["posed"])
    shift = int(round(fbx.animation_data.action.frame_range[0]))  # the export's frame 1, shown on 2
    assert shift == 2
    return bvh, fbx, (FRAMES[0] + shift - 1, FRAMES[1] + shift - 1)


def test_a_source_posed_at_rest_keeps_its_feet_and_sets_out_where_it_does(empty_scene, sources, caplog):
    """Blender's FBX exporter writes the pose shown at export as the file's rest: the walk's first
    pose. Measured from that rest, the motion still plants its feet, stays on the ground, strides
    by the legs' ratio and sets out from the source's first point (it started 0.28 m away when
    the path was turned about the world's origin)."""
    _, fbx, frames = _posed_source(sources)
    target = _target()
    bpy.context.view_layer.objects.active = target
    assert bpy.ops.humananim.retarget_motion(source=fbx.name, frame_start=frames[0],
                                             frame_end=frames[1]) == {"FINISHED"}
    summary = job.stored(target)
    assert "rest pose looks captured" in summary["source_rest_warning"]  # said, in the panel's lines too
    assert any(line.startswith("warning: the source's rest") for line in job.lines(summary))
    said = [r for r in caplog.records if "retarget_motion" in r.getMessage()]
    assert said and said[-1].levelname == "WARNING" and "rest pose looks captured" in said[-1].getMessage()
    skeleton, world = _check_feet_and_stride(target, summary, fbx, frames)
    source_skeleton, source = _shown(fbx, None, frames[:1])
    start = source[0, source_skeleton.role_index("pelvis"), :2, 3]
    assert np.linalg.norm(world[0, skeleton.role_index("pelvis"), :2, 3] - start) < 0.005


@pytest.mark.xfail(strict=True, reason="docs/rigs.md, Sources: each bone's turn is measured from the source's "
                   "rest; a rest that is a captured pose (its bones twisted, arms hanging) moves the result "
                   "(the hands up to 170 mm away on CMU 131_01)")
def test_a_source_posed_at_rest_retargets_as_from_a_t_pose(empty_scene, sources):
    bvh, fbx, frames = _posed_source(sources)
    target = _target()
    from_bvh = job.retarget(bvh, target, empty_scene, frame_range=FRAMES)
    bvh_shown = _shown(target, bpy.data.actions[from_bvh["action"]], np.arange(FRAMES[0], FRAMES[1] + 1))[1]
    from_fbx = job.retarget(fbx, target, empty_scene, frame_range=frames)
    fbx_shown = _shown(target, bpy.data.actions[from_fbx["action"]], np.arange(frames[0], frames[1] + 1))[1]
    assert np.linalg.norm(fbx_shown[..., :3, 3] - bvh_shown[..., :3, 3], axis=-1).max() < 0.005
    assert _angle_deg(fbx_shown, bvh_shown).max() < 2.0


def _cli(*args):
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    return subprocess.run([sys.executable, "-m", "humananim", "retarget", *args], capture_output=True, text=True,
                          env=env, timeout=600)


def _one_line(r, words):
    assert r.returncode == 2, r.stderr
    ours = [line for line in r.stderr.splitlines() if line.startswith("humananim")]  # not Blender's own log
    assert len(ours) == 1 and words in ours[0] and "Traceback" not in r.stderr, r.stderr


@pytest.mark.skipif(FBX_CLI_CRASHES, reason="the bpy 4.2 module crashes at exit after Blender's FBX importer")
def test_the_command_retargets_an_fbx_walk(empty_scene, sources, tmp_path):
    """Into a scene at 30 fps (the file is at 24): the scene keeps its rate, range and frame (the
    FBX importer sets them to the file's), the walk is read at the scene's rate, as a BVH is."""
    out = str(tmp_path / "out.blend")
    ratio = 30 / 24
    frames = (int(1 + FRAMES[0] * ratio), int(1 + FRAMES[1] * ratio))  # the file's frames 302-341
    r = _cli(sources["walk"], "--to", sources["rig30"], "--armature", "Puppet", "--frames", *map(str, frames),
             "--out", out, "--json")
    assert r.returncode == 0, r.stderr
    summary = json.loads(r.stdout)
    assert summary["armature"] == "Puppet" and summary["wrote"] == [os.path.abspath(out)]
    assert summary["frame_range"] == [float(frames[0]), float(frames[1])] and summary["fps"] == 30
    assert summary["planted_slide_mm"] <= SLIDE_MM and summary["lowest_foot_mm"] >= -BELOW_MM
    assert max(mm for mm, _ in summary["mismatch_per_role"].values()) < 1.0
    # the saved scene: its own rate and range, the new action on the rig, judged like the operator's
    bpy.ops.wm.open_mainfile(filepath=out)
    scene = bpy.context.scene
    assert (scene.render.fps, scene.frame_start, scene.frame_end, scene.frame_current) == (30, 5, 77, 9)
    target, source = bpy.data.objects["Puppet"], bpy.data.objects[summary["source"]]
    last = (FRAMES[1] + 2 - 1) * ratio + 1  # the file's last frame (342 at 24 fps), at 30 fps
    assert source.animation_data.action.frame_range[1] == pytest.approx(last, abs=1e-3)
    assert target.animation_data.action.name == summary["action"]
    _check_feet_and_stride(target, summary, source, frames)


def test_the_reported_slide_counts_the_toe_tips(empty_scene):
    """The figure the operator and the command report measures every planted point, the toe tip
    too while the ball is down: on the first 240 frames of the CMU walk the right toe tip, held
    by turning the toe alone, once slid 14.4 mm where holding it needed the foot raised."""
    bvh, _, _ = import_bvh(CMU_WALK, update_scene=False)
    target = _target()
    summary = job.retarget(bvh, target, empty_scene, frame_range=(1, 240))
    assert summary["planted_slide_mm"] <= SLIDE_MM and summary["lowest_foot_mm"] >= -BELOW_MM
    _, traj, planted = _planted(bvh, bvh.animation_data.action, (1, 240))
    assert planted["R"][:, 1].sum() > 100, "the right toe tip is down a long while"


# --- 2. another armature in the scene ------------------------------------------------------------
def test_the_selected_armature_is_the_source(empty_scene):
    """As a user does it: the BVH import selected, the rig active, Retarget Motion invoked with no
    source named (the operator's invoke called directly: the bpy module runs only execute)."""
    from humananim.operators.retarget import HUMANANIM_OT_retarget_motion
    bvh, _, _ = import_bvh(CMU_WALK, update_scene=False)
    target = _target()
    bpy.ops.object.select_all(action="DESELECT")
    bvh.select_set(True)
    target.select_set(True)
    bpy.context.view_layer.objects.active = target
    picked = SimpleNamespace(source="", execute=lambda context: {"FINISHED"})
    assert HUMANANIM_OT_retarget_motion.invoke(picked, bpy.context, None) == {"FINISHED"}
    assert picked.source == bvh.name
    assert bpy.ops.humananim.retarget_motion(source=picked.source, frame_start=FRAMES[0],
                                             frame_end=FRAMES[1]) == {"FINISHED"}
    summary = job.stored(target)
    assert summary["source"] == bvh.name
    _check_feet_and_stride(target, summary, bvh, FRAMES)


def test_one_armature_of_an_fbx_with_several(empty_scene, sources):
    """Both armatures of the file in the scene: the walk named as the source is retargeted, the
    other left alone."""
    before = set(bpy.data.objects)
    bpy.ops.import_scene.fbx(filepath=sources["two"], use_anim=True)
    armatures = {o.name: o for o in bpy.data.objects if o not in before and o.type == "ARMATURE"}
    assert len(armatures) == 2 and "Mixamo" in armatures
    walk = next(o for n, o in armatures.items() if n != "Mixamo")
    target = _target()
    bpy.context.view_layer.objects.active = target
    assert bpy.ops.humananim.retarget_motion(source=walk.name, frame_start=FRAMES[0] + 1,
                                             frame_end=FRAMES[1] + 1) == {"FINISHED"}
    summary = job.stored(target)
    assert summary["source"] == walk.name
    _check_feet_and_stride(target, summary, walk, (FRAMES[0] + 1, FRAMES[1] + 1))


@pytest.mark.skipif(FBX_CLI_CRASHES, reason="the bpy 4.2 module crashes at exit after Blender's FBX importer")
def test_the_command_reads_the_named_armature_of_an_fbx_with_several(empty_scene, sources, tmp_path):
    out = str(tmp_path / "out.blend")
    common = ("--to", sources["rig"], "--frames", str(FRAMES[0] + 1), str(FRAMES[1] + 1), "--out", out)
    r = _cli(sources["two"], *common)
    _one_line(r, "--source-armature")  # the option of this command, not another's
    assert not os.path.exists(out)
    r = _cli(sources["two"], *common, "--source-armature", "Nobody")
    _one_line(r, "no armature named 'Nobody'")
    r = _cli(sources["two"], *common, "--source-armature", "Mixamo", "--json")
    assert r.returncode == 0, r.stderr
    summary = json.loads(r.stdout)
    assert summary["source"] == "Mixamo" and os.path.isfile(out)
    r = _cli(sources["two"], *common, "--source-armature", "cmu_131_01", "--json")
    assert r.returncode == 0, r.stderr
    summary = json.loads(r.stdout)
    assert summary["source"].startswith("cmu_131_01")
    assert summary["planted_slide_mm"] <= SLIDE_MM and summary["lowest_foot_mm"] >= -BELOW_MM


# --- 3. a live-capture take ----------------------------------------------------------------------
def test_a_live_capture_take_is_a_source(cmu_rig):
    """The CMU walk replayed as a live device onto the BVH armature, a take recorded (the action
    Live Capture writes), then that take retargeted onto the control rig."""
    pytest.importorskip("serial")
    from humananim.humananim_addon.capture import job as capture
    scene = bpy.context.scene
    capture.add_device(scene, "REPLAY", name="replay", filepath=CMU_WALK)
    try:
        assert "FINISHED" in bpy.ops.humananim.capture_live()
        live = capture.LIVE
        assert "FINISHED" in bpy.ops.humananim.capture_record()
        end = time.perf_counter() + 2.5
        while time.perf_counter() < end:
            live.session.pump()
            live.step(bpy.context)
            time.sleep(1 / 60)
        take_action, take = live.stop_recording(bpy.context)
    finally:
        capture.disconnect()
    assert take_action is not None and cmu_rig.animation_data.action == take_action
    first, last = (int(np.ceil(take_action.frame_range[0])), int(np.floor(take_action.frame_range[1])))
    assert last - first >= 30, "the take holds more than a second of the walk"
    target = _target()
    bpy.context.view_layer.objects.active = target
    assert bpy.ops.humananim.retarget_motion(source=cmu_rig.name, frame_start=first,
                                             frame_end=last) == {"FINISHED"}
    summary = job.stored(target)
    assert summary["source_motion"] == take_action.name and "source_rest_warning" not in summary
    _check_feet_and_stride(target, summary, cmu_rig, (first, last))
    assert cmu_rig.animation_data.action == take_action


# --- 4. sources that can't be retargeted ---------------------------------------------------------
@pytest.mark.skipif(FBX_CLI_CRASHES, reason="the bpy 4.2 module crashes at exit after Blender's FBX importer")
@pytest.mark.parametrize("kind,words", [("mesh", "no armature"), ("stick", "body role")])
def test_the_command_refuses_a_source_it_cannot_read(sources, tmp_path, kind, words):
    out = str(tmp_path / "out.blend")
    _one_line(_cli(sources[kind], "--to", sources["rig"], "--out", out), words)
    assert not os.path.exists(out)


def test_the_operator_refuses_a_source_without_body_roles(empty_scene, sources):
    stick = import_fbx(sources["stick"])
    target = _target()
    bpy.context.view_layer.objects.active = target
    with pytest.raises(RuntimeError, match="role"):
        bpy.ops.humananim.retarget_motion(source=stick.name)
    assert target.animation_data.action is None
