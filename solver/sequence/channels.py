"""Joint rotations and locations as plain channels that can be filtered, blended and keyed, and back.

Quaternions are filtered in the tangent space: each joint's rotation is written as a rotation
vector v (radians, 3 channels) about a fixed reference r (by default the joint's chordal mean over
the clip), q = r exp(v). The vectors are unrolled over time (the equivalent vector of length
|v| + 2 pi k closest to the previous frame), so a joint that turns past 180 degrees from the
reference stays continuous. Any curve of vectors maps back to unit quaternions (exp, then the
product renormalised against rounding), and the result is put on the hemisphere of the input's
first frame; exp of a continuous vector curve is itself continuous, so every frame stays on the
same hemisphere as its neighbour. Rotation vectors are locally Euclidean: two vectors whose
components differ by at most e are at most sqrt(3) e radians apart as rotations.

Euler channels are unrolled (rotations.unroll_euler) before filtering; locations are used as they are.
"""

from dataclasses import dataclass

import numpy as np

from .. import rotations
from ..trajectories import Trajectories


def mean_quaternion(q, axis=0):
    """Chordal L2 mean of unit quaternions along `axis` (sign-invariant), on the hemisphere of the first."""
    q = np.moveaxis(np.asarray(q, dtype=float), axis, 0)
    m = np.einsum("f...i,f...j->...ij", q, q)
    _, vecs = np.linalg.eigh(m)
    mean = vecs[..., :, -1]
    return mean * np.where((mean * q[0]).sum(-1, keepdims=True) < 0.0, -1.0, 1.0)


def log_map(q):
    """Rotation vectors (..., 3) of unit quaternions (..., 4), |v| <= pi (the w >= 0 representative)."""
    q = rotations.normalize(q)
    q = q * np.where(q[..., :1] < 0.0, -1.0, 1.0)
    s = np.linalg.norm(q[..., 1:], axis=-1, keepdims=True)
    angle = 2.0 * np.arctan2(s, q[..., :1])
    scale = np.divide(angle, s, out=np.full_like(s, 2.0), where=s > 1e-12)
    return q[..., 1:] * scale


def exp_map(v):
    """Unit quaternions (..., 4) of rotation vectors (..., 3); |v| > pi gives w < 0 (continuity kept)."""
    v = np.asarray(v, dtype=float)
    angle = np.linalg.norm(v, axis=-1, keepdims=True)
    half = 0.5 * angle
    sinc = np.where(angle > 1e-12, np.sin(half) / np.where(angle > 1e-12, angle, 1.0), 0.5)
    return np.concatenate((np.cos(half), v * sinc), axis=-1)


def unroll_rotation_vectors(v):
    """Along axis 0, replace each rotation vector by its equivalent (|v| + 2 pi k) v/|v| nearest the
    previous frame's, so the curve has no jump where a rotation passes 180 degrees."""
    v = np.array(v, dtype=float)
    for f in range(1, len(v)):
        norm = np.linalg.norm(v[f], axis=-1, keepdims=True)
        prev = np.linalg.norm(v[f - 1], axis=-1, keepdims=True)
        # a zero vector (identity) takes its direction from the previous frame
        u = np.where(norm > 1e-12, v[f] / np.where(norm > 1e-12, norm, 1.0),
                     v[f - 1] / np.where(prev > 1e-12, prev, 1.0))
        along = (u * v[f - 1]).sum(-1, keepdims=True)
        k = np.round((along - norm) / (2.0 * np.pi))
        v[f] = (norm + 2.0 * np.pi * k) * u
    return v


def to_tangent(q, reference=None):
    """Rotation vectors v (F, ..., 3) with q = reference exp(v); reference (..., 4), default the mean."""
    q = np.asarray(q, dtype=float)
    reference = mean_quaternion(q) if reference is None else np.asarray(reference, dtype=float)
    d = rotations.multiply(rotations.conjugate(reference), q)
    return unroll_rotation_vectors(log_map(d))


def from_tangent(v, reference, like=None):
    """Unit quaternions reference exp(v), renormalised; with `like` (F', ..., 4), each channel is
    flipped as a whole onto the hemisphere of like[0] (continuity is kept by exp)."""
    q = rotations.normalize(rotations.multiply(np.asarray(reference, dtype=float), exp_map(v)))
    if like is not None:
        dot = (q[0] * np.asarray(like, dtype=float)[0]).sum(-1, keepdims=True)
        q = q * np.where(dot < 0.0, -1.0, 1.0)
    return q


def filter_quaternions(q, fn, reference=None):
    """Apply `fn` ((F, C) -> (F', C)) to quaternion curves q (F, ..., 4) through the tangent space."""
    q = rotations.make_continuous(q)
    reference = mean_quaternion(q) if reference is None else reference
    v = to_tangent(q, reference)
    out = np.asarray(fn(v.reshape(len(v), -1)))
    return from_tangent(out.reshape((len(out),) + v.shape[1:]), reference, like=q)


def unroll_euler(angles, orders="XYZ"):
    """Continuous Euler curves (F, J, 3) (radians); `orders` is one order or one per joint."""
    angles = np.asarray(angles, dtype=float)
    if isinstance(orders, str):
        return rotations.unroll_euler(angles, orders)
    out = np.empty_like(angles)
    for j, order in enumerate(orders):
        out[:, j] = rotations.unroll_euler(angles[:, j], order)
    return out


def filter_euler(angles, fn, orders="XYZ"):
    """Apply `fn` ((F, C) -> (F', C)) to Euler curves (F, J, 3) after unrolling them."""
    a = unroll_euler(angles, orders)
    out = np.asarray(fn(a.reshape(len(a), -1)))
    return out.reshape((len(out),) + a.shape[1:])


@dataclass
class ChannelLayout:
    """How a Trajectories was packed: per joint 3 rotation-vector channels (radians) about
    `reference` (J, 4), then 3 location channels (metres)."""

    reference: np.ndarray
    like: np.ndarray  # (J, 4) the first frame's quaternions, for the hemisphere

    @property
    def joint_count(self):
        return len(self.reference)

    @property
    def kinds(self):
        """'rotation' or 'location' for each of the 6 J channels."""
        return np.array((["rotation"] * 3 + ["location"] * 3) * self.joint_count)


def pack(traj: Trajectories, reference=None):
    """(F, 6 J) channels of a Trajectories and their layout."""
    q = rotations.make_continuous(traj.rotations)
    reference = mean_quaternion(q) if reference is None else np.asarray(reference, dtype=float)
    v = to_tangent(q, reference)
    channels = np.concatenate((v, traj.translations), axis=-1).reshape(len(v), -1)
    return channels, ChannelLayout(reference, q[0].copy())


def unpack(channels, layout: ChannelLayout, like: Trajectories, frames=None):
    """A Trajectories from (F', 6 J) channels; `frames` default like.frames (F' must match then)."""
    c = np.asarray(channels, dtype=float).reshape(len(channels), layout.joint_count, 6)
    q = from_tangent(c[..., :3], layout.reference, like=layout.like[None])
    frames = like.frames if frames is None else frames
    return Trajectories(frames, like.fps, q, c[..., 3:].copy(), like.armature_to_world)


def channel_tolerances(kinds, degrees=1.0, centimetres=1.0, angle_unit="radians", per_joint=False):
    """Per-channel tolerances in channel units from an animator's degrees and centimetres.
    `angle_unit` is 'radians' or 'degrees' for rotation channels; locations are in metres.
    per_joint=True divides by sqrt(3) so a whole joint (3 channels) stays within the figure."""
    kinds = np.asarray(kinds)
    rot = np.radians(degrees) if angle_unit == "radians" else float(degrees)
    tol = np.where(kinds == "rotation", rot, 0.01 * centimetres)
    return tol / np.sqrt(3.0) if per_joint else tol
