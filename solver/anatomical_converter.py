"""The anatomical converter (Molet et al. 96, Huang 1996 §6.4.1): 6-D sensors strapped on body
segments to joint rotations of the rig's hierarchy, after a one-pose calibration.

Calibration: the performer stands in the rig's calibration pose (its rest pose unless told
otherwise). For every sensor s on bone b the constant sensor-to-segment rotation
O_s = (T S_s)^-1 B_b is solved, with S_s the sensor's orientation in the tracker frame, T the
tracker-to-world rotation and B_b the bone's world orientation in that pose; the root sensor
also fixes where the tracker's origin lies in the world, and every other sensor gets its
offset to its bone's head in its own frame.

Live: a bone with a sensor turns to T S_s(t) O_s; the bones without a sensor between it and the
next sensor above share its turn (a spine bends along its length, not at one joint); when an arm
or leg has a sensor only at its end (hand or foot), two-bone IK turns the upper and lower limb so
the end reaches the sensor's position; other bones keep their calibration-pose rotation.
Positions of other bones come from the rig's own bone lengths (the converter outputs joint
rotations, so the motion fits any character of the same proportions)."""

import numpy as np

from . import rotations
from .body_roles import SIDES, sided
from .errors import HumanAnimError
from .vectors import cross

# Ascension transmitter frame (X forward, Y right, Z down) to Z-up world: a half turn about X
TRACKER_Z_DOWN = np.diag([1.0, -1.0, -1.0])
LIMBS = (("upper_arm", "forearm", "hand"), ("thigh", "shin", "foot"))


class CalibrationError(HumanAnimError):
    pass


def _rot(q):
    return rotations.to_matrix(np.asarray(q, float))


def _swing(a, b):
    """The smallest rotation matrix taking direction a to direction b."""
    a, b = a / np.linalg.norm(a), b / np.linalg.norm(b)
    v, c = cross(a, b), float(np.dot(a, b))
    s = np.linalg.norm(v)
    if s < 1e-12:
        if c > 0:
            return np.eye(3)
        perp = cross(a, [1.0, 0, 0] if abs(a[0]) < 0.9 else [0, 1.0, 0])
        perp /= np.linalg.norm(perp)
        return 2 * np.outer(perp, perp) - np.eye(3)
    k = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + k + k @ k * ((1 - c) / s ** 2)


def root_of_rotation(r, n):
    """The n-th roots of rotation matrices r (k, 3, 3): the rotations about the same axes by 1/n of
    the angles (0 to 180 degrees), through the rotations' quaternions (half angle and axis)."""
    q = rotations.from_matrix(r)
    sin_half = np.linalg.norm(q[:, 1:], axis=1)
    half = np.arctan2(sin_half, q[:, 0]) / n
    axis = np.divide(q[:, 1:], sin_half[:, None], out=np.zeros((len(r), 3)), where=sin_half[:, None] > 1e-12)
    return rotations.to_matrix(np.column_stack((np.cos(half), axis * np.sin(half)[:, None])))


class _Heard:
    """A set of sensors heard and what the solve needs of it that stays the same from one pose to
    the next: the sensors (a bone with two takes the last one's reading, as a dict of targets
    would), their bones, their calibration offsets stacked, and the bones without a sensor by
    level below the sensor bones (each level's parents are sensor bones or in a level above)."""

    def __init__(self, conv, keys):
        last = {conv.attachments[k]: k for k in keys}
        self.keys = tuple(k for k in keys if last[conv.attachments[k]] == k)
        self.bones = [conv.attachments[k] for k in self.keys]
        self.joints = np.array(self.bones, int)
        self.offsets = np.array([conv.offsets[k] for k in self.keys])
        self.head_offsets = np.array([conv.head_offsets[k] for k in self.keys])
        parents, depth = conv.skeleton.parents, {}
        for j in range(len(parents)):  # parents before children
            if j not in last:
                p = parents[j]
                depth[j] = depth[p] + 1 if p in depth else 0
        self.levels = [np.array([j for j, d in depth.items() if d == level], int)
                       for level in range(max(depth.values(), default=-1) + 1)]
        # the chains whose sensor bone is heard (conv._chain_ends' order), with the rows of `rot`
        # (_targets) of their sensor bones and of the sensor bones above them (None: one is silent)
        row = {j: i for i, j in enumerate(self.bones)}
        self.chains = [k for k, j in enumerate(conv._chain_ends) if j in row]
        self.chain_ends = [conv._chain_ends[k] for k in self.chains]
        self.chain_uppers = [parents[conv._chains[j][0]] for j in self.chain_ends]
        self.chain_end_rows = [row[j] for j in self.chain_ends]
        heard_above = all(a in row for a in self.chain_uppers)
        self.chain_upper_rows = [row[a] for a in self.chain_uppers] if heard_above else None
        self.chain_lengths = np.array([len(conv._chains[j]) + 1 for j in self.chain_ends])


class AnatomicalConverter:
    """`attachments` maps a sensor key (device, channel) to the bone it is strapped on;
    `root`: the key of the sensor on the root bone (its position moves the whole body)."""

    def __init__(self, skeleton, attachments, tracker_rotation=TRACKER_Z_DOWN, root=None):
        self.skeleton = skeleton
        self.attachments = {k: skeleton.index(b) if isinstance(b, str) else int(b) for k, b in attachments.items()}
        self.tracker = np.asarray(tracker_rotation, float)
        self.root = root
        if root is not None and root not in self.attachments:
            raise CalibrationError(f"the root sensor {root} is not attached to a bone")
        self.offsets = {}
        self.head_offsets = {}
        self.origin = np.zeros(3)
        self.calib_basis = None
        self.calibrated = False
        self.rest_local = skeleton.rest_local  # a property that solves: once, not per pose
        self._descendants = {j: skeleton.descendants(j) for j in range(skeleton.joint_count)}
        self._heard_sets = {}  # per set of sensors heard (see _heard)
        self._rest_rot = np.ascontiguousarray(self.rest_local[:, :3, :3])
        # a joint's parent, or for a root the row after the last joint (an identity in _from_targets)
        self._parent_or_identity = np.where(skeleton.parents < 0, skeleton.joint_count, skeleton.parents)
        self._limbs = self._ik_limbs()
        self._chains = self._sensorless_chains()
        # the bone whose sensor places the body (the root sensor on the root bone), else None
        on_root = root is not None and self.attachments[root] == skeleton.root
        self._placed = self.attachments[root] if on_root else None

    def _ik_limbs(self):
        sk, attached = self.skeleton, set(self.attachments.values())
        out = []
        for side in SIDES:
            for upper, lower, end in LIMBS:
                js = [sk.role_index(sided(r, side)) for r in (upper, lower, end)]
                if None in js or js[2] not in attached or js[0] in attached or js[1] in attached:
                    continue
                if sk.parents[js[1]] != js[0] or sk.parents[js[2]] != js[1]:
                    continue
                out.append(tuple(js))
        return out

    def calibrate(self, readings, pose_basis=None):
        """readings: {key: (position (3,), quaternion (4,))} in the tracker frame, taken while the
        performer holds the calibration pose; pose_basis (J, 4, 4): that pose on the rig."""
        sk = self.skeleton
        missing = [k for k in self.attachments if k not in readings]
        if missing:
            raise CalibrationError(f"no reading from {', '.join(map(str, missing))} to calibrate")
        basis = np.tile(np.eye(4), (sk.joint_count, 1, 1)) if pose_basis is None else np.asarray(pose_basis, float)
        world = sk.world_frames(basis)
        if self.root is not None:
            pos, _ = readings[self.root]
            self.origin = world[self.attachments[self.root], :3, 3] - self.tracker @ np.asarray(pos, float)
        for key, j in self.attachments.items():
            pos, quat = readings[key]
            s_world = self.tracker @ _rot(quat)
            self.offsets[key] = s_world.T @ world[j, :3, :3]
            self.head_offsets[key] = s_world.T @ (world[j, :3, 3] - self.sensor_position(pos))
        self.calib_basis = basis.copy()
        # a chain's sensor bone with the chain in the calibration pose, relative to the sensor bone
        # above the chain (whose world rotation is its target: no pass over the rig needed for it)
        self._chain_ends = list(self._chains)
        self._chain_calib = np.array([self._calibration_below(self._chains[j] + [j]) for j in self._chain_ends])
        self._heard_sets = {}  # their offsets have changed
        self.calibrated = True

    def sensor_position(self, pos):
        return self.tracker @ np.asarray(pos, float) + self.origin

    def bone_targets(self, readings):
        """{joint: (world rotation, world head position)} for the bones whose sensor has a reading
        (all sensors at once: a suit streams twenty of them every frame)."""
        heard, rot, head = self._targets(readings)
        return {} if rot is None else dict(zip(heard.bones, zip(rot, head)))

    def _targets(self, readings):
        """(the sensors heard, their bones' world rotations (n, 3, 3), head positions (n, 3))."""
        heard = self._heard(readings)
        if not heard.keys:
            return heard, None, None
        pos = np.array([readings[k][0] for k in heard.keys], float)
        s_world = self.tracker @ rotations.to_matrix(np.array([readings[k][1] for k in heard.keys], float))
        rot = s_world @ heard.offsets
        head = pos @ self.tracker.T + self.origin + np.einsum("nij,nj->ni", s_world, heard.head_offsets)
        return heard, rot, head

    def _heard(self, readings):
        """What stays the same while the same sensors are heard (until the next calibration): built
        once per set of sensors, not per pose."""
        keys = tuple(k for k in self.attachments if k in readings)
        sets = self._heard_sets  # a recalibration (a glove gesture, in the pump thread) starts a new table
        if keys not in sets:
            sets[keys] = _Heard(self, keys)
        return sets[keys]

    def solve(self, readings):
        """Local pose bases (J, 4, 4) of the rig for the newest readings."""
        if not self.calibrated:
            raise CalibrationError("calibrate first: stand in the calibration pose and press Calibrate")
        heard, rot, head = self._targets(readings)
        targets = {} if rot is None else dict(zip(heard.bones, zip(rot, head)))
        turns = self._chain_turns(heard, rot)
        if targets and turns is not None and not any(end in targets for _, _, end in self._limbs):
            return self._from_targets(heard, rot, targets, turns)
        return self._by_forward_pass(heard, rot, targets, turns)

    def _by_forward_pass(self, heard, rot, targets, turns):
        """The pose by a pass down the hierarchy with world frames (positions too): what two-bone
        IK needs, and a chain whose upper sensor bone has no reading yet."""
        basis = self.calib_basis.copy()
        if turns is None:  # a sensor above a chain has no reading yet: its bone is where a first pass puts it
            turns = self._chain_turns(heard, rot, self._forward(basis, targets))
        world = self._forward(basis, targets, turns)
        for upper, lower, end in self._limbs:
            if end not in targets:
                continue  # that sensor has not spoken yet
            self._two_bone_ik(basis, world, upper, lower, end, targets[end])
        return basis

    def _from_targets(self, heard, rot, targets, turns):
        """The pose when no limb needs IK (a suit with a sensor on every segment): a sensor bone's
        world rotation is its target, so its local rotation needs only its parent's world rotation,
        all sensor bones at once. The bones without a reading (fingers, toes, a spine's chain bones
        with their share of the turn) go down from the sensor bones level by level, each level at
        once. No positions: without IK only the root sensor's bone leaves the rig's bone lengths."""
        rest_rot, up = self._rest_rot, self._parent_or_identity
        basis = self.calib_basis.copy()
        world_rot = np.empty((len(up) + 1, 3, 3))
        world_rot[-1] = np.eye(3)  # what a root's frame stands on
        world_rot[heard.joints] = rot
        for level in heard.levels:  # a bone's frame: its parent's world rotation on its rest offset
            frame = world_rot[up[level]] @ rest_rot[level]
            world_rot[level] = frame @ basis[level, :3, :3]
            turned = [i for i, j in enumerate(level) if j in turns]
            if turned:
                bones = level[turned]
                world_rot[bones] = np.array([turns[j] for j in bones]) @ world_rot[bones]
                basis[bones, :3, :3] = np.swapaxes(frame[turned], 1, 2) @ world_rot[bones]
        frame = world_rot[up[heard.joints]] @ rest_rot[heard.joints]
        basis[heard.joints, :3, :3] = np.swapaxes(frame, 1, 2) @ rot
        if self._placed in targets:  # the root bone: its frame is its rest frame
            r = self._placed
            basis[r, :3, 3] = rest_rot[r].T @ (targets[r][1] - self.rest_local[r, :3, 3])
        return basis

    def _forward(self, basis, targets, turns=None):
        """World frames top-down, `basis` updated on the way: a bone with a target takes its
        rotation (the root sensor's bone its position too); a bone with a turn (its share of a
        chain's turn, in the world) takes it on top of the bones above it."""
        sk, rest_local = self.skeleton, self.rest_local
        world = np.empty((sk.joint_count, 4, 4))
        for j, p in enumerate(sk.parents):
            frame = rest_local[j] if p < 0 else world[p] @ rest_local[j]
            if turns is not None and j in turns:
                basis[j, :3, :3] = frame[:3, :3].T @ turns[j] @ frame[:3, :3] @ basis[j, :3, :3]
            if j in targets:
                rot, head = targets[j]
                basis[j, :3, :3] = frame[:3, :3].T @ rot
                if j == self._placed:
                    basis[j, :3, 3] = frame[:3, :3].T @ (head - frame[:3, 3])
            world[j] = frame @ basis[j]
        return world

    def _calibration_below(self, path):
        """The rotation from the frame of the bone above `path` to its last bone's frame, the
        bones of `path` in the calibration pose."""
        out = np.eye(3)
        for b in path:
            out = out @ self.rest_local[b, :3, :3] @ self.calib_basis[b, :3, :3]
        return out

    def _chain_turns(self, heard, rot, world=None):
        """{bone: world rotation}: every sensor bone's turn relative to its calibration pose
        (the chain above it in the calibration pose below the sensor bone above the chain, as
        its target `rot` or `world` has it), shared evenly by the bones without sensors between
        the two (their joints bend together, like a spine), so it is not all taken at one joint:
        each of the n bones of a chain with its sensor bone turns by the n-th root of the turn
        (same axis, 1/n of the angle). All chains at once: an MVN suit has several. None when
        a sensor above a chain has no reading and no `world` is given."""
        if not heard.chains:
            return {}
        if world is not None:
            upper = world[heard.chain_uppers, :3, :3]
        elif heard.chain_upper_rows is None:
            return None
        else:
            upper = rot[heard.chain_upper_rows]
        calib = upper @ self._chain_calib[heard.chains]
        turn = rot[heard.chain_end_rows] @ np.swapaxes(calib, 1, 2)
        shares = root_of_rotation(turn, heard.chain_lengths)
        turns = {}
        for j, share in zip(heard.chain_ends, shares):
            for b in self._chains[j]:  # a bone in two chains (a branch point) takes both turns
                turns[b] = share @ turns[b] if b in turns else share
        return turns

    def _sensorless_chains(self):
        """{sensor bone: the bones without sensor between it and the nearest sensor bone above}
        (top-down), for bones whose limb the IK does not already fill (e.g. the spine between
        the pelvis and the chest)."""
        sk, attached = self.skeleton, set(self.attachments.values())
        ik_ends = {end for _, _, end in self._limbs}
        out = {}
        for j in attached - ik_ends:
            path, a = [], sk.parents[j]
            while a >= 0 and a not in attached:
                path.append(a)
                a = sk.parents[a]
            if path and a >= 0:
                out[j] = path[::-1]
        return out

    def _two_bone_ik(self, basis, world, upper, lower, end, target):
        sk, rest_local = self.skeleton, self.rest_local
        a, b, c = world[upper, :3, 3], world[lower, :3, 3], world[end, :3, 3]
        goal = target[1]
        l1, l2 = np.linalg.norm(b - a), np.linalg.norm(c - b)
        d_vec = goal - a
        d = np.clip(np.linalg.norm(d_vec), abs(l1 - l2) + 1e-6, l1 + l2 - 1e-6)
        u = d_vec / max(np.linalg.norm(d_vec), 1e-9)
        bend = cross(b - a, c - b)
        n = bend / np.linalg.norm(bend) if np.linalg.norm(bend) > 1e-6 * l1 * l2 else world[upper, :3, 0]
        side = cross(n, u)
        side /= max(np.linalg.norm(side), 1e-9)
        cos_a = np.clip((l1 ** 2 + d ** 2 - l2 ** 2) / (2 * l1 * d), -1, 1)
        elbow = a + l1 * (cos_a * u + np.sqrt(1 - cos_a ** 2) * side)
        wrist = a + d * u
        # turn the upper limb, then the lower one, by the smallest rotations (keeps their twist)
        for j, new_tail in ((upper, elbow), (lower, wrist)):
            frame = world[sk.parents[j]] @ rest_local[j]
            head = world[j, :3, 3]
            tail = world[lower if j == upper else end, :3, 3]
            new_rot = _swing(tail - head, new_tail - head) @ world[j, :3, :3]
            basis[j, :3, :3] = frame[:3, :3].T @ new_rot
            world[j] = frame @ basis[j]
            self._refresh(basis, world, j)
        # the end keeps the sensor's orientation
        frame = world[lower] @ rest_local[end]
        basis[end, :3, :3] = frame[:3, :3].T @ target[0]
        world[end] = frame @ basis[end]
        self._refresh(basis, world, end)

    def _refresh(self, basis, world, j):
        sk, rest_local = self.skeleton, self.rest_local
        for k in self._descendants[j]:
            world[k] = world[sk.parents[k]] @ rest_local[k] @ basis[k]
