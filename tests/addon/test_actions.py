"""Reading actions into trajectories and writing them back, on real rigs and real motion."""

import math

import pytest

bpy = pytest.importorskip("bpy")
import numpy as np  # noqa: E402

from conftest import CMU_CLIPS, assert_same_pose, fcurve_snapshot, import_cmu, world_pose
from humananim.humananim_addon import action_api, actions
from humananim.humananim_addon.armature import skeleton_from_armature


def round_trip(obj, scene, exact=None):
    skeleton = skeleton_from_armature(obj, scene, require=False)
    source = obj.animation_data.action
    frames = actions.sample_frames(source, obj)
    before = world_pose(obj, scene, frames)
    keys_before = fcurve_snapshot(source, obj)
    traj = actions.read_action(obj, scene, skeleton, exact=exact)
    # the solver's forward kinematics reproduces Blender's pose from the trajectories
    assert_same_pose(traj.world_frames(skeleton), before)
    result = actions.write_action(obj, skeleton, traj, "roundtrip", "ACTION", source)
    assert obj.animation_data.action == result and result != source
    after = world_pose(obj, scene, frames)
    errors = assert_same_pose(after, before)
    # the source is untouched and protected
    assert fcurve_snapshot(source, obj).keys() == keys_before.keys()
    for key, co in keys_before.items():
        assert np.array_equal(fcurve_snapshot(source, obj)[key], co)
    assert source.use_fake_user
    return skeleton, traj, errors


@pytest.mark.parametrize("clip", CMU_CLIPS, ids=["131_01", "131_03"])
def test_cmu_clip_round_trips_every_frame(empty_scene, clip):
    obj = import_cmu(clip)
    skeleton, traj, _ = round_trip(obj, empty_scene)
    assert traj.frame_count == (995 if clip.endswith("01.bvh") else 1248)
    assert traj.fps == pytest.approx(120.0, rel=1e-4)
    # Euler bones stay Euler: the written action keys rotation_euler in the bones' own order
    paths = {fc.data_path.rsplit(".", 1)[1] for fc in action_api.fcurves_of(obj.animation_data.action, obj)}
    assert paths == {"location", "rotation_euler"}


def test_metarig_round_trip_with_every_rotation_mode(metarig, empty_scene):
    scene = bpy.context.scene
    obj = metarig
    modes = ["QUATERNION", "XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX", "AXIS_ANGLE"]
    rng = np.random.default_rng(3)
    bpy.ops.object.mode_set(mode="POSE")
    posed = list(obj.pose.bones)[:60]
    for i, pb in enumerate(posed):
        pb.rotation_mode = modes[i % len(modes)]
    for frame in range(1, 41, 8):
        for pb in posed:
            q = rng.normal(size=4)
            q /= np.linalg.norm(q)
            if pb.rotation_mode == "QUATERNION":
                pb.rotation_quaternion = q
                pb.keyframe_insert("rotation_quaternion", frame=frame)
            elif pb.rotation_mode == "AXIS_ANGLE":
                pb.rotation_axis_angle = (rng.uniform(0, 2 * math.pi), *rng.normal(size=3))
                pb.keyframe_insert("rotation_axis_angle", frame=frame)
            else:
                pb.rotation_euler = rng.uniform(-math.pi, math.pi, 3)
                pb.keyframe_insert("rotation_euler", frame=frame)
            if not pb.bone.use_connect:
                pb.location = rng.normal(scale=0.05, size=3)
                pb.keyframe_insert("location", frame=frame)
    bpy.ops.object.mode_set(mode="OBJECT")
    obj.location = (1.0, -2.0, 0.5)
    obj.rotation_euler = (0.1, 0.2, 0.7)
    bpy.context.view_layer.update()
    _, traj, _ = round_trip(obj, scene)
    assert traj.frame_count == 33
    assert np.allclose(np.linalg.norm(traj.rotations, axis=-1), 1.0)


def test_exact_path_matches_fcurve_path(cmu_rig, empty_scene):
    skeleton = skeleton_from_armature(cmu_rig, empty_scene)
    fast = actions.read_action(cmu_rig, empty_scene, skeleton, frame_range=(1, 200), exact=False)
    exact = actions.read_action(cmu_rig, empty_scene, skeleton, frame_range=(1, 200), exact=True)
    assert_same_pose(fast.world_frames(skeleton), exact.world_frames(skeleton))


def test_scaled_armature_is_read_in_metres(cmu_rig, empty_scene):
    skeleton_m = skeleton_from_armature(cmu_rig, empty_scene)
    cmu_rig.scale = (0.5, 0.5, 0.5)
    bpy.context.view_layer.update()
    skeleton = skeleton_from_armature(cmu_rig, empty_scene)
    assert skeleton.unit_scale == pytest.approx(0.5)
    assert np.allclose(skeleton.lengths, 0.5 * skeleton_m.lengths)
    round_trip(cmu_rig, empty_scene)


def test_key_times_sampling(cmu_rig, empty_scene):
    skeleton = skeleton_from_armature(cmu_rig, empty_scene)
    traj = actions.read_action(cmu_rig, empty_scene, skeleton, on_keys=True)
    assert traj.frame_count == 995


def test_nla_output_keeps_active_action(cmu_rig, empty_scene):
    skeleton = skeleton_from_armature(cmu_rig, empty_scene)
    source = cmu_rig.animation_data.action
    traj = actions.read_action(cmu_rig, empty_scene, skeleton, frame_range=(1, 50))
    result = actions.write_action(cmu_rig, skeleton, traj, "nla result", "NLA", source)
    tracks = cmu_rig.animation_data.nla_tracks
    assert tracks[-1].name == "HumanAnim: nla result"
    assert tracks[-1].strips[0].action == result
    assert cmu_rig.animation_data.action == source


def test_nan_keys_are_refused_with_a_message(cmu_rig, empty_scene):
    source = cmu_rig.animation_data.action
    fc = action_api.fcurves_of(source, cmu_rig)[5]
    fc.keyframe_points[10].co[1] = float("nan")
    fc.update()
    n_actions = len(bpy.data.actions)
    with pytest.raises(RuntimeError, match="NaN"):
        bpy.ops.humananim.bake_action()
    assert len(bpy.data.actions) == n_actions
    assert cmu_rig.animation_data.action == source


def test_bake_operator_writes_a_new_action(cmu_rig, empty_scene):
    source = cmu_rig.animation_data.action
    assert bpy.ops.humananim.bake_action() == {"FINISHED"}
    result = cmu_rig.animation_data.action
    assert result != source and result.name.startswith(source.name)
    assert "UNDO" in bpy.types.HUMANANIM_OT_bake_action.bl_options


def test_constraints_and_drivers_are_read_as_blender_shows_them(metarig, empty_scene):
    """A rig with a constraint and a driver: the F-curves alone would be wrong."""
    scene = bpy.context.scene
    obj = metarig
    bpy.ops.object.mode_set(mode="POSE")
    upper, forearm, hand = (obj.pose.bones[n] for n in ("upper_arm.L", "forearm.L", "hand.L"))
    for frame, angle in ((1, 0.0), (20, 1.2), (40, -0.4)):
        upper.rotation_mode = "XYZ"
        upper.rotation_euler = (angle, 0.3 * angle, 0.0)
        upper.keyframe_insert("rotation_euler", frame=frame)
    copy = forearm.constraints.new("COPY_ROTATION")
    copy.target, copy.subtarget, copy.mix_mode, copy.target_space, copy.owner_space = (
        obj, "upper_arm.L", "ADD", "LOCAL", "LOCAL")
    hand.rotation_mode = "XYZ"
    fcurve = hand.driver_add("rotation_euler", 0)
    fcurve.driver.expression = "frame / 40"
    bpy.ops.object.mode_set(mode="OBJECT")
    skeleton = skeleton_from_armature(obj, scene)
    assert actions.needs_evaluation(obj)
    frames = actions.sample_frames(obj.animation_data.action, obj)
    blender = world_pose(obj, scene, frames)
    traj = actions.read_action(obj, scene, skeleton)  # auto: through the depsgraph
    assert_same_pose(traj.world_frames(skeleton), blender)
    naive = actions.read_action(obj, scene, skeleton, exact=False)
    with pytest.raises(AssertionError):
        assert_same_pose(naive.world_frames(skeleton), blender)


def _stand_in_operator(reports):
    """What the modal steps need of an operator instance (bpy can't instantiate one headless)."""
    from types import SimpleNamespace
    cls = bpy.types.HUMANANIM_OT_bake_action
    op = SimpleNamespace(action="", output="SCENE", bl_label=cls.bl_label, bl_idname=cls.bl_idname,
                         report=lambda kind, text: reports.append((set(kind), text)))
    op.job = lambda context: cls.job(op, context)
    return op


def test_long_bake_shows_progress_and_finishes(cmu_rig, empty_scene, monkeypatch):
    from humananim.operators import common
    # timer ticks of 5 ms: the bake spans several ticks however fast the machine (at 50 ms one
    # fast machine did it in two)
    monkeypatch.setattr(common, "CHUNK_SECONDS", 0.005)
    empty_scene.humananim.exact = "DEPSGRAPH"
    source, reports, seen = cmu_rig.animation_data.action, [], []
    op = _stand_in_operator(reports)
    common.start_job(op, bpy.context)
    while (state := common.step_job(op, bpy.context)) == {"RUNNING_MODAL"}:
        seen.append(bpy.context.window_manager.humananim_progress)
        assert cmu_rig.animation_data.action == source  # nothing written before the end
    assert state == {"FINISHED"}
    assert len(seen) >= 2 and seen == sorted(seen) and 0.0 < seen[0] < seen[-1] <= 1.0
    assert cmu_rig.animation_data.action.name == f"{source.name}.baked"
    assert bpy.context.window_manager.humananim_progress == -1.0
    assert reports and "995 frames" in reports[-1][1]


def test_escape_cancels_a_bake_and_leaves_nothing(cmu_rig, empty_scene, monkeypatch):
    from humananim.operators import common
    monkeypatch.setattr(common, "CHUNK_SECONDS", 0.005)  # Esc comes within the bake on any machine
    empty_scene.humananim.exact = "DEPSGRAPH"
    empty_scene.frame_set(7)
    source, reports = cmu_rig.animation_data.action, []
    n_actions = len(bpy.data.actions)
    op = _stand_in_operator(reports)
    common.start_job(op, bpy.context)
    assert common.step_job(op, bpy.context) == {"RUNNING_MODAL"}
    assert common.cancel_job(op, bpy.context) == {"CANCELLED"}
    assert len(bpy.data.actions) == n_actions
    assert cmu_rig.animation_data.action == source and empty_scene.frame_current == 7
    assert reports[-1][0] == {"WARNING"} and "nothing written" in reports[-1][1]


def test_location_keys_on_connected_bones_are_ignored_like_blender(metarig, empty_scene):
    scene = bpy.context.scene
    bpy.ops.object.mode_set(mode="POSE")
    shin = metarig.pose.bones["shin.L"]
    assert shin.bone.use_connect
    for frame, z in ((1, 0.0), (10, 0.3)):
        shin.location = (0.0, 0.0, z)
        shin.keyframe_insert("location", frame=frame)
        shin.rotation_quaternion = (1.0, 0.2 * z, 0.0, 0.0)
        shin.keyframe_insert("rotation_quaternion", frame=frame)
    bpy.ops.object.mode_set(mode="OBJECT")
    skeleton = skeleton_from_armature(metarig, scene, require=False)
    traj = actions.read_action(metarig, scene, skeleton, exact=False)
    assert_same_pose(traj.world_frames(skeleton), world_pose(metarig, scene, traj.frames))
