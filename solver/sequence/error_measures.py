"""Errors an animator can read: degrees, centimetres, and how far any bone's tail moved.

tail_error compares two motions of the same Skeleton through forward kinematics
(Trajectories.world_frames): for every frame and bone it measures how far the bone's tail
(head + length along the bone's Y) and a point `beyond` metres further along the bone moved,
and returns the largest of each, with where it happened. A point past the tail magnifies
rotation errors of short bones (hands, feet, head) the way a held prop or a long limb would.
"""

from dataclasses import dataclass

import numpy as np

from .. import rotations
from ..skeleton import Skeleton
from ..trajectories import Trajectories


def rotation_error_deg(qa, qb):
    """Angle in degrees between quaternions (..., 4) (sign-invariant)."""
    return np.degrees(rotations.angle_between(qa, qb))


def angle_error_deg(a, b):
    """Difference of angles in radians as degrees, wrapped to [0, 180]."""
    d = np.remainder(np.asarray(a, float) - np.asarray(b, float) + np.pi, 2.0 * np.pi) - np.pi
    return np.degrees(np.abs(d))


def euler_error_deg(ea, eb, order="XYZ"):
    """Angle in degrees between the rotations of two Euler triples (..., 3) in radians."""
    return rotation_error_deg(rotations.from_euler(ea, order), rotations.from_euler(eb, order))


def location_error_cm(a, b):
    """Distance in centimetres between positions (..., 3) in metres (or |a - b| for scalars)."""
    d = np.asarray(a, float) - np.asarray(b, float)
    return 100.0 * (np.linalg.norm(d, axis=-1) if d.ndim and d.shape[-1] == 3 else np.abs(d))


def channel_errors(a, b, kinds):
    """Largest error of each channel (C,) between (F, C) arrays: degrees for 'rotation' channels
    (radians), centimetres for 'location' channels (metres)."""
    d = np.abs(np.asarray(a, float) - np.asarray(b, float)).max(axis=0)
    kinds = np.asarray(kinds)
    return np.where(kinds == "rotation", np.degrees(d), 100.0 * d)


@dataclass
class TailError:
    """Largest distances (metres) of the bone tails and of the points `beyond` past them."""

    tail: float
    point: float
    tail_bone: str
    tail_frame: int
    point_bone: str
    point_frame: int
    beyond: float

    @property
    def tail_cm(self):
        return 100.0 * self.tail

    @property
    def point_cm(self):
        return 100.0 * self.point


def bone_points(skeleton: Skeleton, traj: Trajectories, beyond=0.10):
    """World positions (F, J, 3) of every bone's tail and of the point `beyond` metres past it."""
    world = traj.world_frames(skeleton)
    y = world[..., :3, 1]
    head = world[..., :3, 3]
    tail = head + y * skeleton.lengths[:, None]
    return tail, tail + y * beyond


def tail_error(skeleton: Skeleton, a: Trajectories, b: Trajectories, beyond=0.10):
    """The largest tail and tail-plus-`beyond` position errors between two motions (same frames)."""
    if a.frame_count != b.frame_count:
        raise ValueError("the two motions must have the same frames")
    ta, pa = bone_points(skeleton, a, beyond)
    tb, pb = bone_points(skeleton, b, beyond)
    dt = np.linalg.norm(ta - tb, axis=-1)
    dp = np.linalg.norm(pa - pb, axis=-1)
    ft, jt = np.unravel_index(np.argmax(dt), dt.shape)
    fp, jp = np.unravel_index(np.argmax(dp), dp.shape)
    return TailError(float(dt[ft, jt]), float(dp[fp, jp]), skeleton.names[jt], int(ft),
                     skeleton.names[jp], int(fp), beyond)
