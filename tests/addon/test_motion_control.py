"""Dynamic motion control in Blender: the operator, loads, impulses from arrow Empties,
colliders, bad input, and the viewport overlay's geometry, on a CMU import and the metarig."""

import math

import pytest

bpy = pytest.importorskip("bpy")
import numpy as np  # noqa: E402
from mathutils import Vector  # noqa: E402

from conftest import fcurve_snapshot, world_pose  # noqa: E402
from humananim.humananim_addon import action_api, actions  # noqa: E402
from humananim.humananim_addon.motion_control import job as motion_control  # noqa: E402
from humananim.humananim_addon.motion_control import overlay  # noqa: E402
from humananim.humananim_addon.synthesis import job as synthesis  # noqa: E402
from humananim.humananim_addon.armature import skeleton_from_armature  # noqa: E402

pytestmark = pytest.mark.slow

FRAMES = (1, 96)  # 0.8 s of the 120 fps walk: enough for a push to show


@pytest.fixture
def cmu_short(cmu_rig):
    props = bpy.context.scene.humananim_control
    props.frame_start, props.frame_end = FRAMES
    return cmu_rig


def _control(obj, **props):
    settings = bpy.context.scene.humananim_control
    for key, value in props.items():
        setattr(settings, key, value)
    source = obj.animation_data.action
    assert bpy.ops.humananim.dynamic_control() == {"FINISHED"}
    result = obj.animation_data.action
    assert result != source and result.name.startswith(f"{source.name}.control")
    action_api.assign_action(obj, source, action_api.object_slot(source, obj))  # ready for the next run
    return source, result


def _curve(action, obj, path):
    curves = {(fc.data_path, fc.array_index): fc for fc in action_api.fcurves_of(action, obj)}
    fc = curves[(path, 0)]
    return np.array([fc.evaluate(f) for f in range(FRAMES[0], FRAMES[1] + 1)])


def _stress(action, obj, bone):
    return _curve(action, obj, f'pose.bones["{bone}"]["{motion_control.STRESS}"]')


def _bone_heads(obj, action, bone):
    action_api.assign_action(obj, action, action_api.object_slot(action, obj))
    heads = world_pose(obj, bpy.context.scene, np.arange(FRAMES[0], FRAMES[1] + 1))[:, obj.pose.bones.find(bone), :3, 3]
    return heads


def test_operator_bakes_a_new_action_with_stress_and_balance_curves(cmu_short):
    obj = cmu_short
    keys_before = fcurve_snapshot(obj.animation_data.action, obj)
    source, result = _control(obj)
    snapshot = fcurve_snapshot(source, obj)  # the source is untouched and kept
    assert snapshot.keys() == keys_before.keys()
    assert all(np.array_equal(snapshot[k], v) for k, v in keys_before.items())
    assert source.use_fake_user
    for bone in ("LeftElbow", "Chest", "RightKnee"):
        values = _stress(result, obj, bone)
        assert np.isfinite(values).all() and (values >= 0.0).all()
    balance = _curve(result, obj, f'["{motion_control.BALANCE_ERROR}"]')
    falling = _curve(result, obj, f'["{motion_control.FALLING}"]')
    assert np.isfinite(balance).all() and (balance >= 0.0).all()
    assert set(np.unique(falling)) <= {0.0, 1.0}
    # the kept motion stays close to the captured one without any disturbance
    heads = _bone_heads(obj, result, "Hips")
    captured = _bone_heads(obj, source, "Hips")
    assert np.abs(heads - captured).max() < 0.10
    data = motion_control.CACHE[(obj.name, result.name)]
    assert data.bones.shape == (FRAMES[1] - FRAMES[0] + 1, len(obj.data.bones), 2, 3)


def test_a_load_raises_the_stress_on_the_arms_and_back(cmu_short):
    obj = cmu_short
    _, free = _control(obj, strength_scale=0.3)
    _, loaded = _control(obj, strength_scale=0.3, load_left=20.0, load_right=20.0)
    arms_back = ("LeftShoulder", "LeftElbow", "RightShoulder", "RightElbow", "Chest", "lowerback")
    free_total = sum(_stress(free, obj, b).sum() for b in arms_back)
    loaded_total = sum(_stress(loaded, obj, b).sum() for b in arms_back)
    assert loaded_total > free_total + 1.0


def test_gravity_is_the_scenes_and_substeps_are_the_panels(cmu_short):
    """The scene's gravity (Scene > Gravity, off when unticked) is what the bodies weigh: on the
    Moon the legs' and back's stress is a fraction of the Earth's (without gravity a walk is
    another problem again: the feet can no longer push on the floor); the panel's Substeps
    changes the bake."""
    obj, scene = cmu_short, bpy.context.scene
    legs_back = ("LeftHip", "LeftKnee", "RightHip", "RightKnee", "lowerback")

    def stress(action):
        return sum(_stress(action, obj, b).sum() for b in legs_back)

    _, earth = _control(obj)
    scene.gravity = (0.0, 0.0, -9.81 / 6.0)
    _, moon = _control(obj)
    scene.use_gravity = False
    _, none = _control(obj)
    print("stress: Earth", stress(earth), "Moon", stress(moon), "none", stress(none))
    assert stress(moon) < 0.5 * stress(earth)
    assert abs(stress(none) - stress(moon)) > 0.01 * stress(earth)  # unticked: no gravity at all
    scene.use_gravity, scene.gravity = True, (0.0, 0.0, -9.81)
    _, two = _control(obj, substeps=2)
    hips = _bone_heads(obj, earth, "Hips"), _bone_heads(obj, two, "Hips")
    assert 1e-7 < np.abs(hips[0] - hips[1]).max() < 0.02  # another integration of the same motion


def test_an_impulse_from_an_arrow_empty_is_placed_and_pushes_the_chest(cmu_short):
    obj, scene = cmu_short, bpy.context.scene
    _, calm = _control(obj)
    backwards = obj.matrix_world.to_3x3() @ Vector((0, 1, 0))
    item = motion_control.add_impulse(obj, scene, "Chest", 40, backwards, magnitude=60.0)
    assert item.empty.empty_display_type == "SINGLE_ARROW" and item.duration == 0.0
    skeleton = skeleton_from_armature(obj, scene)
    traj = actions.read_action(obj, scene, skeleton, frame_range=FRAMES)
    (impulse,) = motion_control.impulses(scene.humananim_control, skeleton, traj, scene)
    # along the arrow's Z axis, at its location: 30 cm before the chest's middle at frame 40
    assert np.allclose(impulse.direction, np.array(backwards), atol=1e-6)
    j = skeleton.index("Chest")
    expected = np.array([0.0, skeleton.lengths[j] / 2, 0.0]) - 0.3 * np.linalg.solve(
        traj.world_frames(skeleton)[40 - FRAMES[0], j, :3, :3], np.array(backwards))
    assert np.linalg.norm(np.array(impulse.point) - expected) < 1e-4
    assert impulse.time == pytest.approx((40 - FRAMES[0]) / traj.fps)
    assert impulse.bone == "Chest" and impulse.magnitude == 60.0 and impulse.duration == 0.0
    _, pushed = _control(obj)
    before, after = _bone_heads(obj, calm, "Chest"), _bone_heads(obj, pushed, "Chest")
    shift = (after - before) @ np.array(backwards)
    assert np.abs(shift[:40 - FRAMES[0] - 2]).max() < 0.002  # nothing happens before the push
    assert shift[40 - FRAMES[0]:].max() > 0.01  # the chest gives way in the push's direction


def _ball_into_chest(obj, scene):
    """A 12 cm ball that flies into the chest from the front between frames 30 and 60."""
    skeleton = skeleton_from_armature(obj, scene)
    traj = actions.read_action(obj, scene, skeleton, frame_range=FRAMES)
    world = traj.world_frames(skeleton)
    j = skeleton.index("Chest")
    chest = world[60 - FRAMES[0], j, :3, 3] + world[60 - FRAMES[0], j, :3, 1] * skeleton.lengths[j] / 2
    front = -np.array(obj.matrix_world.to_3x3() @ Vector((0, 1, 0)))  # the character's front
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.12, location=tuple(chest + 1.0 * front))
    ball = bpy.context.active_object
    ball.keyframe_insert("location", frame=30)
    ball.location = tuple(chest + 0.05 * front)
    ball.keyframe_insert("location", frame=60)
    for fc in action_api.fcurves_of(ball.animation_data.action, ball):
        for key in fc.keyframe_points:
            key.interpolation = "LINEAR"  # a steady flight
    bpy.context.view_layer.objects.active = obj
    return ball, chest, front


def test_a_force_over_an_interval_and_a_load_from_a_frame(cmu_short):
    """An arrow with a duration is a force (N) over it, not an impulse; a load carried from a
    chosen frame (Load From) changes nothing before it."""
    obj, scene = cmu_short, bpy.context.scene
    source, calm = _control(obj)
    backwards = obj.matrix_world.to_3x3() @ Vector((0, 1, 0))
    item = motion_control.add_impulse(obj, scene, "Chest", 40, backwards, magnitude=600.0, duration=0.1)
    skeleton = skeleton_from_armature(obj, scene)
    traj = actions.read_action(obj, scene, skeleton, frame_range=FRAMES)
    (force,) = motion_control.impulses(scene.humananim_control, skeleton, traj, scene)
    assert force.duration == pytest.approx(0.1) and force.magnitude == 600.0 and item.duration == force.duration
    _, pushed = _control(obj)
    shift = (_bone_heads(obj, pushed, "Chest") - _bone_heads(obj, calm, "Chest")) @ np.array(backwards)
    assert np.abs(shift[:40 - FRAMES[0] - 2]).max() < 0.002  # nothing before the force
    assert shift[40 - FRAMES[0]:].max() > 0.01  # the chest gives way along it
    scene.humananim_control.impulses.clear()
    action_api.assign_action(obj, source, action_api.object_slot(source, obj))  # (_bone_heads assigned others)
    (load,) = motion_control.loads(replace_props(scene, load_left=20.0, load_frame=60), skeleton, traj)
    assert load.start_time == pytest.approx((60 - FRAMES[0]) / traj.fps) and load.mass == 20.0
    _, loaded = _control(obj)
    moved = np.linalg.norm(_bone_heads(obj, loaded, "LeftHand") - _bone_heads(obj, calm, "LeftHand"), axis=1)
    assert moved[:60 - FRAMES[0] - 2].max() < 1e-4 and moved[60 - FRAMES[0]:].max() > 0.005


def test_foot_pose_markers_override_the_contacts(cmu_short):
    """The Motion Queue's pose markers on the source action set the feet's contacts
    (foot.L=supporting plants the left foot from that frame): marked in mid-swing, the foot stays
    where it is instead of swinging on; a mistyped marker is one clear message."""
    obj, scene = cmu_short, bpy.context.scene
    source, calm = _control(obj)
    ankle = _bone_heads(obj, calm, "LeftAnkle")
    speed = np.linalg.norm(np.diff(ankle[:, :2], axis=0), axis=1)
    # the left foot in mid-swing (it lands at ~37): a fixed frame, not the fastest one, whose speed
    # is nearly flat over frames 19-23 (the argmax moved between them with the swing's details)
    mark = FRAMES[0] + 21
    assert speed[mark - FRAMES[0]] * 120.0 > 0.5  # m/s
    action_api.assign_action(obj, source, action_api.object_slot(source, obj))  # (_bone_heads assigned calm)
    marker = synthesis.add_marker(source, mark, "foot.L", "supporting")
    try:
        skeleton = skeleton_from_armature(obj, scene)
        traj = actions.read_action(obj, scene, skeleton, frame_range=FRAMES)
        (contact,) = motion_control.contact_overrides(source, traj.frames)
        assert (contact.side, contact.start_frame, contact.end_frame, contact.on) == ("L", mark, FRAMES[1], True)
        _, planted = _control(obj)
        held = _bone_heads(obj, planted, "LeftAnkle")[mark - FRAMES[0] + 1:mark - FRAMES[0] + 11]
        swung = ankle[mark - FRAMES[0] + 1:mark - FRAMES[0] + 11]
        # the ankle of a planted foot may move a little as the foot rolls about its contact (measured
        # 5.6 mm over these ten frames, against 34 mm of swing without the marker)
        assert np.ptp(held[:, :2], axis=0).max() < 0.25 * np.ptp(swung[:, :2], axis=0).max()
        action_api.assign_action(obj, source, action_api.object_slot(source, obj))
        marker.name = "foot.L=planted"
        with pytest.raises(RuntimeError, match="unknown constraint 'planted'"):
            bpy.ops.humananim.dynamic_control()
    finally:
        source.pose_markers.remove(marker)


def replace_props(scene, **values):
    props = scene.humananim_control
    for key, value in values.items():
        setattr(props, key, value)
    return props


def test_a_ball_flying_into_the_chest_changes_the_motion(cmu_short):
    obj, scene = cmu_short, bpy.context.scene
    _, calm = _control(obj)
    ball, chest, front = _ball_into_chest(obj, scene)
    props = scene.humananim_control
    props.collider = ball
    skeleton = skeleton_from_armature(obj, scene)
    traj = actions.read_action(obj, scene, skeleton, frame_range=FRAMES)
    (collider,) = motion_control.colliders(props, obj, traj, scene)
    positions = np.asarray(collider.positions)
    assert positions.shape == (traj.frame_count, 1, 3) and np.asarray(collider.radii)[0] == pytest.approx(0.12, rel=0.02)
    assert np.allclose(positions[60 - FRAMES[0], 0], chest + 0.05 * front, atol=1e-3)
    speed = np.linalg.norm(np.asarray(collider.velocities)[45 - FRAMES[0], 0])
    assert speed == pytest.approx(0.95 / (30 / traj.fps), rel=0.1)  # 0.95 m in a quarter second
    assert collider.mass == math.inf
    _, hit = _control(obj)
    before, after = _bone_heads(obj, calm, "Chest"), _bone_heads(obj, hit, "Chest")
    assert np.linalg.norm(after - before, axis=1).max() > 0.005


def test_another_armature_becomes_spheres_along_its_bones(cmu_short, ):
    obj, scene = cmu_short, bpy.context.scene
    bpy.ops.object.armature_add(location=(0.0, 0.0, 0.0))
    other = bpy.context.active_object  # one bone, head at the origin, tail 1 m up
    props = scene.humananim_control
    props.collider, props.collider_radius = other, 0.25
    bpy.context.view_layer.objects.active = obj
    skeleton = skeleton_from_armature(obj, scene)
    traj = actions.read_action(obj, scene, skeleton, frame_range=(1, 10))
    (collider,) = motion_control.colliders(props, obj, traj, scene)
    positions = np.asarray(collider.positions)
    assert positions.shape == (10, 5, 3)  # every 25 cm from head to tail
    assert np.allclose(positions[0, :, 2], [0.0, 0.25, 0.5, 0.75, 1.0], atol=1e-6)
    assert np.allclose(collider.radii, 0.25) and np.allclose(collider.velocities, 0.0)
    props.collider = obj
    with pytest.raises(Exception, match="itself"):
        motion_control.colliders(props, obj, traj, scene)


def test_metarig_bakes_with_a_load(metarig):
    scene = bpy.context.scene
    scene.render.fps = 30
    bpy.ops.object.mode_set(mode="POSE")
    for frame, angle in ((1, 0.0), (15, 0.6), (30, 0.0)):
        pb = metarig.pose.bones["upper_arm.L"]
        pb.rotation_mode = "XYZ"
        pb.rotation_euler = (angle, 0.0, 0.0)
        pb.keyframe_insert("rotation_euler", frame=frame)
        metarig.pose.bones["spine"].keyframe_insert("location", frame=frame)
    bpy.ops.object.mode_set(mode="OBJECT")
    source, result = _control(metarig, load_left=5.0, frame_start=1, frame_end=30)
    curves = {fc.data_path for fc in action_api.fcurves_of(result, metarig)}
    assert f'pose.bones["upper_arm.L"]["{motion_control.STRESS}"]' in curves
    assert f'["{motion_control.BALANCE_ERROR}"]' in curves
    assert len(action_api.fcurves_of(source, metarig)) < len(curves)


def test_bad_input_is_one_clear_message(cmu_short):
    obj = cmu_short
    action = obj.animation_data.action
    obj.animation_data.action = None
    with pytest.raises(RuntimeError, match="no action to control"):
        bpy.ops.humananim.dynamic_control()
    action_api.assign_action(obj, action, action_api.object_slot(action, obj))
    fc = next(fc for fc in action_api.fcurves_of(action, obj) if "Chest" in fc.data_path)
    fc.keyframe_points[10].co[1] = float("nan")
    with pytest.raises(RuntimeError, match="NaN"):
        bpy.ops.humananim.dynamic_control()
    props = bpy.context.scene.humananim_control
    props.frame_start, props.frame_end = 50, 40
    with pytest.raises(RuntimeError, match="frame range"):
        bpy.ops.humananim.dynamic_control()


def _synthetic_overlay():
    frames = np.array([1.0, 2.0, 3.0])
    bones = np.zeros((3, 4, 2, 3))
    bones[..., 1, 2] = 1.0
    control = np.array([[0, 1, 2, 3]] * 3, np.int8)
    stress = np.zeros((3, 4))
    stress[1, 0] = 5.0  # a stressed joint with no control on it at frame 2
    return motion_control.OverlayData(frames=frames, ghost=bones + 0.1, bones=bones, control=control, stress=stress,
                                      zmp=np.array([[0.0, 0.0], [np.nan, np.nan], [0.1, 0.0]]),
                                      polygons=[np.array([[-1, -1], [1, -1], [1, 1]], float)] * 3, ground=0.0,
                                      falling=np.array([False, False, True]))


def test_overlay_geometry_colours_each_bone_by_its_control():
    data = _synthetic_overlay()
    groups = overlay.frame_geometry(data, 1)
    colours = [c for _, c, _ in groups]
    for colour in (overlay.GHOST, overlay.FREE, overlay.POLYGON, overlay.ZMP, *overlay.KIND_COLOURS.values()):
        assert colour in colours
    assert overlay.STRESS not in colours
    for segments, _, width in groups:
        assert np.asarray(segments).ndim == 3 and np.asarray(segments).shape[1:] == (2, 3) and width > 0
    polygon = next(s for s, c, _ in groups if c == overlay.POLYGON)
    assert len(polygon) == 3 and np.allclose(polygon[:, :, 2], 0.0)  # closed, on the ground
    stressed = [c for _, c, _ in overlay.frame_geometry(data, 2)]
    assert overlay.STRESS in stressed and overlay.ZMP not in stressed  # no ZMP in the air
    assert overlay.ZMP_FALLING in [c for _, c, _ in overlay.frame_geometry(data, 3)]
    assert overlay.frame_geometry(data, 10) == []


def test_overlay_follows_the_result_and_the_handler_toggles(cmu_short):
    obj = cmu_short
    _, result = _control(obj)
    assert motion_control.overlay_data(obj) is None  # the source is active again
    action_api.assign_action(obj, result, action_api.object_slot(result, obj))
    data = motion_control.overlay_data(obj)
    groups = overlay.frame_geometry(data, 20)
    assert sum(len(s) for s, c, _ in groups if c == overlay.GHOST) == len(obj.data.bones)
    assert all(np.isfinite(np.asarray(s)).all() for s, _, _ in groups)
    assert overlay.is_enabled()  # on by default with the add-on
    bpy.ops.humananim.toggle_overlay()
    assert not overlay.is_enabled()
    bpy.ops.humananim.toggle_overlay()
    assert overlay.is_enabled()
    overlay.unregister()
    overlay.unregister()  # twice is harmless
    assert not overlay.is_enabled()
    overlay.register()
