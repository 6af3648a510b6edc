"""Flock of Birds: the real driver through a real pyserial port on a pseudo-terminal."""

import numpy as np
import pytest

from humananim.solver import rotations
from humananim.humananim_addon.devices import fob
from capture_helpers import collect, wait_for

pytest.importorskip("serial")


def test_words_are_14_bits_with_the_phasing_bit_on_the_first_byte_only():
    values = np.array([-1.0, -0.5, 0.0, 0.25, 0.99997, 1e-4])
    data = fob.encode_words(values, 1.0)
    assert len(data) == 12 and data[0] & 0x80 and not any(b & 0x80 for b in data[1:])
    back = fob.decode_words(data) / 32768.0
    assert np.all(np.abs(back - values) <= 4 / 32768.0)  # the two dropped bits
    assert fob.decode_words(fob.encode_words([-1.0], 1.0))[0] == -32768
    # resolution: 36 in / 8192 steps of 14 bits = 0.11 mm; 144 in: 0.45 mm
    assert fob.resolution(36.0) == pytest.approx(36 * 0.0254 / 8192)
    assert fob.resolution(144.0) == pytest.approx(4 * fob.resolution(36.0))


def test_group_record_carries_the_address_byte():
    rec = fob.encode_record("POSITION/QUATERNION", [0.1, 0.2, -0.3], [10, 20, 30], 36.0, address=3)
    assert len(rec) == fob.record_size("POSITION/QUATERNION", group=True) == 15 and rec[-1] == 3


def _expected(sim, fmt, address, tick):
    pos, ang = sim.true_pose(address, tick)
    rec = fob.encode_record(fmt, pos, ang, sim.range_inches)
    return fob.decode_record(fmt, fob.decode_words(rec), sim.range_inches), (pos, ang)


def _check(sample, sim, fmt, address, tick):
    exact, (pos, ang) = _expected(sim, fmt, address, tick)
    d = sample.data
    for key in set(exact) - {"raw_quaternion"}:
        assert np.array_equal(d[key], exact[key]), key  # decoded exactly as sent
    res = fob.resolution(sim.range_inches)
    rot = fob.angles_to_rotation(ang)
    if "position" in d:
        assert np.all(np.abs(d["position"] - pos) <= res + 1e-12)
    if "angles" in d:
        assert np.all(np.abs(d["angles"] - ang) <= 180 * 4 / 32768 + 1e-9)
    if "matrix" in d:
        assert np.abs(d["matrix"] - rot.T).max() <= 4 / 32768 + 1e-12
    if fmt != "POSITION":
        assert rotations.angle_between(d["quaternion"], rotations.from_matrix(rot)) < 1e-3


@pytest.mark.parametrize("fmt", list(fob.RECORDS))
def test_every_record_format_decodes_exactly_in_stream_mode(fmt):
    with fob.FlockSimulator(birds=(1,), rate=200) as sim:
        dev = fob.FlockOfBirds("fob", sim.port, birds=(1,), record=fmt, settle=0.02)
        dev.start()
        try:
            samples = collect(dev, 40)
        finally:
            dev.stop()
        assert dev.last_error == "" and len(samples) >= 40 and sim.formats[1] == fmt
        first = _tick_of(sim, fmt, 1, samples[0].data.get("position"), range(10), samples[0].data)
        assert first is not None
        for k, s in enumerate(samples):
            _check(s, sim, fmt, 1, first + k)


def test_standalone_bird_in_point_mode_and_extended_range():
    with fob.FlockSimulator(birds=(1,), extended_range=True, standalone=True) as sim:
        dev = fob.FlockOfBirds("fob", sim.port, birds=(1,), record="POSITION/ANGLES", mode="POINT",
                               standalone=True, settle=0.02)
        dev.start()
        try:
            samples = collect(dev, 20)
        finally:
            dev.stop()
        assert dev.range_inches == 144.0 and dev.model == "6DERC"
        # the B at open answers one record that is flushed away; polled records follow in order
        first = _tick_of(sim, "POSITION/ANGLES", 1, samples[0].data["position"], range(10))
        assert first is not None
        for k, s in enumerate(samples):
            _check(s, sim, "POSITION/ANGLES", 1, first + k)


def test_the_72_inch_scaling_is_read_from_the_flock():
    with fob.FlockSimulator(birds=(1,), rate=100) as sim:
        sim.scaling = 1  # set earlier with CHANGE VALUE 3, kept by the flock
        dev = fob.FlockOfBirds("fob", sim.port, record="POSITION/ANGLES", settle=0.02)
        dev.start()
        try:
            samples = collect(dev, 10)
        finally:
            dev.stop()
        assert dev.range_inches == 72.0
        first = _tick_of(sim, "POSITION/ANGLES", 1, samples[0].data["position"], range(10))
        for k, s in enumerate(samples):
            _check(s, sim, "POSITION/ANGLES", 1, first + k)


def test_group_mode_reads_several_birds_on_one_port_through_fbb_addressing():
    birds = (1, 2, 3)
    with fob.FlockSimulator(birds=birds, rate=100) as sim:
        dev = fob.FlockOfBirds("fob", sim.port, birds=birds, record="POSITION/MATRIX", hemisphere="UPPER",
                               settle=0.02)
        dev.start()
        try:
            samples = collect(dev, 60)
        finally:
            dev.stop()
        assert sim.group and sim.configured == 3
        assert all(sim.formats[b] == "POSITION/MATRIX" and sim.hemispheres[b] == "UPPER" for b in birds)
        per_bird = {b: [s for s in samples if s.channel == f"bird{b}"] for b in birds}
        assert all(len(v) >= 19 for v in per_bird.values())
        for b, ss in per_bird.items():
            first = _tick_of(sim, "POSITION/MATRIX", b, ss[0].data["position"], range(10))
            for k, s in enumerate(ss):
                _check(s, sim, "POSITION/MATRIX", b, first + k)


class _Chunks:
    """A port whose reads return the given byte chunks, one per read."""

    def __init__(self, chunks):
        self.chunks = list(chunks)
        self.in_waiting = 0

    def read(self, n):
        return self.chunks.pop(0) if self.chunks else b""


def test_a_group_record_split_between_reads_reaches_the_buffer_whole():
    fmt, birds = "POSITION/QUATERNION", (1, 2, 3)
    dev = fob.FlockOfBirds("fob", "unused", birds=birds, record=fmt)
    dev.range_inches = 36.0
    dev._parser = fob.RecordParser(fmt, dev.range_inches, birds)
    dev._held = []
    record = lambda b, k: fob.encode_record(fmt, (0.01 * k, 0.02 * b, 0.0), (10.0 * b, 0, 0), 36.0, b)
    one = record(1, 0) + record(2, 0) + record(3, 0)
    two = record(1, 1) + record(2, 1) + record(3, 1)
    lost = record(1, 2) + record(3, 2)  # bird 2's record of this tick lost on the line
    size = len(record(1, 0))
    dev._ser = _Chunks([one[:size + 4], one[size + 4:] + two[:2 * size], two[2 * size:], lost, record(1, 3)])
    reads = [[s.channel for s in dev._read()] for _ in range(5)]
    assert reads == [[], ["bird1", "bird2", "bird3"], ["bird1", "bird2", "bird3"], ["bird1", "bird3"], []]
    assert [a for a, _ in dev._whole_records([(2, {}), (3, {})])] == [1, 2, 3]  # bird 1 of tick 3 was held
    assert dev._held == []


def test_missing_bird_and_flock_errors_are_reported():
    with fob.FlockSimulator(birds=(1, 2), rate=50) as sim:
        dev = fob.FlockOfBirds("fob", sim.port, birds=(1, 3), settle=0.02, reconnect_interval=0.05)
        dev.start()
        try:
            assert wait_for(lambda: "bird 3 is not accessible" in dev.last_error)
            assert dev.status == "disconnected"
        finally:
            dev.stop()


def test_change_and_examine_value():
    with fob.FlockSimulator(birds=(1,), rate=50) as sim:
        dev = fob.FlockOfBirds("fob", sim.port, mode="POINT", settle=0.02)
        dev._open()
        try:
            assert dev.examine(fob.PARAM_GROUP_MODE) == b"\x00"
            dev.change(fob.PARAM_GROUP_MODE, [1])
            assert dev.examine(fob.PARAM_GROUP_MODE) == b"\x01"
            dev._write(b"\x7e")  # not a command
            assert dev.error_code() == 6 and "Invalid RS232" in fob.ERRORS[6]
            assert dev.error_code() == 0  # reading the code clears it
        finally:
            dev._close()


def _tick_of(sim, fmt, address, position, ticks, data=None):
    for t in ticks:
        exact, _ = _expected(sim, fmt, address, t)
        key = "position" if "position" in exact else next(iter(exact))
        if np.array_equal(exact[key], position if data is None or key == "position" else data[key]):
            return t
    return None


def test_garbage_and_partial_records_resync_without_losing_later_samples():
    fmt, birds = "POSITION/QUATERNION", (1, 2)
    with fob.FlockSimulator(birds=birds, rate=100) as sim:
        dev = fob.FlockOfBirds("fob", sim.port, birds=birds, record=fmt, settle=0.02)
        dev.start()
        try:
            assert wait_for(lambda: dev.seq >= 20)
            rng = np.random.default_rng(1)
            with sim._lock:  # between two ticks: garbage, then half a record, then more garbage
                cut = sim.tick_count
                sim.send(bytes(rng.integers(0, 256, 37, dtype=np.uint8)))
                sim.send(sim._records(cut, birds)[:9])
                sim.send(bytes(rng.integers(0, 128, 11, dtype=np.uint8)))
            assert wait_for(lambda: dev.seq >= 2 * (cut + 30))
        finally:
            dev.stop()
        samples = dev.buffer.drain()  # the buffer kept every decoded sample
        assert dev.garbage_bytes > 0 and dev.lost >= 1
    decoded = {b: [] for b in birds}
    for s in samples:
        decoded[int(s.channel[4:])].append(s)
    for b in birds:
        ticks = [_tick_of(sim, fmt, b, s.data["position"], range(0, cut + 40)) for s in decoded[b]]
        assert None not in ticks
        after = [t for t in ticks if t >= cut]
        assert after[: 30] == list(range(cut, cut + 30))  # every record after the garbage arrived



def test_status_shows_resyncing_while_only_garbage_arrives_then_connected():
    with fob.FlockSimulator(birds=(1,), rate=100) as sim:
        dev = fob.FlockOfBirds("fob", sim.port, settle=0.02, watchdog=5.0)
        dev.start()
        try:
            assert wait_for(lambda: dev.status == "connected" and dev.seq > 5)
            with sim._lock:
                sim.streaming = False
                sim.send(bytes(range(1, 100, 3)) + bytes([0x85, 0x01, 0x02]))  # noise and half a record
            assert wait_for(lambda: dev.status == "resyncing")
            with sim._lock:
                sim.streaming = True
            n = dev.seq
            assert wait_for(lambda: dev.status == "connected" and dev.seq > n + 5)
        finally:
            dev.stop()
