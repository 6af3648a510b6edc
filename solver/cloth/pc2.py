"""PC2 point caches (read by Blender's Mesh Cache modifier): a 32-byte little-endian header
'POINTCACHE2\\0', version 1, point count, start frame, sample rate, sample count; then float32
x y z per point per sample."""

import struct

import numpy as np

MAGIC = b"POINTCACHE2\0"


def write_pc2(path, samples, start=0.0, rate=1.0):
    samples = np.ascontiguousarray(samples, dtype="<f4")
    if samples.ndim != 3 or samples.shape[2] != 3:
        raise ValueError("samples must be (samples, points, 3)")
    with open(path, "wb") as f:
        f.write(MAGIC + struct.pack("<iiffi", 1, samples.shape[1], float(start), float(rate), samples.shape[0]))
        f.write(samples.tobytes())


def read_pc2(path):
    """(samples (S, V, 3) float32, start frame, sample rate)."""
    with open(path, "rb") as f:
        head = f.read(32)
        if head[:12] != MAGIC:
            raise ValueError(f"{path} is not a PC2 file")
        version, points, start, rate, count = struct.unpack("<iiffi", head[12:])
        data = np.frombuffer(f.read(), dtype="<f4")
    return data.reshape(count, points, 3), start, rate
