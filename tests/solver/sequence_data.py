"""Real motion for the sequence tests, without bpy: the CMU clips read by solver.bvh, as the raw
channels Blender's importer keys (Euler angles, root position) and as a Skeleton + Trajectories."""

import functools
import os

import numpy as np

from humananim.solver import bvh as bvh_reader
from humananim.solver.trajectories import Trajectories

MOCAP = os.path.join(os.path.dirname(__file__), "..", "..", "..", "shared", "data", "mocap")
if not os.path.isdir(MOCAP):
    MOCAP = "/work/shared/data/mocap"
CLIPS = ("cmu_131_01.bvh", "cmu_131_03.bvh")


@functools.lru_cache(maxsize=None)
def load(name="cmu_131_01.bvh"):
    return bvh_reader.read(os.path.join(MOCAP, name))


def _columns(bvh):
    return [(j, c) for j, chans in enumerate(bvh.channels) for c in chans]


def euler(bvh):
    """(F, J, 3) the file's Euler angles in radians (x, y, z) and each joint's order (Blender's
    naming: first axis applied first; BVH lists the outermost axis first)."""
    cols = np.full((len(bvh.names), 3), -1)
    order = [""] * len(bvh.names)
    for c, (j, name) in enumerate(_columns(bvh)):
        if name.endswith("rotation"):
            cols[j, "XYZ".index(name[0])] = c
            order[j] = name[0] + order[j]
    return np.radians(bvh.values[:, cols]), order


def root_position(bvh):
    """(F, 3) the root's position channels as the file has them."""
    return bvh.values[:, [c for c, (j, name) in enumerate(_columns(bvh)) if j == 0 and name.endswith("position")]]


def skeleton_and_motion(name="cmu_131_01.bvh", frames=None):
    """The clip's Skeleton and its pose-bone bases as Trajectories on frames 0, 1, ... of the
    selected `frames` (a slice)."""
    bvh = load(name)
    skeleton = bvh_reader.skeleton(bvh)
    traj = bvh_reader.trajectories(bvh, skeleton)
    sel = slice(None) if frames is None else frames
    rot, trans = traj.rotations[sel], traj.translations[sel]
    return skeleton, Trajectories(np.arange(len(rot), dtype=float), traj.fps, rot, trans, np.eye(4))
