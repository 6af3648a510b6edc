"""What the walking generator needs to know about a rig: its thigh height Ht, its forward
direction, hips, feet (heel, ball and toe tip on the sole), the analytic IK of its legs and how far
they reach without hyperextending. Everything comes from the rest pose (armature space, metres);
roles name the bones (pelvis, thighs, shins, feet, toes, spine, arms)."""

import numpy as np

from ..body_roles import SIDES, sided
from ..errors import RigError
from ..motion_control.limb_ik import LimbIK

KNEE_MIN = np.radians(2.0)  # the least knee flexion allowed: no hyperextension
KNEE_STAND = np.radians(5.0)  # knee flexion when standing
UP = np.array([0.0, 0.0, 1.0])


def unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def rot_x(angle):
    """Rotations (..., 3, 3) about x (the sole frame's lateral axis: positive lifts the toes)."""
    c, s = np.cos(angle), np.sin(angle)
    out = np.zeros(np.shape(angle) + (3, 3))
    out[..., 0, 0] = 1.0
    out[..., 1, 1], out[..., 1, 2] = c, -s
    out[..., 2, 1], out[..., 2, 2] = s, c
    return out


def rot_z(angle):
    c, s = np.cos(angle), np.sin(angle)
    out = np.zeros(np.shape(angle) + (3, 3))
    out[..., 2, 2] = 1.0
    out[..., 0, 0], out[..., 0, 1] = c, -s
    out[..., 1, 0], out[..., 1, 1] = s, c
    return out


def axis_angle_matrix(axis, angle):
    """Rotations (..., 3, 3) about unit axes (..., 3) by angles (...) (Rodrigues)."""
    axis = np.asarray(axis, float)
    angle = np.asarray(angle, float)[..., None, None]
    k = np.zeros(axis.shape[:-1] + (3, 3))
    k[..., 0, 1], k[..., 0, 2], k[..., 1, 2] = -axis[..., 2], axis[..., 1], -axis[..., 0]
    k[..., 1, 0], k[..., 2, 0], k[..., 2, 1] = axis[..., 2], -axis[..., 1], axis[..., 0]
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * (k @ k)


def rotation_between(a, b):
    """Smallest rotations (..., 3, 3) turning unit vectors a onto b."""
    a, b = unit(a), unit(b)
    axis = np.cross(a, b)
    s = np.linalg.norm(axis, axis=-1)
    c = np.sum(a * b, axis=-1)
    safe = np.where(s[..., None] > 1e-12, axis / np.maximum(s, 1e-12)[..., None], [1.0, 0.0, 0.0])
    return axis_angle_matrix(safe, np.arctan2(s, c))


class Foot:
    """One foot: its sole frame at rest (origin on the sole under the heel, columns right, forward,
    up) and the foot and toe bones relative to it."""

    def __init__(self, sk, side, forward):
        self.side = side
        self.foot = sk.role_index(sided("foot", side))
        self.toe = sk.role_index(sided("toe", side))
        rest = sk.rest
        ankle = rest[self.foot, :3, 3]
        ends = [ankle, rest[self.foot, :3, 3] + rest[self.foot, :3, 1] * sk.lengths[self.foot]]
        if self.toe is not None:
            ends += [rest[self.toe, :3, 3], rest[self.toe, :3, 3] + rest[self.toe, :3, 1] * sk.lengths[self.toe]]
        ends = np.array(ends)
        self.leg_length = None  # set by the body
        sole_z = ends[:, 2].min()
        self.ball_joint = rest[self.toe, :3, 3] if self.toe is not None else ends[1]
        tip = ends[-1]
        length = max(np.dot(tip - ankle, forward), 0.05)
        self.ankle_height = ankle[2] - sole_z
        self.sole_z = sole_z
        heel = ankle - 0.25 * length * forward
        heel[2] = sole_z
        right = np.cross(forward, UP)
        self.rest_sole = np.eye(4)
        self.rest_sole[:3, :3] = np.column_stack((right, forward, UP))
        self.rest_sole[:3, 3] = heel
        inv = np.linalg.inv(self.rest_sole)
        self.rel_foot = inv @ rest[self.foot]
        self.rel_toe = inv @ rest[self.toe] if self.toe is not None else None
        self.ankle_local = (inv @ np.r_[ankle, 1.0])[:3]  # in sole coordinates
        self.ball_local = (inv @ np.r_[self.ball_joint, 1.0])[:3]  # the toe joint, pivot of toe roll
        ball_sole = self.ball_joint.copy()
        ball_sole[2] = sole_z
        self.ball_sole_local = (inv @ np.r_[ball_sole, 1.0])[:3]
        tip_sole = tip.copy()
        tip_sole[2] = sole_z
        self.tip_local = (inv @ np.r_[tip_sole, 1.0])[:3]
        # the sole points in the frames of the bones that carry them (the ball and tip go with the toe)
        self.heel_in_foot = (np.linalg.inv(rest[self.foot]) @ np.r_[heel, 1.0])[:3]
        carrier = rest[self.toe] if self.toe is not None else rest[self.foot]
        self.ball_in_toe = (np.linalg.inv(carrier) @ np.r_[ball_sole, 1.0])[:3]
        self.tip_in_toe = (np.linalg.inv(carrier) @ np.r_[tip_sole, 1.0])[:3]


class WalkerBody:
    def __init__(self, skeleton):
        sk = self.skeleton = skeleton
        missing = [r for r in ("pelvis",) + tuple(sided(r, s) for s in SIDES for r in ("thigh", "shin", "foot"))
                   if sk.role_index(r) is None]
        if missing:
            raise RigError(f"walking needs the body roles {', '.join(missing)}: set them in Body Roles")
        rest = sk.rest
        self.thigh = {s: sk.role_index(sided("thigh", s)) for s in SIDES}
        self.shin = {s: sk.role_index(sided("shin", s)) for s in SIDES}
        feet = {s: sk.role_index(sided("foot", s)) for s in SIDES}
        ahead = []
        for s in SIDES:
            end = rest[feet[s], :3, 3] + rest[feet[s], :3, 1] * sk.lengths[feet[s]]
            ahead.append(end - rest[feet[s], :3, 3])
        f = np.mean(ahead, axis=0)
        f[2] = 0.0
        if np.linalg.norm(f) < 1e-6:
            raise RigError("cannot tell which way the feet point: the foot bones are vertical in the rest pose")
        self.forward = unit(f)  # armature space
        self.right = np.cross(self.forward, UP)
        self.left = -self.right
        self.hips = {s: rest[self.thigh[s], :3, 3] for s in SIDES}
        self.hip_centre = 0.5 * (self.hips["L"] + self.hips["R"])
        self.hip_offset = {s: float(np.dot(self.hips[s] - self.hip_centre, self.right)) for s in SIDES}
        if not self.hip_offset["R"] > 0 > self.hip_offset["L"]:
            raise RigError("the right thigh is not on the right of the left one as the feet point: check the "
                           "thigh roles")
        self.feet = {s: Foot(sk, s, self.forward) for s in SIDES}
        self.ik = {s: LimbIK(sk, s, "leg") for s in SIDES}
        self.straight = {s: self.ik[s].knee_angle(1e6)[0] for s in SIDES}
        # thigh height: hip flexion axis to the sole with the leg straight (Boulic's Ht)
        self.ht = float(np.mean([self.reach(s, 0.0) + self.feet[s].ankle_height for s in SIDES]))
        self.ankle_height = float(np.mean([self.feet[s].ankle_height for s in SIDES]))
        self.trunk = [sk.index(b) for b in sk.roles.chain("spine") + sk.roles.chain("chest")]
        self.neck = [sk.index(b) for b in sk.roles.chain("neck") + sk.roles.chain("head")][:1]
        self.arms = {s: tuple(sk.role_index(sided(r, s)) for r in ("upper_arm", "forearm")) for s in SIDES}

    def reach(self, side, flexion):
        """Hip-to-ankle distance of the leg with the knee flexed `flexion` radians from straight."""
        ik = self.ik[side]
        return float(np.linalg.norm(ik._ankle_in_upper(self.straight[side] + flexion)))

    def flexion(self, side, distance):
        """Knee flexion from straight giving a hip-ankle distance."""
        return self.ik[side].knee_angle(distance)[0] - self.straight[side]
