"""The session core without bpy: ring buffer, recording, faults, the anatomical converter, the
replay device and the grasping automaton."""

import os
import sys
import threading
import time

import numpy as np
import pytest

from humananim.solver import bvh, rotations
from humananim.solver.body_roles import sided
from humananim.humananim_addon.devices import cyberglove, fob, sim_fob, sim_glove
from humananim.solver.anatomical_converter import TRACKER_Z_DOWN, AnatomicalConverter, CalibrationError
from humananim.humananim_addon.devices.glove_calibration import GloveCalibration
from humananim.solver.hands.grasp_automaton import FREE_HAND, GRASPING_IN_PROGRESS, SECURE_GRASP, GraspAutomaton
from humananim.solver.hands.sensors import Box, Sphere, default_hand_sensors, sensor_centres
from humananim.humananim_addon.devices.replay import ReplayDevice
from humananim.humananim_addon.devices.ringbuffer import RingBuffer
from humananim.humananim_addon.devices.session import Session, Take
from capture_helpers import drained, wait_for
from capture_rigs import curled_basis, hand_skeleton

CLIP = os.path.join(os.path.dirname(__file__), "..", "..", "humananim_addon", "data", "mocap", "cmu_131_01.bvh")


def test_ring_buffer_is_bounded_and_counts_what_it_overwrites():
    rb = RingBuffer(4)
    for i in range(3):
        rb.push(i)
    assert rb.drain() == [0, 1, 2] and rb.drain() == []
    for i in range(10):
        rb.push(i)
    assert rb.drain() == [6, 7, 8, 9] and rb.dropped == 6 and rb.newest() == 9 and rb.pushed == 13


def test_a_record_pushed_at_once_is_never_split_by_a_drain_on_another_thread():
    rb, done, drained = RingBuffer(100000), threading.Event(), []

    def reader():
        for record in range(20000):
            rb.push_many([(record, bird) for bird in range(5)])
            if record % 500 == 0:
                time.sleep(0.001)  # let the drainer in (it also preempts at the switch interval)
        done.set()

    t = threading.Thread(target=reader)
    interval = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)  # the threads take turns often, as a loaded machine makes them
    try:
        t.start()
        while not done.is_set():
            drained.append(rb.drain())
        t.join()
    finally:
        sys.setswitchinterval(interval)
    drained.append(rb.drain())
    assert rb.dropped == 0 and sum(map(len, drained)) == 100000
    assert sum(1 for d in drained if d) > 10
    assert all(len(d) % 5 == 0 and all(b == i % 5 for i, (_, b) in enumerate(d)) for d in drained)


def _two_devices(rate, speed):
    fsim = sim_fob.FlockSimulator(birds=(1,), rate=rate, speed=speed).start()
    gsim = sim_glove.CyberGloveSimulator(sensors=18, rate=rate, speed=speed).start()
    devices = [fob.FlockOfBirds("fob", fsim.port, birds=(1,), record="POSITION/QUATERNION", settle=0.02),
               cyberglove.CyberGlove("glove", gsim.port, sensors=18, settle=0.02)]
    return fsim, gsim, devices


def _record_two_devices(seconds, speed):
    rate = 120.0
    fsim, gsim, devices = _two_devices(rate, speed)
    session = Session(devices).start()
    try:
        assert wait_for(lambda: fsim.streaming and gsim.streaming and all(d.seq for d in devices))
        with fsim._lock, gsim._lock:  # start both at a tick boundary: the take holds exactly these ticks
            assert drained(devices)  # what was sent before is read before recording starts
            session.start_recording()
            first = (fsim.tick_count, gsim.tick_count)
        n = int(seconds * rate)  # device time: 60 s at 120 Hz is 7200 records from each device
        assert wait_for(lambda: fsim.tick_count - first[0] >= n and gsim.tick_count - first[1] >= n,
                        timeout=3 * seconds / speed + 30)
        with fsim._lock, gsim._lock:
            last = (fsim.tick_count, gsim.tick_count)
            fsim.streaming = gsim.streaming = False
        assert drained(devices)  # the last records cross the line
        take = session.stop_recording()
    finally:
        session.stop()
        fsim.stop()
        gsim.stop()
    sent = (last[0] - first[0], last[1] - first[1])
    assert min(sent) >= seconds * rate
    for key, k in ((("fob", "bird1"), 0), (("glove", "glove"), 1)):
        seqs = [x.seq for x in take.samples[key]]
        assert seqs == list(range(seqs[0], seqs[0] + len(seqs)))  # nothing lost between reader and take
        assert len(seqs) == sent[k]  # every record sent while recording is in the take, and no other
    assert session.dropped == 0 and all(d.discarded_bytes == 0 and d.lost == 0 and d.resyncs == 0 and d.reconnects == 0
                                        for d in devices)
    assert fsim.dropped_bytes == 0 and gsim.dropped_bytes == 0
    return take


def test_two_devices_at_120_hz_for_60_s_real_time_with_zero_dropped_samples():
    take = _record_two_devices(60.0, speed=1.0)
    assert take.duration >= 59.0


def test_two_devices_at_120_hz_for_60_s_of_device_time_run_ten_times_faster():
    _record_two_devices(60.0, speed=10.0)


def test_a_disconnect_mid_take_keeps_the_take_and_reconnects():
    fsim = sim_fob.FlockSimulator(birds=(1, 2), rate=100).start()
    dev = fob.FlockOfBirds("fob", fsim.port, birds=(1, 2), settle=0.02, reconnect_interval=0.05, watchdog=0.3)
    session = Session([dev]).start()
    try:
        assert wait_for(lambda: dev.status == "connected" and dev.seq > 10)
        take = session.start_recording()
        assert wait_for(lambda: take.count() > 40)
        fsim.unplug()
        assert wait_for(lambda: dev.status == "disconnected")
        before = take.count()
        assert before > 40 and session.recording and dev.last_error
        fsim.replug()
        assert wait_for(lambda: dev.status == "connected" and take.count() > before + 40, timeout=15)
        assert dev.reconnects == 1
    finally:
        session.stop()
        fsim.stop()
    assert session.takes == [take] and take.count() > before + 40  # stopping the session kept the take


def test_glove_gestures_start_and_stop_recording_in_the_session():
    gsim = sim_glove.CyberGloveSimulator(sensors=18, rate=100).start()
    dev = cyberglove.CyberGlove("glove", gsim.port, sensors=18, settle=0.02)
    session = Session([dev])
    flat, fist = np.full(18, 40, np.uint8), np.full(18, 220, np.uint8)
    session.glove_calibrations["glove"] = GloveCalibration.from_poses(cyberglove.SENSORS_18, flat, fist)
    point = flat.copy()
    for i, (f, _, axis) in enumerate(cyberglove.SENSORS_18):
        if f in ("middle", "ring", "pinky") and axis == "flex":
            point[i] = 220
    v_sign = point.copy()
    for i, (f, _, axis) in enumerate(cyberglove.SENSORS_18):
        if f == "middle" and axis == "flex":
            v_sign[i] = 40
    session.start()
    try:
        gsim.hold = flat
        assert wait_for(lambda: any(c == "neutral" for _, c in session.events))
        gsim.hold = point
        assert wait_for(lambda: session.recording)
        gsim.hold = v_sign
        assert wait_for(lambda: not session.recording)
    finally:
        session.stop()
        gsim.stop()
    assert [c for _, c in session.events] == ["neutral", "start_recording", "stop_recording"]
    assert len(session.takes) == 1 and session.takes[0].count() > 10


def _cmu():
    clip = bvh.read(CLIP, scale=0.01)
    sk = bvh.skeleton(clip)
    return clip, sk, bvh.trajectories(clip, sk)


def _readings(sk, world, attach, offsets, head_offsets, origin):
    out = {}
    for key, j in attach.items():
        w = world[j, :3, :3] @ offsets[key].T  # sensor world orientation
        s = TRACKER_Z_DOWN.T @ w
        head = world[j, :3, 3]
        pos = TRACKER_Z_DOWN.T @ (head - w @ head_offsets[key] - origin)
        out[key] = (pos, rotations.from_matrix(s))
    return out


def test_anatomical_converter_recovers_the_pose_and_ik_fills_the_arms():
    clip, sk, traj = _cmu()
    roles = ("pelvis", "chest", "head", "hand.L", "hand.R", "thigh.L", "thigh.R", "shin.L", "shin.R")
    attach = {("fob", f"bird{i + 1}"): sk.roles.bone(r) for i, r in enumerate(roles)}
    attach_idx = {k: sk.index(b) for k, b in attach.items()}
    rng = np.random.default_rng(7)
    offsets = {k: rotations.to_matrix(rotations.normalize(rng.normal(size=4))) for k in attach}
    heads = {k: rng.normal(scale=0.03, size=3) for k in attach}
    heads[("fob", "bird1")] = np.zeros(3)  # the root sensor sits on the pelvis's head
    origin = np.array([0.4, -0.2, 0.0])
    rest_world = sk.world_frames(np.tile(np.eye(4), (sk.joint_count, 1, 1)))
    conv = AnatomicalConverter(sk, attach, root=("fob", "bird1"))
    with pytest.raises(CalibrationError):
        conv.solve({})
    conv.calibrate(_readings(sk, rest_world, attach_idx, offsets, heads, origin))
    basis = traj.basis()[40]
    target = sk.world_frames(basis)
    solved = sk.world_frames(conv.solve(_readings(sk, target, attach_idx, offsets, heads, origin)))
    for j in attach_idx.values():
        assert np.allclose(solved[j, :3, :3], target[j, :3, :3], atol=1e-9)
    root = sk.role_index("pelvis")
    assert np.allclose(solved[root, :3, 3], target[root, :3, 3], atol=1e-9)
    for side in "LR":  # no sensor on the arm: IK puts the hand where its sensor is
        hand = sk.role_index(sided("hand", side))
        assert np.linalg.norm(solved[hand, :3, 3] - target[hand, :3, 3]) < 1e-6
        assert sk.role_index(sided("forearm", side)) not in attach_idx.values()


def test_replay_of_a_bvh_at_its_own_rate_loops():
    from humananim.solver.units import bvh_rest_extent, guess_length_scale
    text = open(CLIP).read()
    clip = bvh.parse(text, guess_length_scale(bvh_rest_extent(text))[0])
    dev = ReplayDevice("replay", CLIP, speed=20.0)
    dev.start()
    try:
        assert wait_for(lambda: dev.seq > clip.frame_count + 5, timeout=30)
    finally:
        dev.stop()
    samples = dev.buffer.drain()
    assert samples[0].data["frame"] == 0 and samples[clip.frame_count].data["frame"] == 0  # looped
    f = 17
    s = samples[f].data
    assert np.allclose(s["root_position"], clip.root_positions[f])
    assert np.allclose(s["bones"][clip.names[3]][1], clip.rotations[f, 3])
    assert s["roles"][sk_name(clip, "pelvis")] == ("pelvis", 0)


def sk_name(clip, role):
    return bvh.guess_roles(clip.names).bone(role)


def test_a_take_saves_loads_and_replays(tmp_path):
    take = Take("t")
    dev = fob.FlockOfBirds("fob", "/nonexistent")
    for k in range(30):
        take.add(dev.make_sample("bird1", "pose", {"position": np.array([k * 0.01, 0, 0]),
                                                   "quaternion": np.array([1.0, 0, 0, 0])}, t=100 + k / 60))
    take.save(tmp_path / "t.json")
    back = Take.load(tmp_path / "t.json")
    assert back.count(("fob", "bird1")) == 30 and back.duration == pytest.approx(29 / 60)
    rep = ReplayDevice("replay", back, speed=4.0, loop=False)
    rep.start()
    try:
        assert wait_for(lambda: rep.finished)
    finally:
        rep.stop()
    out = rep.buffer.drain()
    assert [s.data["position"][0] for s in out] == pytest.approx([k * 0.01 for k in range(30)])
    assert all(s.channel == "bird1" and s.kind == "pose" for s in out)


def test_grasping_automaton_states_posture_correction_and_the_object_following_the_hand():
    sk = hand_skeleton()
    sensors = default_hand_sensors(sk, "R")
    ga = GraspAutomaton(sk, sensors)
    ball = Sphere(np.array([0.08, 0.01, 0.06]), 0.035)
    far_box = Box(np.eye(4) + np.diag([0, 0, 0, 0]), np.array([0.01, 0.01, 0.01]))
    far_box.frame[:3, 3] = (1.0, 1.0, 1.0)
    states = []

    def world_of(b):
        return sk.world_frames(b)

    for a in np.linspace(0, 0.8, 17):
        basis, world = ga.update(curled_basis(sk, a), [far_box, ball], world_of)
        depth = ga.radii - ball.distance(sensor_centres(sensors, world, sk))
        assert depth.max() <= ga.tolerance + 1e-9  # fingers rest on the surface, not inside
        if ga.touching.any():
            assert depth[ga.touching].max() > -ga.tolerance
        states.append(ga.state)
    assert states[0] == FREE_HAND and GRASPING_IN_PROGRESS in states and states[-1] == SECURE_GRASP
    assert states.index(GRASPING_IN_PROGRESS) < states.index(SECURE_GRASP) and ga.object == 1
    assert ga.colour[2] < 0.5 and ga.colour[1] > 0.5  # green
    # the grasped object follows the hand
    basis = curled_basis(sk, 0.8)
    basis[0, :3, 3] = (0.0, 0.2, 0.1)
    basis[0, :3, :3] = rotations.to_matrix(rotations.axis_rotation(2, 0.5))
    before = ga.object_pose(sk.world_frames(curled_basis(sk, 0.8)))
    moved = ga.object_pose(sk.world_frames(basis))
    hand_motion = sk.world_frames(basis)[0] @ np.linalg.inv(sk.world_frames(curled_basis(sk, 0.8))[0])
    assert np.allclose(moved, hand_motion @ before)
    # opening the hand releases it
    shapes = [far_box, Sphere(moved[:3, 3], ball.radius)]
    for a in np.linspace(0.8, 0.0, 9):
        b = curled_basis(sk, a)
        b[0] = basis[0]
        ga.update(b, shapes, world_of)
    assert ga.state == FREE_HAND and ga.object_pose(world_of(b)) is None


def test_converter_solves_with_some_sensors_still_silent():
    clip, sk, traj = _cmu()
    attach = {("fob", "bird1"): sk.roles.bone("pelvis"), ("fob", "bird2"): sk.roles.bone("hand.L")}
    conv = AnatomicalConverter(sk, attach, root=("fob", "bird1"))
    q = np.array([1.0, 0, 0, 0])
    conv.calibrate({k: (np.zeros(3), q) for k in attach})
    basis = conv.solve({("fob", "bird1"): (np.array([0.1, 0, 0]), q)})  # the hand's bird not heard yet
    assert np.all(np.isfinite(basis))


def test_a_take_spreads_bursts_and_keeps_one_pose_per_record():
    take = Take()
    dev = fob.FlockOfBirds("fob", "/nonexistent", birds=(1, 2))
    # bird records of ticks 0..5; ticks 2-4 arrived in one read (same decoding time)
    arrival = [0.0, 0.01, 0.04, 0.04, 0.04, 0.05]
    for k, t in enumerate(arrival):
        for b in (1, 2):  # bird 2 of tick 1 comes in the next read, with tick 2
            take.add(dev.make_sample(f"bird{b}", "pose", {"tick": k}, t=0.04 if (k, b) == (1, 2) else t))
    ticks = take.device_ticks("fob")
    assert np.allclose([t for t, _ in ticks], [0.0, 0.01, 0.02, 0.03, 0.04, 0.05])  # as sent, 100 Hz
    poses = take.poses()
    assert len(poses) == 6  # one pose per tick: both birds in it, no tick merged into another
    assert all(sorted(s.channel for s in group) == ["bird1", "bird2"] for _, group in poses)
    assert [group[0].data["tick"] for _, group in poses] == list(range(6))
    # a burst first in the take goes back at the device's period
    take = Take()
    for k, t in enumerate([0.02, 0.02, 0.02, 0.03, 0.04]):
        take.add(dev.make_sample("bird1", "pose", {}, t=t))
    assert np.allclose([t for t, _ in take.device_ticks("fob")], [0.0, 0.01, 0.02, 0.03, 0.04])


def test_the_spine_without_sensors_shares_the_chest_sensor_turn():
    clip, sk, traj = _cmu()
    attach = {("fob", "bird1"): "Hips", ("fob", "bird2"): "Chest2"}
    idx = {k: sk.index(b) for k, b in attach.items()}
    conv = AnatomicalConverter(sk, attach, root=("fob", "bird1"))
    rest_world = sk.world_frames(np.tile(np.eye(4), (sk.joint_count, 1, 1)))
    offsets = {k: np.eye(3) for k in attach}
    heads = {k: np.zeros(3) for k in attach}
    conv.calibrate(_readings(sk, rest_world, idx, offsets, heads, np.zeros(3)))
    assert conv._chains[sk.index("Chest2")] == [sk.index("lowerback"), sk.index("Chest")]
    # the chest bends 60 degrees forward about the world X axis, the pelvis stays
    target = rest_world.copy()
    turn = rotations.to_matrix(rotations.axis_rotation(0, np.radians(60)))
    target[sk.index("Chest2"), :3, :3] = turn @ rest_world[sk.index("Chest2"), :3, :3]
    basis = conv.solve(_readings(sk, target, idx, offsets, heads, np.zeros(3)))
    world = sk.world_frames(basis)
    assert np.allclose(world[sk.index("Chest2"), :3, :3], target[sk.index("Chest2"), :3, :3], atol=1e-9)
    for name in ("lowerback", "Chest", "Chest2"):  # 20 degrees at each of the three joints
        local = rotations.from_matrix(basis[sk.index(name), :3, :3])
        assert np.degrees(rotations.angle_between(local, np.array([1.0, 0, 0, 0]))) == pytest.approx(20.0, abs=1e-6)
