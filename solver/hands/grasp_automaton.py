"""The interactive grasping automaton (Huang 1996 §4.7, fig. 4-26, after Rezzonico et al. 95):
the gloved hand's sphere sensors against the scene's objects decide between FREE_HAND,
GRASPING_IN_PROGRESS (something touches) and SECURE_GRASP (the thumb and an opposing finger or
the palm touch the same object: it then follows the hand). The hand posture is corrected so
fingers rest on the surface instead of sinking in: each penetrating finger's flexion is scaled
back (bisection) to where its deepest sensor just touches."""

import numpy as np

from .. import rotations
from ..body_roles import FINGERS, sided
from .sensors import contacts, sensor_centres

FREE_HAND, GRASPING_IN_PROGRESS, SECURE_GRASP = "FREE_HAND", "GRASPING_IN_PROGRESS", "SECURE_GRASP"
# the thesis's colour code: pale skin, blue, green; touching sensors lighter than the others
STATE_COLOURS = {FREE_HAND: (0.96, 0.80, 0.69, 1.0), GRASPING_IN_PROGRESS: (0.2, 0.35, 0.95, 1.0),
                 SECURE_GRASP: (0.15, 0.8, 0.25, 1.0)}
SENSOR_COLOURS = {False: (0.25, 0.25, 0.25, 1.0), True: (0.8, 0.8, 0.8, 1.0)}


class GraspAutomaton:
    def __init__(self, skeleton, sensors, side="R", tolerance=0.002, release_frames=3):
        self.skeleton, self.sensors, self.side = skeleton, list(sensors), side
        self.tolerance = tolerance
        self.release_frames = release_frames
        self.radii = np.array([s.radius for s in self.sensors])
        self.state = FREE_HAND
        self.object = None  # index of the grasped or touched object
        self.grip = None  # object frame in the hand frame at the moment of the secure grasp
        self.touching = np.zeros(len(self.sensors), bool)
        self._apart = 0
        self.hand = skeleton.role_index(sided("hand", side))
        self.rest_local = skeleton.rest_local
        self.chains = {f: [skeleton.index(n) for n in skeleton.roles.chain(sided(f, side))] for f in FINGERS}

    def _touch(self, world, shapes):
        centres = sensor_centres(self.sensors, world, self.skeleton)
        best, touch_any = None, np.zeros(len(self.sensors), bool)
        for i, shape in enumerate(shapes):
            t, _ = contacts(centres, self.radii, shape, self.tolerance)
            touch_any |= t
            if t.any() and (best is None or t.sum() > best[1].sum()):
                best = (i, t)
        return best, touch_any

    def _opposed(self, touch):
        fingers = {self.sensors[k].finger for k in np.flatnonzero(touch)}
        return "thumb" in fingers and bool(fingers & {"index", "middle", "ring", "pinky", "palm"})

    def correct_posture(self, basis, shapes, world_of):
        """Scale back the flexion of fingers whose sensors would sink into an object: each finger
        closes along the glove's posture until it first touches (scan, then bisection)."""
        basis = basis.copy()
        world = world_of(basis)
        rest_local = self.rest_local
        for finger, chain in self.chains.items():
            if not chain:
                continue
            idx = [k for k, s in enumerate(self.sensors) if s.joint in chain]
            glove = [rotations.from_matrix(basis[j, :3, :3]) for j in chain]
            glove = [q if q[0] >= 0 else -q for q in glove]
            base = world[self.skeleton.parents[chain[0]]]
            sensors = [self.sensors[k] for k in idx]
            radii = self.radii[idx]

            def pose(scale):
                frames, parent, rots = {}, base, []
                for n, j in enumerate(chain):
                    q = rotations.normalize(np.array([1.0, 0, 0, 0]) * (1 - scale) + glove[n] * scale)
                    r = rotations.to_matrix(q)
                    b = basis[j].copy()
                    b[:3, :3] = r
                    rots.append(r)
                    parent = frames[j] = parent @ rest_local[j] @ b
                return frames, rots

            def depth(scale):
                frames, _ = pose(scale)
                centres = np.array([frames[s.joint][:3, :3] @ np.array([0.0, s.along * self.skeleton.lengths[s.joint], 0])
                                    + frames[s.joint][:3, 3] for s in sensors])
                return max(float(np.max(radii - sh.distance(centres))) for sh in shapes)

            steps = 16
            hi = next((k / steps for k in range(0, steps + 1) if depth(k / steps) > self.tolerance), None)
            if hi is None or hi == 0.0:
                continue  # never touches, or inside even when straight (the hand is in the object)
            lo = hi - 1.0 / steps
            for _ in range(14):
                mid = 0.5 * (lo + hi)
                if depth(mid) > 0.0:
                    hi = mid
                else:
                    lo = mid
            for j, r in zip(chain, pose(lo)[1]):
                basis[j, :3, :3] = r
        return basis

    def update(self, basis, shapes, world_of):
        """One step: the glove's basis in, (corrected basis, grasped object index or None) out.
        `world_of(basis)` is the rig's forward kinematics (world joint frames)."""
        if self.state == SECURE_GRASP and self.object is not None:
            shapes = list(shapes)
        basis = self.correct_posture(basis, shapes, world_of) if shapes else basis
        world = world_of(basis)
        best, touch = self._touch(world, shapes)
        self.touching = touch
        if self.state == SECURE_GRASP:
            if best is not None and best[0] == self.object and self._opposed(best[1]):
                self._apart = 0
            else:
                self._apart += 1
                if self._apart >= self.release_frames:  # the hand opened: release
                    self.state = GRASPING_IN_PROGRESS if touch.any() else FREE_HAND
                    self.grip, self._apart = None, 0
                    self.object = best[0] if best is not None else None
        elif best is None:
            self.state, self.object = FREE_HAND, None
        elif self._opposed(best[1]):
            self.state, self.object = SECURE_GRASP, best[0]
            self.grip = np.linalg.inv(world[self.hand]) @ self.object_frame(shapes[best[0]])
        else:
            self.state, self.object = GRASPING_IN_PROGRESS, best[0]
        return basis, world

    @staticmethod
    def object_frame(shape):
        if hasattr(shape, "frame"):
            return np.array(shape.frame, float)
        m = np.eye(4)
        m[:3, 3] = shape.centre
        return m

    def object_pose(self, world):
        """The grasped object's world frame (it follows the hand), or None."""
        if self.state != SECURE_GRASP or self.grip is None:
            return None
        return world[self.hand] @ self.grip

    @property
    def colour(self):
        return STATE_COLOURS[self.state]
