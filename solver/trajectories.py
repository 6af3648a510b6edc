"""Dense per-frame motion of a skeleton: the floating base in the world, joints in their parents."""

from dataclasses import dataclass

import numpy as np

from . import rotations
from .errors import MotionError
from .skeleton import Skeleton, compose, decompose


@dataclass
class Trajectories:
    """Motion sampled at `frames` (Blender frame numbers, possibly fractional) at `fps`.

    `rotations` (F, J, 4) and `translations` (F, J, 3, metres) are every joint's local pose
    (Blender's pose-bone basis), the root's included. The root's world pose is derived through
    the skeleton's rest frame and `armature_to_world`, the armature object's rigid transform.
    """

    frames: np.ndarray
    fps: float
    rotations: np.ndarray
    translations: np.ndarray
    armature_to_world: np.ndarray

    def __post_init__(self):
        self.frames = np.asarray(self.frames, dtype=float)
        self.rotations = np.asarray(self.rotations, dtype=float)
        self.translations = np.asarray(self.translations, dtype=float)
        if not (np.isfinite(self.rotations).all() and np.isfinite(self.translations).all()):
            bad = np.flatnonzero(~(np.isfinite(self.rotations).all(axis=(1, 2))
                                   & np.isfinite(self.translations).all(axis=(1, 2))))
            raise MotionError(f"the motion has NaN or infinite values at frame {self.frames[bad[0]]:g}")

    @property
    def frame_count(self):
        return len(self.frames)

    @property
    def times(self):
        return (self.frames - self.frames[0]) / self.fps

    def basis(self):
        return compose(self.translations, self.rotations)

    def world_frames(self, skeleton: Skeleton):
        return skeleton.world_frames(self.basis(), self.armature_to_world)

    def root_pose(self, skeleton: Skeleton):
        """World position (F, 3) and orientation (F, 4) of the root joint's frame."""
        r = skeleton.root
        base = self.armature_to_world
        for a in reversed(skeleton.ancestors(r)):
            base = base @ skeleton.rest_local[a] @ self.basis()[:, a]
        return decompose(base @ skeleton.rest_local[r] @ self.basis()[:, r])

    def with_root_pose(self, skeleton: Skeleton, position, orientation):
        """A copy whose root joint has the given world pose; its ancestors keep their pose."""
        r = skeleton.root
        base = np.broadcast_to(self.armature_to_world, (self.frame_count, 4, 4))
        for a in reversed(skeleton.ancestors(r)):
            base = base @ skeleton.rest_local[a] @ self.basis()[:, a]
        basis = np.linalg.solve(base @ skeleton.rest_local[r], compose(position, orientation))
        t, q = decompose(basis)
        trans, rot = self.translations.copy(), self.rotations.copy()
        trans[:, r], rot[:, r] = t, rotations.make_continuous(q)
        return Trajectories(self.frames, self.fps, rot, trans, self.armature_to_world)
