"""The session core: the devices' reader threads feed their ring buffers; a pump (its own thread,
and the display step too) drains them, keeps the newest sample of every channel, runs the glove
gesture commands and records every sample into the take while recording. Nothing here blocks
on a device and nothing touches bpy."""

import collections
import json
import threading
import time

import numpy as np

from .gestures import GestureRecognizer
from .samples import Sample, tracker_reading


class Take:
    """Every sample recorded, per (device, channel), in arrival order."""

    def __init__(self, name="take"):
        self.name = name
        self.samples = collections.defaultdict(list)
        self.started = time.perf_counter()
        self.stopped = None

    def add(self, sample):
        self.samples[(sample.device, sample.channel)].append(sample)

    def count(self, key=None):
        if key is not None:
            return len(self.samples.get(key, ()))
        return sum(len(v) for v in self.samples.values())

    @property
    def keys(self):
        return sorted(self.samples)

    def merged(self):
        """All samples in time order."""
        return sorted((s for v in self.samples.values() for s in v), key=lambda s: (s.time, s.seq))

    def device_ticks(self, device):
        """A device's samples as ticks (one sample per channel: the birds of one group-mode record)
        with their times, bursts spread out: records that arrived in one read (a loaded machine
        reads a few at once) share a decoding time, so they are placed evenly between the previous
        read and theirs, as the device sent them. Returns [(time, [samples])]."""
        samples = sorted((s for (d, _), v in self.samples.items() if d == device for s in v), key=lambda s: s.seq)
        ticks = []
        for s in samples:
            if not ticks or any(x.channel == s.channel for x in ticks[-1]):
                ticks.append([s])
            else:
                ticks[-1].append(s)
        t = np.array([max(x.time for x in tick) for tick in ticks])
        out = t.copy()
        i = 0
        while i < len(t):
            j = i
            while j + 1 < len(t) and t[j + 1] - t[i] < 1e-4:
                j += 1
            if j > i and i > 0:
                out[i:j + 1] = t[i - 1] + (t[i] - t[i - 1]) * np.arange(1, j - i + 2) / (j - i + 1)
            elif j > i:  # a burst first in the take: back from its time at the device's usual period
                steps = np.diff(np.unique(t))
                period = float(np.median(steps)) if len(steps) else 1e-3
                out[:j + 1] = t[j] - period * np.arange(j, -1, -1)
            i = j + 1
        return list(zip(out, ticks))

    def poses(self, merge=0.001):
        """Poses in time order: every tick of every device, with ticks of different devices closer
        than `merge` seconds made one pose. Returns [(time, [samples])]."""
        ticks = []
        for device in sorted({d for d, _ in self.samples}):
            ticks.extend(self.device_ticks(device))
        ticks.sort(key=lambda x: (x[0], x[1][0].seq))
        out = []
        for t, group in ticks:
            keys = {(s.device, s.channel) for s in group}
            if out and t - out[-1][0] < merge and not keys & {(s.device, s.channel) for s in out[-1][1]}:
                out[-1][1].extend(group)
            else:
                out.append((t, list(group)))
        return out

    @property
    def duration(self):
        times = [s.time for v in self.samples.values() for s in v]
        return (max(times) - min(times)) if len(times) > 1 else 0.0

    def to_dict(self):
        return {"name": self.name, "samples": [
            {"device": s.device, "channel": s.channel, "seq": s.seq, "time": s.time, "kind": s.kind,
             "data": _jsonable(s.data)} for s in self.merged()]}

    def save(self, path):
        with open(path, "w") as f:
            json.dump(self.to_dict(), f)

    @classmethod
    def load(cls, path):
        with open(path) as f:
            d = json.load(f)
        take = cls(d.get("name", "take"))
        for s in d["samples"]:
            take.add(Sample(s["device"], s["channel"], s["seq"], s["time"], s["kind"], _arrays(s["data"])))
        return take


def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, np.generic):
        return x.item()
    return x


def _arrays(x):
    if isinstance(x, dict):
        return {k: _arrays(v) for k, v in x.items()}
    if isinstance(x, list) and x and all(isinstance(v, (int, float)) for v in x):
        return np.asarray(x, float)
    if isinstance(x, list):
        return [_arrays(v) for v in x]
    return x


class Session:
    """`pump_interval`: how often the pump thread drains the devices. The display step pumps
    before it reads, so this is not in the rig's latency: the thread keeps the take, the
    gestures and the ring buffers going while the main thread is busy, and every wake-up of
    it takes the interpreter's lock from the readers and the display step."""

    def __init__(self, devices, pump_interval=0.02):
        self.devices = list(devices)
        self.pump_interval = pump_interval
        self.latest = {}
        self.take = None
        self.takes = []
        self.recording = False
        self.events = collections.deque(maxlen=100)
        self.glove_calibrations = {}  # device name -> GloveCalibration
        self.gestures = GestureRecognizer()
        self.converter = None  # an AnatomicalConverter to recalibrate on the fist gesture
        self.calibration_pose = None
        self.take_name = "take"  # the name of takes started by a gesture
        self._lock = threading.RLock()
        self._stop = threading.Event()
        self._thread = None
        self.pumped = 0

    # -- lifecycle -------------------------------------------------------------------------
    def start(self, pump_thread=True):
        for d in self.devices:
            d.start()
        if pump_thread and self._thread is None:
            self._stop.clear()
            self._thread = threading.Thread(target=self._run, name="humananim-capture-pump", daemon=True)
            self._thread.start()
        return self

    def stop(self):
        """Stops the devices; a take being recorded is finished and kept."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(2.0)
            self._thread = None
        for d in self.devices:
            d.stop()
        self.pump()
        if self.recording:
            self.stop_recording()

    def _run(self):
        while not self._stop.wait(self.pump_interval):
            self.pump()

    def device(self, name):
        for d in self.devices:
            if d.name == name:
                return d
        raise KeyError(name)

    # -- the pump ---------------------------------------------------------------------------
    def pump(self):
        """Move every waiting sample into the newest-sample table (and the take). Returns how many."""
        with self._lock:
            n = 0
            for d in self.devices:
                for s in d.buffer.drain():
                    self.latest[(s.device, s.channel)] = s
                    if self.recording:
                        self.take.add(s)
                    if s.kind == "glove" and s.device in self.glove_calibrations:
                        self._gesture(s)
                    n += 1
            self.pumped += n
            return n

    def _gesture(self, s):
        angles = self.glove_calibrations[s.device].angles(s.data["raw"])
        command = self.gestures.update(s.time, angles)
        if command is None:
            return
        self.events.append((s.time, command))
        if command == "start_recording" and not self.recording:
            self.start_recording(self.take_name)
        elif command == "stop_recording" and self.recording:
            self.stop_recording()
        elif command == "recalibrate" and self.converter is not None:
            try:
                self.converter.calibrate(self.pose_readings(), self.calibration_pose)
            except Exception as exc:  # a sensor missing: say so, keep going
                self.events.append((s.time, f"calibration failed: {exc}"))

    # -- what the display step reads ----------------------------------------------------------
    def newest(self):
        with self._lock:
            return dict(self.latest)

    def pose_readings(self):
        """{(device, channel): (position, quaternion)} of the newest pose samples."""
        return {k: tracker_reading(s) for k, s in self.newest().items() if s.kind == "pose" and "quaternion" in s.data}

    # -- recording ------------------------------------------------------------------------
    def start_recording(self, name="take"):
        with self._lock:
            self.pump_unrecorded()
            self.take = Take(name)
            self.recording = True
            return self.take

    def pump_unrecorded(self):
        # samples that arrived before recording started don't belong to the take
        for d in self.devices:
            for s in d.buffer.drain():
                self.latest[(s.device, s.channel)] = s

    def stop_recording(self):
        with self._lock:
            self.pump()
            self.recording = False
            take = self.take
            if take is not None:
                take.stopped = time.perf_counter()
                self.takes.append(take)
            return take

    def status(self):
        return [d.status_dict() for d in self.devices]

    @property
    def dropped(self):
        return sum(d.dropped for d in self.devices)
