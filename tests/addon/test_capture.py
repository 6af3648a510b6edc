"""Live capture in headless bpy: the display step (called directly, as the modal operator does on
each timer event) applies the newest samples of simulated devices to pose bones, and recording
writes a new action with quaternion keys."""

import time
from types import SimpleNamespace

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
pytest.importorskip("serial")

from conftest import CMU_CLIPS  # noqa: E402  (at import: later folders' conftest modules take the name)
from humananim.humananim_addon.capture import job as capture  # noqa: E402
from humananim.humananim_addon.action_api import fcurves_of  # noqa: E402
from humananim.operators.capture import HUMANANIM_OT_capture_live  # noqa: E402
from humananim.solver import rotations  # noqa: E402
from humananim.humananim_addon.devices import vmc  # noqa: E402
from humananim.solver.hands.grasp_automaton import FREE_HAND  # noqa: E402

CMU_BONES = ("Hips", "Chest", "Head", "LeftWrist", "RightWrist")


def wait_for(predicate, timeout=10.0):
    end = time.perf_counter() + timeout
    while time.perf_counter() < end:
        if predicate():
            return True
        time.sleep(0.01)
    return predicate()


@pytest.fixture
def live_cleanup():
    yield
    capture.disconnect()


def _pose_quats(obj, names):
    return np.array([list(obj.pose.bones[n].rotation_quaternion) for n in names])


def _fob(scene, bones, rate=120.0):
    return capture.add_device(scene, "FLOCK", name="fob", simulate=True, rate=rate,
                              birds=",".join(str(i + 1) for i in range(len(bones))), bones=", ".join(bones))


def test_step_applies_the_newest_flock_samples_and_recording_writes_a_quaternion_action(cmu_rig, live_cleanup):
    obj, scene = cmu_rig, bpy.context.scene
    source = obj.animation_data.action
    _fob(scene, CMU_BONES)
    assert "FINISHED" in bpy.ops.humananim.capture_live()
    live = capture.LIVE
    assert all(obj.pose.bones[n].rotation_mode == "QUATERNION" for n in live.skeleton.names)
    assert wait_for(lambda: live.session.pump() >= 0 and len(live.session.pose_readings()) == len(CMU_BONES))
    assert "FINISHED" in bpy.ops.humananim.capture_calibrate()
    assert wait_for(lambda: live.session.device("fob").seq > 40)
    assert live.step(bpy.context)
    newest = live.last_applied
    expected = live.converter.solve({k: (s.data["position"], s.data["quaternion"]) for k, s in newest.items()})
    sk = live.skeleton
    got = _pose_quats(obj, sk.names)
    want = rotations.from_matrix(expected[:, :3, :3])
    assert np.all(np.abs(np.abs(np.sum(got * want, axis=1)) - 1.0) < 1e-5)  # single-precision pose bones
    root = obj.pose.bones[sk.names[sk.root]]
    assert np.allclose(np.array(root.location) * sk.unit_scale, expected[sk.root, :3, 3], atol=1e-5)
    # the newest sample of every channel at the time of the step was applied
    assert all(s.seq <= live.session.latest[k].seq for k, s in newest.items())
    # recording: every sample at the device rate into the take, then a new action
    assert "FINISHED" in bpy.ops.humananim.capture_record()
    t0 = time.perf_counter()
    while time.perf_counter() - t0 < 0.6:
        live.step(bpy.context)
        time.sleep(1 / 60)
    assert "FINISHED" in bpy.ops.humananim.capture_record()
    take = live.session.takes[-1]
    action = obj.animation_data.action
    assert action is not source and action.name.startswith("capture") and source.use_fake_user
    curves = fcurves_of(action, obj)
    paths = {fc.data_path.rsplit(".", 1)[1] for fc in curves}
    assert paths <= {"rotation_quaternion", "location"} and "rotation_quaternion" in paths
    hips = [fc for fc in curves if fc.data_path == 'pose.bones["LeftWrist"].rotation_quaternion']
    assert len(hips) == 4
    times = [t for t, _ in take.poses()]  # the birds of one record a moment apart make one pose
    assert len(times) == take.count(("fob", "bird1"))  # one pose per record of the birds
    assert len(hips[0].keyframe_points) == len(times) >= 10  # every sample time is a key
    seqs = [s.seq for s in take.merged()]  # and the take holds every sample decoded while recording
    assert seqs == list(range(seqs[0], seqs[0] + len(seqs)))
    co = np.empty(2 * len(times))
    hips[0].keyframe_points.foreach_get("co", co)
    fps = scene.render.fps / scene.render.fps_base
    assert np.allclose(np.diff(co[0::2]), np.diff(times) * fps, atol=1e-3)  # at the device's rate


class _Event(SimpleNamespace):
    pass


def test_modal_timer_steps_and_esc_keeps_the_take(cmu_rig, live_cleanup):
    obj, scene = cmu_rig, bpy.context.scene
    _fob(scene, CMU_BONES[:1])
    bpy.ops.humananim.capture_live()
    live = capture.LIVE
    assert wait_for(lambda: live.session.pump() >= 0 and live.session.pose_readings())
    live.calibrate()
    live.start_recording(scene)
    op = SimpleNamespace(_timer=None, report=lambda *a: None,
                         _end=lambda c, a: HUMANANIM_OT_capture_live._end(op, c, a))
    before = live.applied
    for _ in range(20):
        assert HUMANANIM_OT_capture_live.modal(op, bpy.context, _Event(type="TIMER")) == {"PASS_THROUGH"}
        time.sleep(1 / 60)
    assert live.applied > before
    n_actions = len(bpy.data.actions)
    assert HUMANANIM_OT_capture_live.modal(op, bpy.context, _Event(type="ESC")) == {"FINISHED"}
    assert capture.LIVE is None and len(bpy.data.actions) == n_actions + 1
    assert obj.animation_data.action.name.startswith("capture")


def test_glove_drives_the_finger_bones_and_the_hand_grasps_a_ball(metarig, live_cleanup):
    obj, scene = metarig, bpy.context.scene
    item = capture.add_device(scene, "CYBERGLOVE", name="glove", simulate=True, rate=100.0, sensors="22", hand="R")
    assert item.sensors == "22"
    bpy.ops.humananim.capture_live()
    live = capture.LIVE
    sk = live.skeleton
    sim = live.sims[0]
    chain = sk.roles.chain("index.R")
    assert len(chain) == 3 and live.grasp["R"].state == FREE_HAND
    sim.hold = np.full(22, 40, np.uint8)
    assert wait_for(lambda: live.session.pump() >= 0 and ("glove", "glove") in live.session.latest
                    and live.session.latest[("glove", "glove")].data["raw"][0] == 40)
    bpy.ops.humananim.capture_glove_flat()
    sim.hold = np.full(22, 220, np.uint8)
    assert wait_for(lambda: live.session.pump() >= 0 and live.session.latest[("glove", "glove")].data["raw"][0] == 220)
    bpy.ops.humananim.capture_glove_fist()
    live.step(bpy.context)
    bpy.context.view_layer.update()
    world = np.array(obj.matrix_world)

    def tip(name):
        return (world @ np.array(obj.pose.bones[name].tail.to_4d()))[:3]

    def head(name):
        return (world @ np.array(obj.pose.bones[name].head.to_4d()))[:3]

    angle = rotations.angle_between(np.array(obj.pose.bones[chain[1]].rotation_quaternion), np.array([1.0, 0, 0, 0]))
    assert angle == pytest.approx(np.radians(100), abs=1e-3)  # the fist's middle-joint flexion
    fist_tip = tip(chain[2])
    # the fingers curl toward the palm: the fingertip comes closer to the thumb's base
    thumb_base = head(sk.roles.chain("thumb.R")[0])
    sim.hold = np.full(22, 40, np.uint8)
    assert wait_for(lambda: live.session.pump() >= 0 and live.session.latest[("glove", "glove")].data["raw"][0] == 40)
    live.step(bpy.context)
    bpy.context.view_layer.update()
    flat_tip = tip(chain[2])
    assert np.linalg.norm(fist_tip - thumb_base) < np.linalg.norm(flat_tip - thumb_base) - 0.02
    # a ball inside the closing fingers: they rest on it and the automaton leaves FREE_HAND
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.035, location=tuple(fist_tip + 0.5 * (head(chain[0]) - fist_tip)))
    ball = bpy.context.active_object
    coll = bpy.data.collections.new("Graspable")
    scene.collection.children.link(coll)
    coll.objects.link(ball)
    scene.humananim_capture.grasp_collection = coll
    bpy.context.view_layer.objects.active = obj
    shape = capture.shape_of(ball)
    assert type(shape).__name__ == "Sphere" and shape.radius == pytest.approx(0.035, rel=0.02)
    sim.hold = np.full(22, 220, np.uint8)
    assert wait_for(lambda: live.session.pump() >= 0 and live.session.latest[("glove", "glove")].data["raw"][0] == 220)
    live.step(bpy.context)
    ga = live.grasp["R"]
    assert ga.state != FREE_HAND and ga.touching.any()
    from test_panels import draw_all
    log = draw_all(bpy.context)  # the panel shows the live session: status, calibration, record, hand state
    assert ("operator", "humananim.capture_glove_fist") in log and ("operator", "humananim.capture_record") in log
    assert any(kind == "label" and "hand:" in text for kind, text in log)
    # the counters, kept apart, beside each device's last error
    assert any(kind == "label" and "lost 0 records, discarded" in text and "resyncs" in text for kind, text in log)
    from humananim.panels.capture import status_lines
    lines = status_lines(dict(live.status()[0], dropped=2, discarded_bytes=57, resyncs=3,
                              last_error="CyberGlove unknown command"))
    assert lines[1:] == ["lost 2 records, discarded 57 bytes, 3 resyncs", "last error: CyberGlove unknown command"]
    geometry = capture.overlay_geometry(live)
    assert geometry[0][0] == "LINES" and geometry[0][2] == ga.colour
    assert any(kind == "POINTS" and colour == (0.8, 0.8, 0.8, 1.0) for kind, _, colour in geometry)  # touching
    from humananim.solver.hands.sensors import sensor_centres
    # the posture written to the rig keeps the finger sensors out of the ball
    basis = np.tile(np.eye(4), (sk.joint_count, 1, 1))
    q = np.empty(len(obj.pose.bones) * 4)
    obj.pose.bones.foreach_get("rotation_quaternion", q)
    q = q.reshape(-1, 4)[live.pose_order]
    basis[:, :3, :3] = rotations.to_matrix(q)
    centres = sensor_centres(ga.sensors, live._world_of(obj, scene)(basis), sk)
    depth = ga.radii - shape.distance(centres)
    finger = np.array([s.finger != "palm" for s in ga.sensors])
    assert depth[finger].max() < ga.tolerance + 2e-3


def test_vmc_bones_drive_the_rig_through_body_roles(metarig, live_cleanup):
    obj, scene = metarig, bpy.context.scene
    item = capture.add_device(scene, "VMC", name="vmc", vmc_port=0)
    assert item.host == "127.0.0.1"
    bpy.ops.humananim.capture_live()
    live = capture.LIVE
    dev = live.session.device("vmc")
    assert wait_for(lambda: dev.bound_port)
    sender = vmc.VMCSender(port=dev.bound_port)
    q = rotations.normalize(np.array([0.9, 0.2, -0.1, 0.3]))
    try:
        assert wait_for(lambda: sender.frame({"LeftUpperArm": ((0, 0, 0), q)}) or dev.seq > 0)
    finally:
        sender.close()
    assert live.step(bpy.context)
    sk = live.skeleton
    j = sk.role_index("upper_arm.L")
    a = live.rest_q[j]
    want = rotations.multiply(rotations.multiply(rotations.conjugate(a), q), a)
    got = np.array(obj.pose.bones[sk.names[j]].rotation_quaternion)
    assert abs(abs(np.dot(got, want)) - 1.0) < 1e-5
    status = {d["name"]: d for d in live.status()}
    assert status["vmc"]["status"] in ("connected", "disconnected") and status["vmc"]["dropped"] == 0


def test_a_missing_bone_and_no_device_are_clear_errors(cmu_rig, live_cleanup):
    scene = bpy.context.scene
    with pytest.raises(RuntimeError, match="add a device first"):
        bpy.ops.humananim.capture_live()
    _fob(scene, ("NoSuchBone",))
    with pytest.raises(RuntimeError, match="no bone named 'NoSuchBone'"):
        bpy.ops.humananim.capture_live()
    assert capture.LIVE is None


def test_reduced_take_saved_and_replayed(cmu_rig, live_cleanup, tmp_path):
    obj, scene = cmu_rig, bpy.context.scene
    _fob(scene, CMU_BONES[:2])
    scene.humananim_capture.reduce_keys = True
    bpy.ops.humananim.capture_live()
    live = capture.LIVE
    assert wait_for(lambda: live.session.pump() >= 0 and len(live.session.pose_readings()) == 2)
    live.calibrate()
    live.start_recording(scene)
    assert wait_for(lambda: live.session.take.count() > 120)
    action, take = live.stop_recording(bpy.context)
    curves = fcurves_of(action, obj)
    keys = max(len(fc.keyframe_points) for fc in curves)
    assert live.reduction["keys_after"] < live.reduction["keys_before"] and keys < len(take.poses())
    assert live.reduction["max_error_deg"] <= 0.5 + 1e-6
    path = tmp_path / "take.json"
    assert "FINISHED" in bpy.ops.humananim.capture_save_take(filepath=str(path))
    capture.disconnect()
    # the saved take as a replay device: the same samples come back through a session and, with
    # the Flock of Birds kept for its bone mapping but not in use, drive the rig as they did
    scene.humananim_capture.devices[0].use = False
    capture.add_device(scene, "REPLAY", name="again", filepath=str(path))
    bpy.ops.humananim.capture_live()
    live = capture.LIVE
    assert [d.name for d in live.session.devices] == ["again"]
    assert wait_for(lambda: live.session.pump() >= 0 and len(live.session.pose_readings()) == 2)
    live.calibrate()
    assert wait_for(lambda: live.session.device("again").seq >= take.count() // 2)
    assert live.step(bpy.context)
    newest = live.last_applied
    assert set(newest) == {("fob", "bird1"), ("fob", "bird2")}
    sent = {(s.device, s.channel, tuple(s.data["position"])) for s in take.merged()}
    assert all((k[0], k[1], tuple(s.data["position"])) in sent for k, s in newest.items())
    expected = live.converter.solve({k: (s.data["position"], s.data["quaternion"]) for k, s in newest.items()})
    sk = live.skeleton
    got = _pose_quats(obj, sk.names)
    want = rotations.from_matrix(expected[:, :3, :3])
    assert np.all(np.abs(np.abs(np.sum(got * want, axis=1)) - 1.0) < 1e-5)


def test_a_secure_grasp_carries_the_object_with_the_hand(metarig, live_cleanup):
    obj, scene = metarig, bpy.context.scene
    capture.add_device(scene, "CYBERGLOVE", name="glove", simulate=True, rate=100.0, sensors="18", hand="R")
    bpy.ops.humananim.capture_live()
    live = capture.LIVE
    sim, sk = live.sims[0], live.skeleton

    def hold(value):
        sim.hold = np.full(18, value, np.uint8)
        assert wait_for(lambda: live.session.pump() >= 0 and ("glove", "glove") in live.session.latest
                        and live.session.latest[("glove", "glove")].data["raw"][0] == value)

    hold(40)
    bpy.ops.humananim.capture_glove_flat()
    hold(160)
    live.step(bpy.context)
    bpy.context.view_layer.update()
    world = np.array(obj.matrix_world)
    thumb_tip = (world @ np.array(obj.pose.bones[sk.roles.chain("thumb.R")[-1]].tail.to_4d()))[:3]
    index = obj.pose.bones[sk.roles.chain("index.R")[1]]
    index_mid = (world @ np.array(((index.head + index.tail) / 2).to_4d()))[:3]
    centre, radius = (thumb_tip + index_mid) / 2, 0.55 * np.linalg.norm(thumb_tip - index_mid)
    bpy.ops.mesh.primitive_uv_sphere_add(radius=radius, location=tuple(centre))
    ball = bpy.context.active_object
    coll = bpy.data.collections.new("Graspable")
    scene.collection.children.link(coll)
    coll.objects.link(ball)
    scene.humananim_capture.grasp_collection = coll
    bpy.context.view_layer.objects.active = obj
    live.step(bpy.context)
    ga = live.grasp["R"]
    assert ga.state == "SECURE_GRASP" and ga.colour == (0.15, 0.8, 0.25, 1.0)
    before = np.array(ball.matrix_world)
    obj.location = (0.3, -0.2, 0.1)  # the performer walks away with it
    bpy.context.view_layer.update()
    live.step(bpy.context)
    after = np.array(ball.matrix_world)
    assert np.allclose(after[:3, 3] - before[:3, 3], (0.3, -0.2, 0.1), atol=1e-4)
    hold(40)  # the hand opens: released, the ball stays where it was left when the hand moves on
    for _ in range(4):
        live.step(bpy.context)
    assert ga.state != "SECURE_GRASP"
    after = np.array(ball.matrix_world)
    obj.location = (0.6, -0.2, 0.1)
    bpy.context.view_layer.update()
    live.step(bpy.context)
    assert ga.state == FREE_HAND and np.allclose(np.array(ball.matrix_world), after, atol=1e-6)


def test_glove_gestures_record_a_take_that_becomes_an_action(metarig, live_cleanup):
    from humananim.humananim_addon.devices.cyberglove import SENSORS_18
    obj, scene = metarig, bpy.context.scene
    capture.add_device(scene, "CYBERGLOVE", name="glove", simulate=True, rate=100.0, sensors="18", hand="L")
    scene.humananim_capture.take_name = "gestured"
    bpy.ops.humananim.capture_live()
    live = capture.LIVE
    sim = live.sims[0]
    flat, fist = np.full(18, 40, np.uint8), np.full(18, 220, np.uint8)

    def posture(extended):
        raw = fist.copy()
        for i, (finger, _, axis) in enumerate(SENSORS_18):
            if axis != "flex" or finger in extended or finger == "thumb":
                raw[i] = 40
        return raw

    def hold(raw):
        sim.hold = raw
        assert wait_for(lambda: live.step(bpy.context) is not None and ("glove", "glove") in live.session.latest
                        and np.array_equal(live.session.latest[("glove", "glove")].data["raw"], raw.astype(float)))

    hold(flat)
    bpy.ops.humananim.capture_glove_flat()
    hold(fist)
    bpy.ops.humananim.capture_glove_fist()
    hold(flat)
    assert wait_for(lambda: live.step(bpy.context) is not None and live.session.gestures.posture == "neutral")
    hold(posture({"index"}))  # pointing: start recording
    assert wait_for(lambda: live.step(bpy.context) is not None and live.session.recording)
    hold(posture({"index", "middle"}))  # the V: stop
    assert wait_for(lambda: live.step(bpy.context) is not None and live.gesture_actions)
    action = live.gesture_actions[0]
    assert action.name.startswith("gestured") and obj.animation_data.action == action
    assert [c for _, c in live.session.events][-3:] == ["neutral", "start_recording", "stop_recording"]


def test_a_replayed_bvh_puts_the_joints_where_the_file_says(cmu_rig, live_cleanup):
    from humananim.solver import bvh
    from humananim.solver.units import bvh_rest_extent, guess_length_scale
    obj, scene = cmu_rig, bpy.context.scene
    capture.add_device(scene, "REPLAY", name="replay", filepath=CMU_CLIPS[0])
    bpy.ops.humananim.capture_live()
    live = capture.LIVE
    assert wait_for(lambda: live.session.pump() >= 0 and live.session.device("replay").seq > 30)
    assert live.step(bpy.context)
    bpy.context.view_layer.update()
    sample = live.last_applied[("replay", "skeleton")]
    text = open(CMU_CLIPS[0]).read()
    clip = bvh.parse(text, guess_length_scale(bvh_rest_extent(text))[0])
    want = clip.positions()[sample.data["frame"]]
    world = np.array(obj.matrix_world)
    got = np.array([(world @ np.array(obj.pose.bones[n].head.to_4d()))[:3] for n in clip.names])
    assert np.abs(got - want).max() < 1e-4


def test_a_usb_glove_that_is_not_there_shows_why_in_the_status(metarig, live_cleanup):
    scene = bpy.context.scene
    capture.add_device(scene, "HID_GLOVE", name="usb", hand="L")
    bpy.ops.humananim.capture_live()
    live = capture.LIVE
    dev = live.session.device("usb")
    assert wait_for(lambda: dev.status == "disconnected" and dev.last_error)
    assert "hidapi is not installed" in dev.last_error or "no USB glove" in dev.last_error
    assert "usb" in live.gloves and live.grasp  # its hand is ready for when it is plugged in
    capture.add_device(scene, "HID_GLOVE", name="other", decoder="nope")
    capture.disconnect()
    with pytest.raises(RuntimeError, match="no HID glove decoder 'nope'"):
        bpy.ops.humananim.capture_live()
