"""One timestamped reading of one device channel (a bird, a glove, an MVN segment, a VMC bone
set), and the one place where a pose reading becomes the anatomical converter's input."""

from dataclasses import dataclass, field

import numpy as np


@dataclass
class Sample:
    """`time` is time.perf_counter() when the reader thread decoded it (monotonic, shared by
    every thread and process on the machine). `seq` counts the device's decoded samples.

    `kind` says what `data` holds:
    - 'pose': {'position': (3,) metres, 'quaternion': (4,) w,x,y,z} of a sensor in the
      tracker's frame, plus 'angles' (azimuth, elevation, roll in degrees) or 'matrix' when
      the device sent them; 'frame': 'z_up' when that frame is Z-up (Xsens MVN), else the
      Ascension transmitter frame (X forward, Y right, Z down);
    - 'glove': {'raw': (n,) sensor values as the device counts them};
    - 'skeleton': {'bones': {name: (position, quaternion)}, 'root': (position, quaternion)
      or None, 'blendshapes': {name: value}} (VMC, replay).
    """

    device: str
    channel: str
    seq: int
    time: float
    kind: str
    data: dict = field(default_factory=dict)


# a half turn about X: a Z-up reading (X forward, Y left) in the Z-down tracker frame
_HALF_TURN_X = np.array([0.0, 1.0, 0.0, 0.0])
_FLIP = np.array([1.0, -1.0, -1.0])


def tracker_reading(sample):
    """(position, quaternion) of a pose sample in the anatomical converter's tracker frame
    (the Ascension transmitter frame, X forward, Y right, Z down): a Z-up reading is turned
    half a turn about X, so every device calibrates and solves through one converter."""
    d = sample.data
    pos = np.asarray(d["position"], float) if "position" in d else np.zeros(3)
    q = np.asarray(d["quaternion"], float)
    if d.get("frame") == "z_up":
        w, x, y, z = q
        return pos * _FLIP, np.array([-x, w, -z, y])  # (0, 1, 0, 0) * q
    return pos, q
