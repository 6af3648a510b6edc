"""Small 3-D helpers of the control loop's per-step geometry (cross products, a point's motion on
a moving body, the rotation vector of a small rotation)."""

import math

import numpy as np

from ..vectors import cross as cross_rows


def cross3(a, b):
    """Cross product of two 3-sequences of floats (a list)."""
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def cross(a, b):
    """Cross products of 3-vectors or (k, 3) stacks (one pair of 3-vectors on plain floats)."""
    a = np.asarray(a, float)
    b = np.asarray(b, float)
    if a.shape == (3,) and b.shape == (3,):
        return np.array(cross3(a.tolist(), b.tolist()))
    return cross_rows(a, b)


def point_motion(w, vo, al, ao, x):
    """Velocity and acceleration (lists) of the world point x (3 floats) of a body of spatial
    velocity (w, vo) and acceleration (al, ao) at the origin: vo + w x x and ao + al x x + w x x'."""
    xd = [v + c for v, c in zip(vo, cross3(w, x))]
    xdd = [a + c + e for a, c, e in zip(ao, cross3(al, x), cross3(w, xd))]
    return xd, xdd


def rotation_log(rot):
    """Rotation vector (3,) of a rotation matrix (angle below pi: the legs' small corrections)."""
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = np.asarray(rot, float).tolist()
    w = [0.5 * (r21 - r12), 0.5 * (r02 - r20), 0.5 * (r10 - r01)]
    sin = math.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
    if sin >= 1e-12:
        scale = math.atan2(sin, 0.5 * (r00 + r11 + r22 - 1.0)) / sin
        w = [w[0] * scale, w[1] * scale, w[2] * scale]
    return np.array(w)
