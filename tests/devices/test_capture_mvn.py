"""Xsens MVN network streaming: the receiver (mvn.py) on a local UDP socket against the sender
written separately from the specification (sim_mvn.py): several actors, split samples, faults,
silence, and calibration through the anatomical converter like the Flock of Birds."""

import numpy as np

from humananim.solver import rotations
from humananim.solver.anatomical_converter import AnatomicalConverter
from humananim.humananim_addon.devices import mvn, sim_mvn
from humananim.humananim_addon.devices.samples import tracker_reading
from humananim.humananim_addon.devices.session import Session
from capture_helpers import drained, wait_for
from test_capture_core import _cmu


def _receiver(**kw):
    dev = mvn.MVNReceiver("mvn", port=0, reconnect_interval=0.05, **kw)
    dev.start()
    assert wait_for(lambda: dev.bound_port is not None)
    return dev


def _check(sender, samples):
    """Every sample is the pose its actor's segment had at the sample the header names."""
    ids = {mvn.segment_name(sid, sender.props): sid for sid in sender.segment_ids()}
    for s in samples:
        actor, seg = s.channel.split("/")
        tick, _ = sender.sent[(int(actor[5:]), s.data["sample_counter"])]
        pos, q = sender.true_pose(int(actor[5:]), ids[seg], tick)
        assert np.allclose(s.data["position"], pos, atol=1e-5), s.channel
        assert np.degrees(rotations.angle_between(s.data["quaternion"], q)) < 1e-3, s.channel
        assert s.data["time_code"] == round(1000 * tick / sender.rate)


def test_the_header_and_segment_table_follow_the_specification():
    sender = sim_mvn.MVNSender(port=9, actors=(3,), props=2, fingers=40)
    (dg,) = sender.datagrams_of(3, 5, 77)
    d = mvn.parse_header(dg)
    assert (d.kind, d.sample, d.index, d.last, d.actor, d.body, d.props, d.fingers) == ("02", 77, 0, True, 3, 23, 2, 40)
    assert d.items == 23 + 2 + 40 and len(d.payload) == 32 * d.items
    segs = mvn.parse_pose_quaternion(d)
    assert list(segs)[:3] == ["Pelvis", "L5", "L3"] and "Prop2" in segs and "LeftFinger0" in segs
    assert "RightFinger19" in segs and len(segs) == 65
    assert mvn.parse_header(dg[:-1]) is None and mvn.parse_header(b"MXTQ02" + dg[6:]) is None
    sender.sock.close()


def test_several_actors_and_split_samples_decode_exactly():
    dev = _receiver()
    sender = sim_mvn.MVNSender(port=dev.bound_port, actors=(0, 1), rate=120, props=1, max_items=10).start()
    try:
        assert wait_for(lambda: dev.seq > 24 * 2 * 60)
    finally:
        sender.stop()
        drained([dev])
        dev.stop()
    samples = dev.buffer.drain()
    assert {s.channel.split("/")[0] for s in samples} == {"actor0", "actor1"}
    assert dev.actors == {0: "Actor A", 1: "Actor B"}  # names from the meta data (type 12)
    _check(sender, samples)
    assert dev.lost == 0 and dev.discarded_bytes == 0 and dev.resyncs == 0
    # every sample whole: 24 segments each
    per_sample = {}
    for s in samples:
        per_sample.setdefault((s.channel.split("/")[0], s.data["sample_counter"]), []).append(s)
    assert {len(v) for v in per_sample.values()} == {24}


def test_faults_are_counted_apart_and_never_give_a_wrong_sample():
    dev = _receiver(watchdog=0.3)
    sender = sim_mvn.MVNSender(port=dev.bound_port, actors=(0,), rate=120, max_items=12, meta_every=0).start()
    try:
        assert wait_for(lambda: dev.seq > 23 * 20)
        sender.fault("drop")  # half a split sample lost: the sample is lost
        assert wait_for(lambda: dev.lost == 1)
        sender.fault("garbage", 2)
        sender.fault("other")
        assert wait_for(lambda: dev.resyncs == 2 and dev.skipped == 1)
        sender.fault("duplicate")
        assert wait_for(lambda: dev.discarded_bytes > 2 * 97)
        before = dev.lost
        sender.fault("restart")
        n = dev.seq
        assert wait_for(lambda: dev.seq > n + 23 * 20)
        assert dev.lost == before  # a restarted counter is not a loss
        sender.paused = True
        assert wait_for(lambda: dev.status == "disconnected" and dev.silent)
        sender.paused = False
        assert wait_for(lambda: dev.status == "connected" and dev.reconnects == 1)
    finally:
        sender.stop()
        drained([dev])
        dev.stop()
    samples = dev.buffer.drain()
    assert dev.lost == 1 and dev.discarded_bytes >= 2 * 97 + 12 * 32 + 24
    # samples of the restarted counter are checked against the second use of that counter
    later = [s for s in samples if s.seq > n]
    _check(sender, later)


def test_mvn_calibrates_and_solves_through_the_anatomical_converter():
    """The performer holds the rig's rest pose at one sample; later segment turns become the
    same turns of the rig's bones in its Z-up world."""
    clip, sk, traj = _cmu()
    roles = {"Pelvis": "pelvis", "T8": "chest", "LeftUpperArm": "upper_arm.L", "RightLowerLeg": "shin.R"}
    attach = {("mvn", mvn.channel(0, seg)): sk.roles.bone(role) for seg, role in roles.items()}
    dev = _receiver()
    sender = sim_mvn.MVNSender(port=dev.bound_port, actors=(0,), rate=60).start()
    session = Session([dev]).start(pump_thread=False)
    try:
        assert wait_for(lambda: session.pump() >= 0 and all(k in session.latest for k in attach))
        conv = AnatomicalConverter(sk, attach, root=("mvn", mvn.channel(0, "Pelvis")))
        readings = session.pose_readings()
        conv.calibrate(readings)
        cal = {k: session.latest[k] for k in attach}
        n = dev.seq
        assert wait_for(lambda: dev.seq > n + 24 * 30)
        session.pump()
        later = {k: session.latest[k] for k in attach}
        world = sk.world_frames(conv.solve(session.pose_readings()))
    finally:
        session.stop()
        sender.stop()
    rest = sk.world_frames(np.tile(np.eye(4), (sk.joint_count, 1, 1)))
    for k, bone in attach.items():
        j = sk.index(bone)
        turn = rotations.to_matrix(later[k].data["quaternion"]) @ rotations.to_matrix(cal[k].data["quaternion"]).T
        assert np.allclose(world[j, :3, :3], turn @ rest[j, :3, :3], atol=1e-6), bone
    root = sk.index(attach[("mvn", mvn.channel(0, "Pelvis"))])
    moved = later[("mvn", mvn.channel(0, "Pelvis"))].data["position"] - cal[("mvn", mvn.channel(0, "Pelvis"))].data["position"]
    assert np.allclose(world[root, :3, 3] - rest[root, :3, 3], moved, atol=1e-6)  # Z up stays Z up


def test_a_z_up_reading_is_a_half_turn_in_the_tracker_frame():
    from humananim.humananim_addon.devices.samples import Sample
    q = rotations.normalize(np.array([0.3, 0.1, -0.5, 0.7]))
    s = Sample("mvn", "actor0/Pelvis", 1, 0.0, "pose", {"position": np.array([1.0, 2.0, 3.0]), "quaternion": q,
                                                       "frame": "z_up"})
    p, t = tracker_reading(s)
    half = np.diag([1.0, -1.0, -1.0])
    assert np.allclose(p, half @ [1.0, 2.0, 3.0]) and np.allclose(half @ rotations.to_matrix(t), rotations.to_matrix(q))
