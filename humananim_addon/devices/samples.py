"""One timestamped reading of one device channel (a bird, a glove, a VMC bone set)."""

from dataclasses import dataclass, field


@dataclass
class Sample:
    """`time` is time.perf_counter() when the reader thread decoded it (monotonic, shared by
    every thread and process on the machine). `seq` counts the device's decoded samples.

    `kind` says what `data` holds:
    - 'pose': {'position': (3,) metres, 'quaternion': (4,) w,x,y,z} of a sensor in the
      tracker's frame, plus 'angles' (azimuth, elevation, roll in degrees) or 'matrix' when
      the device sent them;
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
