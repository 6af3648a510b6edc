"""Quaternions (w, x, y, z), Euler angles in Blender's orders, axis-angle; vectorised over leading axes."""

import numpy as np

EULER_ORDERS = ("XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX")
_AXIS = {"X": 0, "Y": 1, "Z": 2}


def normalize(q):
    q = np.asarray(q, dtype=float)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def multiply(a, b):
    """Hamilton product a*b (apply b, then a)."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack((
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    ), axis=-1)


def conjugate(q):
    q = np.array(q, dtype=float)
    q[..., 1:] *= -1.0
    return q


def to_matrix(q):
    """Unit quaternions (..., 4) to rotation matrices (..., 3, 3)."""
    w, x, y, z = np.moveaxis(normalize(q), -1, 0)
    return np.stack((
        np.stack((1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)), -1),
        np.stack((2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)), -1),
        np.stack((2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)), -1),
    ), axis=-2)


def from_matrix(m):
    """Rotation matrices (..., 3, 3) to unit quaternions with w >= 0 (Shepperd's method)."""
    m = np.asarray(m, dtype=float)
    shape = m.shape[:-2]
    m = m.reshape(-1, 3, 3)
    q = np.empty((len(m), 4))
    trace = np.trace(m, axis1=1, axis2=2)
    diag = np.diagonal(m, axis1=1, axis2=2)
    case = np.where(trace > diag.max(axis=1), 3, diag.argmax(axis=1))
    for c in range(4):
        sel = case == c
        if not sel.any():
            continue
        r = m[sel]
        if c == 3:
            s = 2.0 * np.sqrt(1.0 + trace[sel])
            q[sel] = np.stack((0.25 * s, (r[:, 2, 1] - r[:, 1, 2]) / s,
                               (r[:, 0, 2] - r[:, 2, 0]) / s, (r[:, 1, 0] - r[:, 0, 1]) / s), -1)
            continue
        i, j, k = c, (c + 1) % 3, (c + 2) % 3
        s = 2.0 * np.sqrt(np.maximum(1.0 + r[:, i, i] - r[:, j, j] - r[:, k, k], 1e-300))
        out = np.empty((len(r), 4))
        out[:, 0] = (r[:, k, j] - r[:, j, k]) / s
        out[:, 1 + i] = 0.25 * s
        out[:, 1 + j] = (r[:, j, i] + r[:, i, j]) / s
        out[:, 1 + k] = (r[:, k, i] + r[:, i, k]) / s
        q[sel] = out
    q = normalize(q)
    q *= np.where(q[:, :1] < 0.0, -1.0, 1.0)
    return q.reshape(shape + (4,))


def axis_rotation(axis_index, angle):
    """Quaternions for rotations by `angle` (...) about a coordinate axis."""
    angle = np.asarray(angle, dtype=float)
    q = np.zeros(angle.shape + (4,))
    q[..., 0] = np.cos(0.5 * angle)
    q[..., 1 + axis_index] = np.sin(0.5 * angle)
    return q


def from_euler(angles, order="XYZ"):
    """Blender Euler angles (..., 3) as (x, y, z) values; `order` names the first axis applied first."""
    angles = np.asarray(angles, dtype=float)
    q = None
    for axis in order:
        r = axis_rotation(_AXIS[axis], angles[..., _AXIS[axis]])
        q = r if q is None else multiply(r, q)
    return q


def to_euler(q, order="XYZ", previous=None):
    """Unit quaternions to Blender Euler angles; with `previous` (same shape), the equivalent
    triple closest to it is chosen so curves stay continuous (like Blender's compatible Euler)."""
    m = to_matrix(q)
    first, second, third = (_AXIS[a] for a in order)
    # R = R3 R2 R1; parity of the axis permutation fixes the signs
    sign = 1.0 if (second - first) % 3 == 1 else -1.0
    i, j, k = first, second, third
    sin_b = np.clip(-sign * m[..., k, i], -1.0, 1.0)
    b = np.arcsin(sin_b)
    regular = np.sqrt(np.maximum(1.0 - sin_b * sin_b, 0.0)) > 1e-6
    a = np.where(regular, np.arctan2(sign * m[..., k, j], m[..., k, k]),
                 np.arctan2(-sign * m[..., j, k], m[..., j, j]))  # gimbal lock: third angle 0
    c = np.where(regular, np.arctan2(sign * m[..., j, i], m[..., i, i]), 0.0)
    out = np.empty(m.shape[:-2] + (3,))
    out[..., first], out[..., second], out[..., third] = a, b, c
    if previous is not None:
        out = closest_euler(out, np.asarray(previous, dtype=float), order)
    return out


def closest_euler(angles, previous, order="XYZ"):
    """Of the two Euler triples for each rotation (each plus multiples of 2 pi), the one nearest `previous`."""
    first, second, third = (_AXIS[a] for a in order)
    alt = angles.copy()
    alt[..., first] += np.pi
    alt[..., second] = np.pi - angles[..., second]
    alt[..., third] += np.pi
    best = None
    best_dist = None
    for cand in (angles, alt):
        cand = previous + np.remainder(cand - previous + np.pi, 2.0 * np.pi) - np.pi
        dist = np.abs(cand - previous).sum(axis=-1)
        if best is None:
            best, best_dist = cand, dist
        else:
            take = dist < best_dist
            best = np.where(take[..., None], cand, best)
            best_dist = np.minimum(dist, best_dist)
    return best


def unroll_euler(angles, order="XYZ"):
    """Make a sampled Euler curve (F, ..., 3) continuous frame to frame."""
    out = np.array(angles, dtype=float)
    for f in range(1, len(out)):
        out[f] = closest_euler(out[f], out[f - 1], order)
    return out


def from_axis_angle(axis_angle):
    """Blender's axis-angle channels (..., 4) = (angle, x, y, z); a zero axis means no rotation."""
    aa = np.asarray(axis_angle, dtype=float)
    axis = aa[..., 1:]
    norm = np.linalg.norm(axis, axis=-1, keepdims=True)
    axis = np.divide(axis, norm, out=np.zeros_like(axis), where=norm > 0.0)
    half = np.where(norm > 0.0, 0.5 * aa[..., :1], 0.0)
    return np.concatenate((np.cos(half), np.sin(half) * axis), axis=-1)


def to_axis_angle(q):
    q = normalize(q)
    q = q * np.where(q[..., :1] < 0.0, -1.0, 1.0)
    s = np.linalg.norm(q[..., 1:], axis=-1, keepdims=True)
    angle = 2.0 * np.arctan2(s, q[..., :1])
    axis = np.divide(q[..., 1:], s, out=np.zeros_like(q[..., 1:]), where=s > 1e-12)
    axis[..., 1] = np.where(s[..., 0] > 1e-12, axis[..., 1], 1.0)  # Blender's default axis is +Y
    return np.concatenate((angle, axis), axis=-1)


def make_continuous(q, axis=0):
    """Flip quaternions along `axis` (time) onto the hemisphere of their predecessor."""
    q = np.array(q, dtype=float)
    q = np.moveaxis(q, axis, 0)
    for f in range(1, len(q)):
        dot = (q[f] * q[f - 1]).sum(axis=-1, keepdims=True)
        q[f] *= np.where(dot < 0.0, -1.0, 1.0)
    return np.moveaxis(q, 0, axis)


def rotate(q, v):
    """Rotate vectors v (..., 3) by quaternions q (..., 4)."""
    return np.einsum("...ij,...j->...i", to_matrix(q), v)


def angle_between(a, b):
    """Rotation angle (radians) taking quaternion a to b."""
    d = multiply(conjugate(normalize(a)), normalize(b))
    return 2.0 * np.arctan2(np.linalg.norm(d[..., 1:], axis=-1), np.abs(d[..., 0]))


def axis_angle_matrix(axis, angle):
    """Rotations (..., 3, 3) about unit axes (..., 3) by angles (...) (Rodrigues)."""
    axis = np.asarray(axis, float)
    angle = np.asarray(angle, float)[..., None, None]
    k = np.zeros(axis.shape[:-1] + (3, 3))
    k[..., 0, 1], k[..., 0, 2], k[..., 1, 2] = -axis[..., 2], axis[..., 1], -axis[..., 0]
    k[..., 1, 0], k[..., 2, 0], k[..., 2, 1] = axis[..., 2], -axis[..., 1], axis[..., 0]
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * (k @ k)


def rotation_between(a, b):
    """Smallest rotations (..., 3, 3) turning directions a onto b (..., 3)."""
    a = np.asarray(a, float) / np.linalg.norm(a, axis=-1, keepdims=True)
    b = np.asarray(b, float) / np.linalg.norm(b, axis=-1, keepdims=True)
    axis = np.cross(a, b)
    s = np.linalg.norm(axis, axis=-1)
    c = np.sum(a * b, axis=-1)
    safe = np.where(s[..., None] > 1e-12, axis / np.maximum(s, 1e-12)[..., None], [1.0, 0.0, 0.0])
    return axis_angle_matrix(safe, np.arctan2(s, c))
