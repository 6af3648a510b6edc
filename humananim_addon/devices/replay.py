"""A replay device for demos: a BVH file or a recorded take played back at its own rate,
looping, through the same ring buffer and session as a live device."""

import time

import numpy as np

from ...solver import bvh as bvh_io
from ...solver.units import bvh_rest_extent, guess_length_scale
from .device import Device, DeviceError


class ReplayDevice(Device):
    """`source`: a .bvh path or a session.Take; `rate`: a BVH's frames per second (default: the
    file's own; a take keeps its recorded timing); `speed` scales playback."""

    kind = "replay"

    def __init__(self, name, source, rate=None, loop=True, speed=1.0, **kw):
        super().__init__(name, **kw)
        self.loop, self.speed = loop, speed
        self._frames = self._load(source, rate)
        self._index = 0
        self._t0 = None
        self.finished = False

    def _load(self, source, rate):
        if isinstance(source, str):
            if not source.lower().endswith(".bvh"):
                raise DeviceError(f"replay plays a .bvh file or a recorded take, not '{source}'")
            try:
                with open(source) as f:
                    text = f.read()
            except OSError as exc:
                raise DeviceError(f"cannot read '{source}': {exc.strerror}") from None
            # the unit guessed as the BVH import does, so the replay fits the imported rig
            scale, _ = guess_length_scale(bvh_rest_extent(text))
            clip = bvh_io.parse(text, scale)
            roles = bvh_io.guess_roles(clip.names)
            by_name = {}
            for role, names in roles.bones.items():
                for k, n in enumerate(names):
                    by_name[n] = (role, k)
            fps = rate or clip.fps
            frames = []
            for f in range(clip.frame_count):
                bones = {n: (None, clip.rotations[f, j]) for j, n in enumerate(clip.names)}
                frames.append((f / fps, "skeleton", {"bones": bones, "root_position": clip.root_positions[f],
                                                     "root_bone": clip.names[int(np.flatnonzero(clip.parents < 0)[0])],
                                                     "roles": by_name, "frame": f}))
            self.period = clip.frame_count / fps
            return frames
        samples = source.merged()
        if not samples:
            raise DeviceError("the take is empty")
        # a take plays at its own timing (`speed` scales it); it loops after one mean interval
        t0 = samples[0].time
        gap = (samples[-1].time - t0) / max(1, len(samples) - 1)
        self.period = samples[-1].time - t0 + gap
        # the samples come back as their devices sent them (same device and channel names), so
        # the rig maps them as it mapped the live devices
        return [(s.time - t0, s.kind, dict(s.data, channel=s.channel, device=s.device)) for s in samples]

    def _open(self):
        self._t0 = time.perf_counter()
        self._index = 0

    def _read(self):
        if self.finished:
            time.sleep(0.01)
            return []
        now = time.perf_counter()
        elapsed = (now - self._t0) * self.speed
        out = []
        while True:
            loops, i = divmod(self._index, len(self._frames))
            if loops and not self.loop:
                self.finished = True
                break
            t, kind, data = self._frames[i]
            if t + loops * self.period > elapsed:
                break
            sample = self.make_sample(data.get("channel", "skeleton"), kind, data, now)
            sample.device = data.get("device", self.name)
            out.append(sample)
            self._index += 1
        if not out:
            loops, i = divmod(self._index, len(self._frames))
            wait = (self._frames[i][0] + loops * self.period - elapsed) / self.speed
            time.sleep(min(max(wait, 0.0), 0.01))
        return out
