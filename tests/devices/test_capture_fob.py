"""Flock of Birds: the real driver (fob.py) through a real pyserial port on a pseudo-terminal,
against the simulator written separately from the guide (sim_fob.py): every record format to
one rotation convention, every state the flock can be left in, every addressing configuration,
and honest counters."""

import numpy as np
import pytest

from humananim.solver import rotations
from humananim.humananim_addon.devices import fob, sim_fob
from capture_helpers import collect, wait_for

pytest.importorskip("serial")

ANGLE_STEP = 180.0 * 4 / 32768  # one step of a 14-bit angle word


def _truth(angles):
    return rotations.from_matrix(fob.angles_to_rotation(angles))


def test_words_are_14_bits_with_the_phasing_bit_on_the_first_byte_only():
    values = np.array([-1.0, -0.5, 0.0, 0.25, 0.99997, 1e-4])
    data = sim_fob.words(values, 1.0)
    assert len(data) == 12 and data[0] & 0x80 and not any(b & 0x80 for b in data[1:])
    back = fob.decode_words(data) / 32768.0
    assert np.all(np.abs(back - values) <= 4 / 32768.0)  # the two dropped bits
    assert fob.decode_words(sim_fob.words([-1.0], 1.0))[0] == -32768
    assert fob.resolution(36.0) == pytest.approx(36 * 0.0254 / 8192)
    assert fob.resolution(144.0) == pytest.approx(4 * fob.resolution(36.0))


def test_the_guides_matrix_is_the_transpose_of_the_sensor_rotation():
    rng = np.random.default_rng(0)
    for _ in range(20):
        ang = rng.uniform([-180, -89, -180], [180, 89, 180])
        m = sim_fob.matrix_m(*ang)
        assert np.allclose(m, fob.angles_to_rotation(ang).T, atol=1e-12)
        assert np.allclose(fob.rotation_to_angles(m.T), ang, atol=1e-9)


def test_every_format_gives_one_rotation_for_the_same_pose():
    """The same pose sent as ANGLES, MATRIX and QUATERNION (with and without position) decodes
    to one quaternion: the sensor's orientation in the transmitter frame."""
    rng = np.random.default_rng(1)
    worst = 0.0
    for _ in range(300):
        ang = rng.uniform([-180, -89.9, -180], [180, 89.9, 180])
        pos = rng.uniform(-0.8, 0.8, 3)
        truth = _truth(ang)
        quats = {}
        for fmt in fob.RECORDS:
            if fmt == "POSITION":
                continue
            rec = sim_fob.record(fmt, pos, ang, 36.0)
            d = fob.decode_record(fmt, fob.decode_words(rec), 36.0)
            quats[fmt] = d["quaternion"]
            if "position" in d:
                assert np.all(np.abs(d["position"] - pos) <= fob.resolution(36.0))
        for fmt, q in quats.items():
            err = np.degrees(rotations.angle_between(q, truth))
            worst = max(worst, err)
            assert err < 0.1, (fmt, ang, err)
    assert worst > 0.0  # quantised, not compared with itself


def _match(sim, bird, samples, fmt, search):
    """The tick of each sample: its decoded pose equals the simulator's true pose at that tick
    within one step of the words; None for a sample no tick explains (a wrong sample)."""
    ticks = []
    res = fob.resolution(sim.range_inches)
    for s in samples:
        found = None
        for t in search:
            pos, ang = sim.true_pose(bird, t)
            d = s.data
            if "position" in d and np.any(np.abs(d["position"] - pos) > res + 1e-9):
                continue
            if fmt != "POSITION" and np.degrees(rotations.angle_between(d["quaternion"], _truth(ang))) > 0.1:
                continue
            found = t
            break
        ticks.append(found)
    return ticks


def _check_stream(sim, dev, samples, fmt, birds, search=None):
    """Every sample is a record of the bird it is labelled with, in order, none missing."""
    search = search or range(0, sim.tick_count + 5)
    for b in birds:
        ss = [s for s in samples if s.channel == f"bird{b}"]
        assert len(ss) >= 5, (b, len(samples))
        ticks = _match(sim, b, ss, fmt, search)
        assert None not in ticks, f"bird {b}: a sample matches no tick of that bird"
        assert ticks == list(range(ticks[0], ticks[0] + len(ticks)))
    assert {s.channel for s in samples} == {f"bird{b}" for b in birds}


def _run(sim, dev, n=30):
    dev.buffer.drain()  # samples the reader pushed after an earlier run's last collect are not this run's
    dev.start()
    try:
        samples = collect(dev, n)
    finally:
        dev.stop()
    return samples


@pytest.mark.parametrize("fmt", list(fob.RECORDS))
def test_every_record_format_decodes_in_stream_mode(fmt):
    with sim_fob.FlockSimulator(birds=(1,), rate=200) as sim:
        dev = fob.FlockOfBirds("fob", sim.port, birds=(1,), record=fmt, settle=0.02)
        samples = _run(sim, dev, 40)
        assert dev.last_error == "" and sim.formats[1] == fmt
        _check_stream(sim, dev, samples, fmt, (1,))


# -- any state to the configured one ------------------------------------------------------------
def _leave(sim, state):
    """Put the flock in a state an earlier session (or the power switch) left it in."""
    with sim._lock:
        if state == "asleep":
            sim.configured, sim.asleep = len(sim.units), True
        elif state == "group_mode_left_on":
            sim.configured, sim.group = len(sim.units), True
            sim.streaming, sim.stream_target = True, 1
        elif state == "already_streaming":
            sim.configured, sim.streaming, sim.stream_target = len(sim.units), True, 1
        elif state == "formats_left_over":
            sim.configured = len(sim.units)
            sim.formats = {b: "MATRIX" for b in sim.birds}
            sim.hemispheres = {b: "AFT" for b in sim.birds}
            sim.error = 6
        # "power_up": the simulator starts in its power-up state


@pytest.mark.parametrize("state", ["power_up", "asleep", "group_mode_left_on", "already_streaming",
                                   "formats_left_over"])
@pytest.mark.parametrize("mode", ["STREAM", "POINT"])
def test_one_bird_connects_from_any_state(state, mode):
    fmt = "POSITION/QUATERNION"
    with sim_fob.FlockSimulator(birds=(1, 2, 3), rate=150) as sim:
        _leave(sim, state)
        dev = fob.FlockOfBirds("fob", sim.port, birds=(1,), record=fmt, mode=mode, settle=0.03)
        samples = _run(sim, dev)
        assert dev.last_error == "" and not sim.group and sim.formats[1] == fmt
        assert sim.hemispheres[1] == "FORWARD"
        _check_stream(sim, dev, samples, fmt, (1,))  # no record of birds 2 and 3 labelled bird 1
        assert dev.lost == 0


def test_connect_after_disconnect_and_after_a_power_cycle_during_a_silent_pause():
    fmt = "POSITION/ANGLES"
    with sim_fob.FlockSimulator(birds=(1, 2), rate=150) as sim:
        dev = fob.FlockOfBirds("fob", sim.port, birds=(1, 2), record=fmt, settle=0.03)
        _check_stream(sim, dev, _run(sim, dev), fmt, (1, 2))
        # our disconnect put the transmitter to sleep (the simulator reads the command on its own thread)
        assert wait_for(lambda: sim.asleep)
        _check_stream(sim, dev, _run(sim, dev), fmt, (1, 2))  # a second Connect wakes it
        dev = fob.FlockOfBirds("fob", sim.port, birds=(1, 2), record=fmt, settle=0.03, watchdog=0.3,
                               reconnect_interval=0.05)
        dev.start()
        try:
            assert wait_for(lambda: dev.seq > 20)
            with sim._lock:
                sim.streaming = False  # a silent pause ...
            sim.power_cycle()  # ... during which the flock is switched off and on
            assert wait_for(lambda: dev.reconnects >= 1 and dev.status == "connected", timeout=15)
            dev.buffer.drain()
            after = collect(dev, 30)
        finally:
            dev.stop()
        assert sim.power_ups == 2
        _check_stream(sim, dev, after, fmt, (1, 2))


def test_a_different_number_of_birds_than_last_time():
    fmt = "POSITION/QUATERNION"
    with sim_fob.FlockSimulator(birds=(1, 2, 3), rate=150) as sim:
        for birds in ((1, 2, 3), (1,), (1, 2), (2, 3), (3,)):
            dev = fob.FlockOfBirds("fob", sim.port, birds=birds, record=fmt, settle=0.03)
            samples = _run(sim, dev, 15 * len(birds))
            assert dev.last_error == "" and sim.group == (len(birds) > 1), birds
            _check_stream(sim, dev, samples, fmt, birds)


# -- addressing ------------------------------------------------------------------------------------
@pytest.mark.parametrize("config", ["standalone", "flock_one_bird_at_2", "flock_several", "erc_one_bird",
                                    "erc_several"])
@pytest.mark.parametrize("mode", ["STREAM", "POINT"])
def test_addressing_in_every_configuration(config, mode):
    fmt = "POSITION/MATRIX"
    physical, read, kw = {
        "standalone": ((1,), (1,), dict(standalone=True)),
        "flock_one_bird_at_2": ((1, 2), (2,), {}),
        "flock_several": ((1, 2, 3, 4), (1, 3, 4), {}),
        "erc_one_bird": ((2,), (2,), {}),
        "erc_several": ((2, 3, 4), (2, 3, 4), {}),
    }[config]
    erc = config.startswith("erc")
    with sim_fob.FlockSimulator(birds=physical, extended_range=erc, rate=150, standalone=config == "standalone") as sim:
        dev = fob.FlockOfBirds("fob", sim.port, birds=read, record=fmt, mode=mode, settle=0.03, **kw)
        samples = _run(sim, dev, 15 * len(read))
        assert dev.last_error == ""
        assert dev.range_inches == (144.0 if erc else 36.0) and ("ERC" in dev.model) == erc
        _check_stream(sim, dev, samples, fmt, read)


def test_the_72_inch_scaling_is_read_from_the_flock():
    with sim_fob.FlockSimulator(birds=(1,), rate=150) as sim:
        sim.scaling = 1  # set earlier with CHANGE VALUE 3, kept by the flock
        dev = fob.FlockOfBirds("fob", sim.port, record="POSITION/ANGLES", settle=0.03)
        samples = _run(sim, dev)
        assert dev.range_inches == 72.0
        _check_stream(sim, dev, samples, "POSITION/ANGLES", (1,))


def test_missing_bird_and_flock_errors_are_reported():
    with sim_fob.FlockSimulator(birds=(1, 2), rate=50) as sim:
        dev = fob.FlockOfBirds("fob", sim.port, birds=(1, 3), settle=0.02, reconnect_interval=0.05)
        dev.start()
        try:
            assert wait_for(lambda: "cannot auto-configure 3 units" in dev.last_error)
            assert dev.status == "disconnected"
        finally:
            dev.stop()
        dev = fob.FlockOfBirds("fob", sim.port, birds=(1, 3), units=2, settle=0.02, reconnect_interval=0.05)
        dev.start()
        try:
            assert wait_for(lambda: "bird 3 is not accessible" in dev.last_error)
        finally:
            dev.stop()
    with sim_fob.FlockSimulator(birds=(2,), extended_range=True, rate=50) as sim:
        dev = fob.FlockOfBirds("fob", sim.port, birds=(1,), settle=0.02, reconnect_interval=0.05)
        dev.start()
        try:  # the ERC at address 1 has no receiver
            assert wait_for(lambda: "bird 1 is not accessible, running and with a sensor" in dev.last_error)
        finally:
            dev.stop()


def test_change_and_examine_value():
    with sim_fob.FlockSimulator(birds=(1,), rate=50) as sim:
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


# -- counters ---------------------------------------------------------------------------------
def test_garbage_between_records_is_discarded_not_lost_and_later_records_all_arrive():
    fmt, birds = "POSITION/QUATERNION", (1, 2)
    with sim_fob.FlockSimulator(birds=birds, rate=100) as sim:
        dev = fob.FlockOfBirds("fob", sim.port, birds=birds, record=fmt, settle=0.02)
        dev.start()
        try:
            assert wait_for(lambda: dev.seq >= 20)
            rng = np.random.default_rng(1)
            with sim._lock:  # between two ticks: garbage, half a record of the next tick, garbage
                cut = sim.tick_count
                sim.send(bytes(rng.integers(0, 256, 37, dtype=np.uint8)))
                sim.send(sim.records(cut, None)[:9])
                sim.send(bytes(rng.integers(0, 128, 11, dtype=np.uint8)))
            assert wait_for(lambda: dev.seq >= 2 * (cut + 30))
        finally:
            dev.stop()
        samples = dev.buffer.drain()
    assert dev.discarded_bytes >= 37 + 9 + 11 - 10 and 1 <= dev.resyncs <= 3
    assert dev.lost == 0  # noise was added, no record was lost
    _check_stream(sim, dev, samples, fmt, birds)


def test_a_bird_cut_from_a_group_tick_is_one_record_lost():
    fmt, birds = "POSITION/ANGLES", (1, 2, 3)
    with sim_fob.FlockSimulator(birds=birds, rate=100) as sim:
        dev = fob.FlockOfBirds("fob", sim.port, birds=birds, record=fmt, settle=0.02)
        dev.start()
        try:
            assert wait_for(lambda: dev.seq >= 30)
            sim.cut(fob.record_size(fmt, group=True))  # the next bird record vanishes on the line
            n = dev.seq
            assert wait_for(lambda: dev.seq >= n + 60)
        finally:
            dev.stop()
        samples = dev.buffer.drain()
    assert dev.lost == 1 and dev.discarded_bytes == 0
    gaps = {}
    for b in birds:
        ticks = _match(sim, b, [s for s in samples if s.channel == f"bird{b}"], fmt, range(sim.tick_count + 5))
        assert None not in ticks  # no wrong sample
        gaps[b] = sorted(set(np.diff(ticks)))
    assert sorted(gaps.values()) == [[1], [1], [1, 2]]  # one bird skipped one tick, the others none


def test_a_group_record_split_between_reads_reaches_the_buffer_whole():
    fmt, birds = "POSITION/QUATERNION", (1, 2, 3)
    dev = fob.FlockOfBirds("fob", "unused", birds=birds, record=fmt)
    dev.range_inches = 36.0
    dev._parser = fob.RecordParser(fmt, dev.range_inches, birds)
    record = lambda b, k: sim_fob.record(fmt, (0.01 * k, 0.02 * b, 0.0), (10.0 * b, 0, 0), 36.0) + bytes([b])
    one = record(1, 0) + record(2, 0) + record(3, 0)
    two = record(1, 1) + record(2, 1) + record(3, 1)
    lost = record(1, 2) + record(3, 2)  # bird 2's record of this tick lost on the line
    size = len(record(1, 0))

    class Chunks:
        in_waiting = 0

        def __init__(self, chunks):
            self.chunks = list(chunks)

        def read(self, n):
            return self.chunks.pop(0) if self.chunks else b""

    dev._ser = Chunks([one[:size + 4], one[size + 4:] + two[:2 * size], two[2 * size:], lost, record(1, 3)])
    dev._last_data = 1e18
    reads = [[s.channel for s in dev._read()] for _ in range(5)]
    assert reads == [[], ["bird1", "bird2", "bird3"], ["bird1", "bird2", "bird3"], ["bird1", "bird3"], []]
    assert dev.lost == 1 and dev.discarded_bytes == 0 and dev.resyncs == 0


def test_status_shows_resyncing_while_only_garbage_arrives_then_connected():
    with sim_fob.FlockSimulator(birds=(1,), rate=100) as sim:
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
            st = dev.status_dict()
            assert st["resyncs"] == 1 and st["discarded_bytes"] > 0 and st["lost"] == 0
        finally:
            dev.stop()
