"""Real motion for the sequence tests, without bpy: a minimal BVH reader of the CMU clips and a
Skeleton + Trajectories built from it (bones along +Y as in Blender, BVH rotations carried over)."""

import functools
import os

import numpy as np

from humananim.solver import rotations
from humananim.solver.skeleton import Skeleton
from humananim.solver.trajectories import Trajectories

MOCAP = os.path.join(os.path.dirname(__file__), "..", "..", "..", "shared", "data", "mocap")
if not os.path.isdir(MOCAP):
    MOCAP = "/work/shared/data/mocap"
CLIPS = ("cmu_131_01.bvh", "cmu_131_03.bvh")


class Bvh:
    """names, parents, offsets (J, 3), channels [(joint, 'Xrotation'), ...], motion (F, C) in
    file units (degrees, metres), frame_time (s), end_sites {joint: offset}."""

    def __init__(self, path):
        with open(path) as f:
            header, motion = f.read().split("MOTION", 1)
        self.names, self.parents, self.offsets, self.channels = [], [], [], []
        self.end_sites = {}
        stack, in_end, pending_end = [], False, None
        tokens = header.split()
        k = 0
        while k < len(tokens):
            tok = tokens[k]
            if tok in ("ROOT", "JOINT"):
                self.names.append(tokens[k + 1])
                self.parents.append(stack[-1] if stack else -1)
                k += 2
                continue
            if tok == "End":
                pending_end = stack[-1]
                k += 2
                continue
            if tok == "{":
                if pending_end is not None:
                    in_end = True
                else:
                    stack.append(len(self.names) - 1)
            elif tok == "}":
                if in_end:
                    in_end, pending_end = False, None
                else:
                    stack.pop()
            elif tok == "OFFSET":
                off = [float(v) for v in tokens[k + 1:k + 4]]
                if in_end:
                    self.end_sites[pending_end] = np.array(off)
                else:
                    self.offsets.append(off)
                k += 4
                continue
            elif tok == "CHANNELS":
                n = int(tokens[k + 1])
                j = len(self.names) - 1
                self.channels += [(j, c) for c in tokens[k + 2:k + 2 + n]]
                k += 2 + n
                continue
            k += 1
        lines = motion.strip().splitlines()
        frames = int(lines[0].split(":")[1])
        self.frame_time = float(lines[1].split(":")[1])
        self.motion = np.array([line.split() for line in lines[2:2 + frames]], dtype=float)
        self.offsets = np.array(self.offsets)
        self.parents = np.array(self.parents)

    @property
    def fps(self):
        return 1.0 / self.frame_time

    def rotation_columns(self):
        """(J, 3) column of each joint's X, Y, Z rotation channel, and each joint's Euler order
        (Blender's naming: first axis applied first; BVH lists the outermost axis first)."""
        cols = np.full((len(self.names), 3), -1)
        order = [""] * len(self.names)
        for c, (j, name) in enumerate(self.channels):
            if name.endswith("rotation"):
                cols[j, "XYZ".index(name[0])] = c
                order[j] = name[0] + order[j]
        return cols, order

    def euler(self):
        """(F, J, 3) Euler angles in radians (x, y, z) and the per-joint orders."""
        cols, order = self.rotation_columns()
        return np.radians(self.motion[:, cols]), order

    def root_position(self):
        cols = [c for c, (j, name) in enumerate(self.channels) if j == 0 and name.endswith("position")]
        return self.motion[:, cols]


@functools.lru_cache(maxsize=None)
def load(name="cmu_131_01.bvh"):
    return Bvh(os.path.join(MOCAP, name))


def _rest_rotation(direction):
    """A rotation taking +Y onto `direction`."""
    y = np.array([0.0, 1.0, 0.0])
    d = direction / np.linalg.norm(direction)
    axis = np.cross(y, d)
    s, c = np.linalg.norm(axis), float(y @ d)
    if s < 1e-9:
        return np.array([1.0, 0.0, 0.0, 0.0]) if c > 0 else np.array([0.0, 0.0, 0.0, 1.0])
    angle = np.arctan2(s, c)
    return np.concatenate(([np.cos(angle / 2)], np.sin(angle / 2) * axis / s))


def skeleton_and_motion(name="cmu_131_01.bvh", frames=None):
    """A Skeleton (bones along +Y towards their first child or end site, Y up as in the file)
    and the clip as Trajectories; the pose bone basis is R_rest^-1 R_bvh R_rest."""
    bvh = load(name)
    J = len(bvh.names)
    heads = np.zeros((J, 3))
    for j in range(J):
        heads[j] = bvh.offsets[j] + (heads[bvh.parents[j]] if bvh.parents[j] >= 0 else 0.0)
    rest = np.tile(np.eye(4), (J, 1, 1))
    lengths = np.zeros(J)
    qrest = np.zeros((J, 4))
    for j in range(J):
        kids = np.flatnonzero(bvh.parents == j)
        tail = bvh.offsets[kids[0]] if len(kids) else bvh.end_sites.get(j, np.array([0.0, 0.05, 0.0]))
        if np.linalg.norm(tail) < 1e-6:
            tail = np.array([0.0, 0.05, 0.0])
        lengths[j] = np.linalg.norm(tail)
        qrest[j] = _rest_rotation(tail)
        rest[j, :3, :3] = rotations.to_matrix(qrest[j])
        rest[j, :3, 3] = heads[j]
    euler, orders = bvh.euler()
    sel = slice(None) if frames is None else frames
    euler = euler[sel]
    F = len(euler)
    q_bvh = np.stack([rotations.from_euler(euler[:, j], orders[j]) for j in range(J)], axis=1)
    basis_q = rotations.multiply(rotations.conjugate(qrest)[None], rotations.multiply(q_bvh, qrest[None]))
    trans = np.zeros((F, J, 3))
    root_pos = bvh.root_position()[sel] - heads[0]
    trans[:, 0] = rotations.rotate(rotations.conjugate(qrest[0]), root_pos)
    skeleton = Skeleton(
        names=bvh.names, parents=bvh.parents, rest=rest, lengths=lengths,
        connected=np.zeros(J, bool), dof=np.ones((J, 3), bool),
        limits=np.tile([-np.inf, np.inf], (J, 3, 1)), mass=np.ones(J), com=np.zeros((J, 3)),
        inertia=np.tile(np.eye(3) * 0.01, (J, 1, 1)))
    traj = Trajectories(np.arange(F, dtype=float), bvh.fps, rotations.make_continuous(basis_q),
                        trans, np.eye(4))
    return skeleton, traj
