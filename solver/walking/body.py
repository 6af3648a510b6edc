"""What the walking generator needs to know about a rig: its thigh height Ht, its forward
direction, hips, feet (heel, ball and toe tip on the sole), the analytic IK of its legs and how far
they reach without hyperextending. Everything comes from a standing pose (armature space, metres):
the rest pose when the figure stands in it, else a standing frame of a motion of the rig
(`standing_reference`: a BVH's rest pose may have every bone along X, as Bandai Namco's has);
roles name the bones (pelvis, thighs, shins, feet, toes, spine, arms).

The forward direction is the body's facing: the left hip's side crossed with up (forward x left =
up), so it needs no foot bone pointing anywhere; the toes, when they point clearly, only check
the sides."""

from dataclasses import replace

import numpy as np

from ..body_roles import SIDES, sided
from ..errors import RigError
from ..motion_control.limb_ik import LimbIK
from ..rotations import axis_angle_matrix, rotation_between  # noqa: F401 (walk.py's names)

KNEE_MIN = np.radians(2.0)  # the least knee flexion allowed: no hyperextension
KNEE_STAND = np.radians(5.0)  # knee flexion when standing
UP = np.array([0.0, 0.0, 1.0])
TOE_ALONG_GROUND = 0.03  # m: a toe's tip this near its base's height lies along the ground


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
        toe_flat = True
        if self.toe is not None:
            ball, toe_tip = rest[self.toe, :3, 3], rest[self.toe, :3, 3] + rest[self.toe, :3, 1] * sk.lengths[self.toe]
            ends.append(ball)
            # a toe that stands up or dips into the floor is a made-up tail (a BVH's zero-length toe
            # continuing the foot's line, as Blender makes it): the sole is then at the ball, and
            # the toe is laid along the ground (below)
            toe_flat = abs(toe_tip[2] - ball[2]) < TOE_ALONG_GROUND
            if toe_flat:
                ends.append(toe_tip)
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
        if not toe_flat:  # the toe turned about its head to lie along the sole
            along = self.rel_toe[:3, 1].copy()
            along[2] = 0.0
            along = unit(along) if np.linalg.norm(along) > 1e-3 else np.array([0.0, 1.0, 0.0])
            self.rel_toe[:3, :3] = rotation_between(self.rel_toe[:3, 1], along) @ self.rel_toe[:3, :3]
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
        carrier = self.rest_sole @ self.rel_toe if self.toe is not None else rest[self.foot]
        self.ball_in_toe = (np.linalg.inv(carrier) @ np.r_[ball_sole, 1.0])[:3]
        self.tip_in_toe = (np.linalg.inv(carrier) @ np.r_[tip_sole, 1.0])[:3]


class WalkerBody:
    def __init__(self, skeleton, hinges=None):
        sk = self.skeleton = skeleton
        missing = [r for r in ("pelvis",) + tuple(sided(r, s) for s in SIDES for r in ("thigh", "shin", "foot"))
                   if sk.role_index(r) is None]
        if missing:
            raise RigError(f"walking needs the body roles {', '.join(missing)}: set them in Body Roles")
        rest = sk.rest
        self.thigh = {s: sk.role_index(sided("thigh", s)) for s in SIDES}
        self.shin = {s: sk.role_index(sided("shin", s)) for s in SIDES}
        if not stands(sk):
            raise RigError("the rig does not stand in its rest pose (its legs do not hang below the hips): "
                           "give the walk a motion of the rig to take a standing pose from")
        self.hips = {s: rest[self.thigh[s], :3, 3] for s in SIDES}
        self.hip_centre = 0.5 * (self.hips["L"] + self.hips["R"])
        self.forward = facing(sk)  # armature space
        self.right = np.cross(self.forward, UP)
        self.left = -self.right
        self.hip_offset = {s: float(np.dot(self.hips[s] - self.hip_centre, self.right)) for s in SIDES}
        toes = _toes_ahead(sk)
        if toes is not None and np.dot(toes, self.forward) < -0.5 * np.linalg.norm(toes):
            raise RigError("the feet point backwards from the way the hips face: check the left and right "
                           "thigh roles")
        self.feet = {s: Foot(sk, s, self.forward) for s in SIDES}
        self.ik = {s: LimbIK(sk, s, "leg", hinge=(hinges or {}).get(s)) for s in SIDES}
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
        return float(np.linalg.norm(ik.ankle_in_upper(self.straight[side] + flexion)))

    def flexion(self, side, distance):
        """Knee flexion from straight giving a hip-ankle distance."""
        return self.ik[side].knee_angle(distance)[0] - self.straight[side]


def _leg_vectors(sk, rest=None):
    rest = sk.rest if rest is None else rest
    return {s: rest[..., sk.role_index(sided("foot", s)), :3, 3] - rest[..., sk.role_index(sided("thigh", s)), :3, 3]
            for s in SIDES}


def stands(sk):
    """Whether the rest pose is a standing figure: both legs hang from the hips (hip to ankle
    within 35 deg of straight down) and the hips are side by side. A rig without both legs' thigh
    and foot roles is taken as it is."""
    if any(sk.role_index(sided(r, s)) is None for r in ("thigh", "foot") for s in SIDES):
        return True
    legs = _leg_vectors(sk)
    hang = all(v[2] < -np.cos(np.radians(35.0)) * np.linalg.norm(v) for v in legs.values())
    return bool(hang and _hip_side(sk) is not None)


def _hip_side(sk):
    """Horizontal unit vector from the right hip to the left one, or None."""
    d = sk.rest[sk.role_index("thigh.L"), :3, 3] - sk.rest[sk.role_index("thigh.R"), :3, 3]
    d[2] = 0.0
    n = np.linalg.norm(d)
    return d / n if n > 1e-4 else None


def facing(sk):
    """The body's forward direction in the rest pose: forward x left = up."""
    left = _hip_side(sk)
    if left is None:
        raise RigError("the left and right thighs start at the same place: check the thigh roles")
    return unit(np.cross(left, UP))


def _toes_ahead(sk):
    """Mean horizontal direction from the ankles to the tips of the feet (foot and toe bones),
    or None where they point up or down."""
    out = []
    for s in SIDES:
        foot, toe = sk.role_index(sided("foot", s)), sk.role_index(sided("toe", s))
        tip = sk.rest[foot, :3, 3] + sk.rest[foot, :3, 1] * sk.lengths[foot]
        if toe is not None:
            tip = max((tip, sk.rest[toe, :3, 3] + sk.rest[toe, :3, 1] * sk.lengths[toe]),
                      key=lambda q: np.linalg.norm((q - sk.rest[foot, :3, 3])[:2]))
        out.append(tip - sk.rest[foot, :3, 3])
    f = np.mean(out, axis=0)
    f[2] = 0.0
    return f if np.linalg.norm(f) > 0.02 else None


def standing_frame(sk, world):
    """Index of the frame of a motion (world frames (F, J, 4, 4)) in which the figure best stands,
    by a cost in metres: both ankles down at their lowest (weighted 4: a raised foot is not
    standing) with the foot bone pitched as it is when down, legs long and hanging, feet side by
    side under the hips."""
    heads = world[:, :, :3, 3]
    cost = np.zeros(len(world))
    ankles = {}
    for s in SIDES:
        foot = sk.role_index(sided("foot", s))
        hip, ankle = heads[:, sk.role_index(sided("thigh", s))], heads[:, foot]
        leg = hip - ankle
        d = np.linalg.norm(leg, axis=1)
        down = ankle[:, 2] < ankle[:, 2].min() + 0.01
        pitch = world[:, foot, 2, 1]  # the foot bone's direction, up component
        flat = np.median(pitch[down])
        cost += 4 * (ankle[:, 2] - ankle[:, 2].min()) + 0.1 * np.abs(pitch - flat) + (d.max() - d) + (d - leg[:, 2])
        ankles[s] = ankle
    hips = heads[:, sk.role_index("thigh.L")] - heads[:, sk.role_index("thigh.R")]
    feet = ankles["L"] - ankles["R"]
    cost += np.linalg.norm((feet - hips)[:, :2], axis=1)
    return int(np.argmin(cost))


def standing_reference(skeleton, motion):
    """A skeleton whose rest pose stands, taken from `motion` (Trajectories of `skeleton`), and
    the pose-bone bases B0 (J, 4, 4) that carry the original rest pose to it: a pose basis' on the
    new skeleton is the basis B0 @ basis' on the original one (same world frames). Also the knee
    hinge axes found in the motion (lower bone frame of the new skeleton), per side, or None.
    Returns (skeleton, None, None) when the rest pose stands."""
    if stands(skeleton):
        return skeleton, None, None
    if motion is None or motion.frame_count == 0:
        raise RigError("the rig does not stand in its rest pose (its legs do not hang below the hips, as in a "
                       "BVH whose bones all lie along one axis): walking needs a motion of the rig (its action) "
                       "to take a standing pose from")
    basis = motion.basis()
    world = skeleton.world_frames(basis)  # armature space
    k = standing_frame(skeleton, world)
    b0 = basis[k].copy()
    sk = replace(skeleton, rest=world[k].copy())
    hinges = {}
    for s in SIDES:
        lower = sk.role_index(sided("shin", s))
        rel = np.linalg.solve(b0[lower][None, :3, :3].repeat(len(basis), 0), basis[:, lower, :3, :3])
        hinges[s] = knee_axis(rel)
    return sk, b0, hinges


def knee_axis(rel):
    """The axis (F, 3, 3) relative rotations of a knee turn about most: the principal direction of
    their rotation vectors, signed so that the larger rotations turn positively about it; None
    when the knee barely moves (under 10 deg)."""
    from .. import rotations
    q = rotations.from_matrix(rel)
    q = q * np.where(q[:, :1] < 0, -1.0, 1.0)
    angle = 2 * np.arctan2(np.linalg.norm(q[:, 1:], axis=1), q[:, 0])
    if angle.max() < np.radians(10.0):
        return None
    v = q[:, 1:] / np.maximum(np.linalg.norm(q[:, 1:], axis=1), 1e-12)[:, None] * angle[:, None]
    w, vec = np.linalg.eigh(v.T @ v)
    axis = vec[:, -1]
    return axis if np.sum(v @ axis) >= 0 else -axis
