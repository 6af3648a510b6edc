"""VMC over a local UDP socket: the minimal OSC codec and the receiver."""

import struct

import numpy as np
import pytest

from humananim.solver import rotations
from humananim.humananim_addon.devices import osc, vmc
from capture_helpers import wait_for


def test_osc_messages_and_nested_bundles_round_trip():
    m = osc.encode_message("/VMC/Ext/Bone/Pos", "Hips", 1.5, -2.0, 0.25, 0.0, 0.0, 0.0, 1.0)
    assert len(m) % 4 == 0
    ((addr, args),) = osc.parse(m)
    assert addr == "/VMC/Ext/Bone/Pos" and args[0] == "Hips" and args[1:] == [1.5, -2.0, 0.25, 0.0, 0.0, 0.0, 1.0]
    inner = osc.encode_bundle([osc.encode_message("/a", 3, "xyz", b"\x01\x02\x03", True, None)])
    out = osc.parse(osc.encode_bundle([m, inner, osc.encode_message("/VMC/Ext/Blend/Apply")]))
    assert [a for a, _ in out] == ["/VMC/Ext/Bone/Pos", "/a", "/VMC/Ext/Blend/Apply"]
    assert out[1][1] == [3, "xyz", b"\x01\x02\x03", True, None]
    with pytest.raises(osc.OSCError):
        osc.parse(b"#bundle\x00" + bytes(8) + struct.pack(">i", 999) + b"abcd")
    with pytest.raises(osc.OSCError):
        osc.parse(b"garbage")


def test_unity_frames_convert_to_z_up_and_back():
    rng = np.random.default_rng(0)
    for _ in range(10):
        p, q = rng.normal(size=3), rotations.normalize(rng.normal(size=4))
        up, uq = vmc.to_unity(p, q)
        p2, q2 = vmc.from_unity(up, uq)
        assert np.allclose(p2, p) and np.allclose(q2, q)
    # Unity's up (+Y) is Blender's up (+Z); Unity's forward (+Z) is Blender's -Y
    assert np.allclose(vmc.from_unity((0, 1, 0), (0, 0, 0, 1))[0], (0, 0, 1))
    assert np.allclose(vmc.from_unity((0, 0, 1), (0, 0, 0, 1))[0], (0, -1, 0))


def test_receiver_listens_on_localhost_and_decodes_bones_root_and_blendshapes():
    assert vmc.DEFAULT_PORT == 39539 and vmc.VMCReceiver("v").host == "127.0.0.1"
    dev = vmc.VMCReceiver("vmc", port=0)
    dev.start()
    try:
        assert wait_for(lambda: dev.bound_port)
        sender = vmc.VMCSender(port=dev.bound_port)
        q = rotations.normalize(np.array([0.9, 0.1, -0.2, 0.3]))
        for k in range(20):
            sender.frame({"Hips": ((0.0, 0.0, 1.0 + 0.01 * k), q), "LeftUpperArm": ((0.1, 0, 0), q)},
                         root=((0.5, 0.0, 0.0), (1.0, 0, 0, 0)), blendshapes={"A": 0.5})
        assert wait_for(lambda: dev.seq >= 20)
        sender.raw(b"not osc at all")
        sender.frame({"Hips": ((0.0, 0.0, 2.0), q)})
        assert wait_for(lambda: dev.seq >= 21)
        sender.close()
    finally:
        dev.stop()
    samples = dev.buffer.drain()
    assert len(samples) == 21 and dev.bad_packets == 1
    last = samples[-1].data
    pos, quat = last["bones"]["Hips"]
    assert np.allclose(pos, (0, 0, 2.0), atol=1e-6) and np.allclose(quat, q, atol=1e-6)
    assert np.allclose(samples[-2].data["bones"]["Hips"][0], (0, 0, 1.19), atol=1e-6)
    assert last["blendshapes"] == {"A": 0.5} and np.allclose(last["root"][0], (0.5, 0, 0))
    assert last["roles"]["LeftUpperArm"] == ("upper_arm.L", 0)


def test_receiver_reports_silence_as_disconnected_and_comes_back():
    dev = vmc.VMCReceiver("vmc", port=0, watchdog=0.2)
    dev.start()
    try:
        assert wait_for(lambda: dev.status == "disconnected")
        sender = vmc.VMCSender(port=dev.bound_port)
        assert wait_for(lambda: sender.frame({"Hips": ((0, 0, 1), (1, 0, 0, 0))}) or dev.status == "connected")
        sender.close()
    finally:
        dev.stop()


def test_port_in_use_is_a_clear_error():
    import socket
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    try:
        dev = vmc.VMCReceiver("vmc", port=s.getsockname()[1])
        with pytest.raises(Exception, match="cannot listen on 127.0.0.1"):
            dev._open()
    finally:
        s.close()
