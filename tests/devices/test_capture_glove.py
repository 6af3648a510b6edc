"""CyberGlove through a pseudo-terminal, its calibration to finger joint angles, the USB HID
glove's report decoders and the gesture commands."""

import math
import sys

import numpy as np
import pytest

from humananim.humananim_addon.devices import cyberglove, hidglove, sim_glove
from humananim.humananim_addon.devices.device import DeviceError
from humananim.humananim_addon.devices.gestures import GestureRecognizer, finger_curls
from humananim.humananim_addon.devices.glove_calibration import DIP_COUPLING, FIST_DEGREES, GloveCalibration
from capture_helpers import collect, wait_for

pytest.importorskip("serial")


def _first_tick(sim, raw, ticks=range(20)):
    for t in ticks:
        if np.array_equal(sim.values(t).astype(float), raw):
            return t
    return None


@pytest.mark.parametrize("sensors", [18, 22])
@pytest.mark.parametrize("mode", ["STREAM", "POLL"])
def test_records_decode_exactly(sensors, mode):
    with sim_glove.CyberGloveSimulator(sensors=sensors, rate=150) as sim:
        dev = cyberglove.CyberGlove("glove", sim.port, sensors=sensors, mode=mode, settle=0.02)
        dev.start()
        try:
            samples = collect(dev, 30)
        finally:
            dev.stop()
        assert dev.last_error == "" and len(samples) >= 30
        first = _first_tick(sim, samples[0].data["raw"])
        assert first is not None
        for k, s in enumerate(samples):
            assert s.data["raw"].shape == (sensors,)
            assert np.array_equal(s.data["raw"], sim.values(first + k).astype(float))


@pytest.mark.parametrize("time_stamp", [False, True])
@pytest.mark.parametrize("status_byte", [False, True])
@pytest.mark.parametrize("left_on", [False, True])
def test_time_stamp_and_status_byte_configured_from_any_state(time_stamp, status_byte, left_on):
    """The driver sets 'D' and 'U' to what it is configured for, whatever another program left
    on the glove, and parses the records that follow exactly."""
    with sim_glove.CyberGloveSimulator(sensors=18, rate=150) as sim:
        sim.time_stamp = sim.status_byte = sim.streaming = left_on  # another program left it streaming too
        dev = cyberglove.CyberGlove("glove", sim.port, sensors=18, settle=0.02, time_stamp=time_stamp,
                                    status_byte=status_byte)
        dev.start()
        try:
            samples = collect(dev, 30)
        finally:
            dev.stop()
        assert dev.last_error == "" and dev.discarded_bytes == 0 and dev.resyncs == 0
        assert (sim.time_stamp, sim.status_byte) == (time_stamp, status_byte)
        first = _first_tick(sim, samples[0].data["raw"])
        assert first is not None
        for k, s in enumerate(samples):
            assert np.array_equal(s.data["raw"], sim.values(first + k).astype(float))
            assert ("time_stamp" in s.data) == time_stamp and ("status" in s.data) == status_byte
            if time_stamp:
                assert s.data["time_stamp"] == round(1000 * (first + k) / sim.rate)


def test_a_glove_power_cycled_mid_session_is_configured_again():
    with sim_glove.CyberGloveSimulator(sensors=22, rate=150) as sim:
        dev = cyberglove.CyberGlove("glove", sim.port, sensors=22, settle=0.02, time_stamp=True, status_byte=True,
                                    watchdog=0.3, reconnect_interval=0.05)
        dev.start()
        try:
            assert wait_for(lambda: dev.seq > 10)
            sim.power_cycle()  # the box restarts: time stamp and status byte off, not streaming
            assert wait_for(lambda: dev.reconnects == 1 and sim.time_stamp and sim.status_byte, timeout=15)
            dev.buffer.drain()
            samples = collect(dev, 20)
        finally:
            dev.stop()
        for s in samples:
            tick = round(s.data["time_stamp"] * sim.rate / 1000)
            assert np.array_equal(s.data["raw"], sim.values(tick).astype(float)) and s.data["status"] == 1


def test_time_stamp_bytes_that_are_zero_are_nul_encoded():
    parser = cyberglove.GloveParser(18, time_stamp=True, status_byte=True)
    with sim_glove.CyberGloveSimulator(sensors=18) as sim:
        sim.time_stamp = sim.status_byte = True
        for stamp_ms, tick in ((0, 0), (256000, 25600), (16777216 // 10, 1677721)):
            rec = sim.record(b"S", tick)
            assert b"\x00" not in rec[1:-1][19:]  # the stamp's bytes are never NUL
            (d,) = parser.feed(rec)
            assert d["time_stamp"] == round(1000 * tick / sim.rate) and d["status"] == 1
    assert parser.discarded_bytes == 0


@pytest.mark.parametrize("mode", ["STREAM", "POLL"])
def test_an_error_reply_is_an_error_never_a_record(mode):
    with sim_glove.CyberGloveSimulator(sensors=18, rate=100) as sim:
        dev = cyberglove.CyberGlove("glove", sim.port, sensors=18, mode=mode, settle=0.02, watchdog=5.0)
        dev.start()
        try:
            assert wait_for(lambda: dev.seq > 5)
            sim.inject(b"e?\x00")  # e.g. a command the glove did not know
            assert wait_for(lambda: "unknown command" in dev.last_error)
            n = dev.seq
            assert wait_for(lambda: dev.seq > n + 10) and dev.reconnects == 0
        finally:
            dev.stop()
        samples = dev.buffer.drain()
        first = _first_tick(sim, samples[0].data["raw"], range(sim.tick_count))
        for k, s in enumerate(samples):  # every sample a record, in order; the error is none of them
            assert np.array_equal(s.data["raw"], sim.values(first + k).astype(float))


def test_wrong_model_and_unplugged_glove_are_reported():
    with sim_glove.CyberGloveSimulator(sensors=22) as sim:
        dev = cyberglove.CyberGlove("glove", sim.port, sensors=18, settle=0.02, reconnect_interval=0.05)
        dev.start()
        try:
            assert wait_for(lambda: "has 22 sensors" in dev.last_error)
        finally:
            dev.stop()
    with sim_glove.CyberGloveSimulator(sensors=18) as sim:
        dev = cyberglove.CyberGlove("glove", sim.port, sensors=18, settle=0.02, reconnect_interval=0.05)
        dev.start()
        try:
            assert wait_for(lambda: dev.seq > 5)
            sim.glove_plugged = False
            assert wait_for(lambda: "glove not plugged in" in dev.last_error and dev.status == "disconnected")
            assert all(s.data["raw"].shape == (18,) for s in dev.buffer.drain())  # no error became a record
            sim.glove_plugged = True
            n = dev.seq
            assert wait_for(lambda: dev.status == "connected" and dev.seq > n + 5)
        finally:
            dev.stop()


def test_garbage_resyncs_and_keeps_later_records():
    with sim_glove.CyberGloveSimulator(sensors=18, rate=100) as sim:
        dev = cyberglove.CyberGlove("glove", sim.port, sensors=18, settle=0.02)
        dev.start()
        try:
            assert wait_for(lambda: dev.seq >= 10)
            with sim._lock:
                cut = sim.tick_count
                sim.send(b"\x01\x02S\x05\x06" + sim.record(b"S", cut)[:7] + b"garbage")
            assert wait_for(lambda: dev.seq >= cut + 25)
        finally:
            dev.stop()
        samples = dev.buffer.drain()
        assert dev.discarded_bytes > 0 and dev.resyncs >= 1 and dev.lost == 0
        ticks = [_first_tick(sim, s.data["raw"], range(cut + 40)) for s in samples]
        after = [t for t in ticks if t is not None and t >= cut]
        assert after[:20] == list(range(cut, cut + 20))


def test_flat_and_fist_calibration_gives_the_fist_angles():
    layout = cyberglove.SENSORS_18
    rng = np.random.default_rng(3)
    flat = rng.uniform(30, 80, len(layout))
    fist = flat + rng.uniform(60, 150, len(layout))
    cal = GloveCalibration.from_poses(layout, flat, fist)
    a_flat, a_fist = cal.angles(flat), cal.angles(fist)
    assert all(abs(v) < 1e-12 for v in a_flat.values())
    for (finger, bone, axis), v in a_fist.items():
        if axis == "flex" and (finger, bone) in FIST_DEGREES and not (finger != "thumb" and bone == 2):
            assert v == pytest.approx(math.radians(FIST_DEGREES[(finger, bone)]))
    # 18 sensors: no distal sensor, the distal joint follows the middle one
    assert a_fist[("index", 2, "flex")] == pytest.approx(DIP_COUPLING * a_fist[("index", 1, "flex")])
    halfway = cal.angles((flat + fist) / 2)
    assert halfway[("middle", 0, "flex")] == pytest.approx(math.radians(FIST_DEGREES[("middle", 0)]) / 2)
    with pytest.raises(DeviceError, match="hardly changed"):
        GloveCalibration.from_poses(layout, flat, flat)
    assert GloveCalibration.from_dict(cal.to_dict()).angles(fist) == pytest.approx(a_fist)


def test_22_sensor_glove_reads_the_distal_joints():
    layout = cyberglove.SENSORS_22
    flat, fist = np.full(22, 50.0), np.full(22, 200.0)
    a = GloveCalibration.from_poses(layout, flat, fist).angles(fist)
    assert a[("ring", 2, "flex")] == pytest.approx(math.radians(FIST_DEGREES[("ring", 2)]))


def test_5dt_ultra_reports_decode_through_the_plugin():
    values = np.round(np.linspace(0.1, 0.9, 14) * 4096) / 4096
    report = hidglove.FiveDTUltra.encode(values, 14)
    assert len(report) == 64
    assert np.array_equal(hidglove.DECODERS["5dt_ultra_14"].decode(report), values)
    five = values[:5]
    assert np.array_equal(hidglove.DECODERS["5dt_ultra_5"].decode(hidglove.FiveDTUltra.encode(five, 5)), five)
    with pytest.raises(ValueError):
        hidglove.DECODERS["5dt_ultra_14"].decode(report[:20])


def test_5dt_glove_calibrates_on_its_own_scale():
    dec = hidglove.DECODERS["5dt_ultra_14"]
    flat, fist = np.full(14, 0.2), np.full(14, 0.8)
    cal = GloveCalibration.from_poses(dec.layout, flat, fist, dec.resolution)
    a = cal.angles(dec.decode(hidglove.FiveDTUltra.encode(fist)))
    assert a[("index", 1, "flex")] == pytest.approx(math.radians(FIST_DEGREES[("index", 1)]), abs=1e-3)
    with pytest.raises(DeviceError, match="hardly changed"):
        GloveCalibration.from_poses(dec.layout, flat, flat + 1 / 4096, dec.resolution)


def test_a_new_glove_is_a_new_decoder_not_a_new_driver(monkeypatch):
    class Toy(hidglove.ReportDecoder):
        name, vendor_id, product_ids = "toy", 0x1234, (0x1,)
        layout = (("index", 0, "flex"),)

        def decode(self, report):
            return np.array([report[1] / 255.0])

    hidglove.register_decoder(Toy())
    try:
        class FakeDevice:
            def open_path(self, path):
                self.path = path

            def read(self, n, timeout):
                return [1, 51] + [0] * 62

            def close(self):
                pass

        class FakeHid:
            @staticmethod
            def enumerate():
                return [{"vendor_id": 0x1234, "product_id": 0x1, "path": b"/dev/hidraw9"}]

            device = FakeDevice

        monkeypatch.setitem(sys.modules, "hid", FakeHid)
        dev = hidglove.HidGlove("toy", decoder="toy")
        dev._open()
        (s,) = dev._read()
        assert s.data["raw"][0] == pytest.approx(0.2) and s.data["model"] == "toy"
    finally:
        hidglove.DECODERS.pop("toy")


def test_hid_glove_says_clearly_what_is_missing(monkeypatch):
    monkeypatch.setitem(sys.modules, "hid", None)  # import hid fails
    dev = hidglove.HidGlove("g")
    with pytest.raises(DeviceError, match="hidapi is not installed"):
        dev._open()

    class NoGlove:
        @staticmethod
        def enumerate():
            return []

    monkeypatch.setitem(sys.modules, "hid", NoGlove)
    with pytest.raises(DeviceError, match="no USB glove"):
        dev._open()
    with pytest.raises(DeviceError, match="no HID glove decoder"):
        hidglove.HidGlove("g", decoder="nope")


def _angles(curl):
    """Calibrated angles with each finger curled by the given fraction of a fist."""
    out = {}
    for f, c in curl.items():
        for k in (0, 1):
            if (f, k) in FIST_DEGREES:
                out[(f, k, "flex")] = c * math.radians(FIST_DEGREES[(f, k)])
    return out


def test_gestures_fire_on_a_change_of_posture_with_hysteresis():
    g = GestureRecognizer(hold=0.2)
    fist = dict(index=1.0, middle=1.0, ring=1.0, pinky=1.0, thumb=1.0)
    flat = dict(index=0.0, middle=0.0, ring=0.0, pinky=0.0, thumb=0.0)
    point = dict(flat, middle=0.9, ring=0.9, pinky=0.9)
    fired = []
    t = 0.0

    def hold(curls, seconds):
        nonlocal t
        end = t + seconds
        while t < end:
            c = g.update(t, _angles(curls))
            if c:
                fired.append(c)
            t += 0.01

    hold(flat, 0.5)
    assert fired == ["neutral"]
    hold(fist, 0.1)  # too short to count
    hold(flat, 0.3)
    assert fired == ["neutral"]
    hold(fist, 1.0)  # held: one command only, not one per sample
    assert fired == ["neutral", "recalibrate"]
    # hysteresis: a finger halfway back (between the thresholds) keeps its state
    hold(dict(fist, index=0.5), 0.5)
    assert fired == ["neutral", "recalibrate"]
    hold(point, 0.5)
    hold(dict(point, index=0.5), 0.5)  # still pointing
    assert fired == ["neutral", "recalibrate", "start_recording"]
    curls = finger_curls(_angles(point))
    assert curls["index"] == pytest.approx(0.0) and curls["ring"] == pytest.approx(0.9)
