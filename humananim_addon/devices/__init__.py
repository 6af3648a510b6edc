"""Live capture without bpy (issue 10): device drivers and their simulators, the reader threads,
the ring buffer, the session that records takes, calibration, glove gestures and grasping.

Serial devices need pyserial and the HID glove needs hidapi; both are imported only when a
device is opened, so the rest of this package runs on numpy alone."""

from .samples import Sample
from .ringbuffer import RingBuffer

__all__ = ["RingBuffer", "Sample"]
