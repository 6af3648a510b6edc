"""Analytic inverse kinematics of a 7-DOF limb (Tolani, Goswami and Badler 2000; Oshita 2003,
sec. 2.4.2 and 3.3.1): a ball joint at the hip (shoulder), a hinge at the knee (elbow) and a ball
joint at the ankle (wrist). Given the frame of the limb's parent (pelvis or shoulder girdle), the
end effector's world frame and the swivel angle of the knee about the hip-ankle axis, the seven
joint angles follow in closed form:

  1. the knee angle from the hip-ankle distance (law of cosines on the rig's real offsets),
  2. the hip rotation that puts the knee on its swivel circle and the ankle on its target,
  3. the ankle rotation that gives the end effector its orientation.

The chain runs from the thigh (upper_arm) role bone to the foot (hand) role bone; bones between
them (twist and helper bones) keep the pose given in `basis`. Rotations are the bones' local
(pose-bone basis) rotations in the Skeleton's conventions (Y along the bone).

Swivel angle: the angle of the knee's offset from the hip-ankle axis n, measured from the
projection u of a reference direction fixed in the parent's frame (the rest pose's knee direction
tipped towards the hip, so that u is the knee's rest direction for an upright leg and becomes
singular only with the ankle pointing up-forward, a very high kick), v = n x u.
"""

import numpy as np

from .. import rotations
from ..dynamics import spatial

LIMBS = {"leg": ("thigh", "shin", "foot"), "arm": ("upper_arm", "forearm", "hand")}


def _unit(x):
    return x / np.linalg.norm(x)


def _frame(e1, e2):
    """Rotation with columns e1, the part of e2 orthogonal to e1, and their cross product."""
    a = _unit(e1)
    b = _unit(e2 - (e2 @ a) * a)
    return np.column_stack((a, b, np.cross(a, b)))


def _rot(axis, angle):
    return rotations.to_matrix(rotations.from_axis_angle(np.concatenate(([angle], axis))))


class LimbIK:
    """IK of one limb of `skeleton`: side "L"/"R", limb "leg"/"arm"; `basis` (J, 4, 4) holds the
    pose of the bones that IK does not move and every bone's location channel."""

    def __init__(self, skeleton, side, limb="leg", basis=None, hinge=None):
        sk = skeleton
        self.skeleton = sk
        self.upper, self.lower, self.end = (sk.role_index(f"{r}.{side}") for r in LIMBS[limb])
        if None in (self.upper, self.lower, self.end):
            raise ValueError(f"the rig has no {limb} roles on side {side}")
        self.basis = np.broadcast_to(np.eye(4), (sk.joint_count, 4, 4)).copy() if basis is None \
            else np.array(basis, float)
        self.upper_chain = self._between(self.upper, self.lower)  # upper frame -> lower at zero rotation
        self.lower_chain = self._between(self.lower, self.end)
        self.knee = self.upper_chain[:3, 3]  # knee point in the upper frame
        self.ankle = self.lower_chain[:3, 3]  # ankle point in the lower frame
        self.hinge = _unit(np.asarray(hinge, float)) if hinge is not None else self._rest_hinge()
        self.reference = self._reference_direction()

    def _between(self, a, b):
        """Transform from bone a's posed frame to bone b's frame at zero rotation."""
        sk, path = self.skeleton, []
        k = b
        while k != a:
            path.append(k)
            k = sk.parents[k]
            if k < 0:
                raise ValueError(f"{sk.names[b]} does not descend from {sk.names[a]}")
        m = np.eye(4)
        for k in reversed(path):
            local = sk.rest_local[k] @ self.basis[k]
            if k == b:  # its own rotation is the unknown: only its location channel
                local = sk.rest_local[k].copy()
                local[:3, 3] += sk.rest_local[k][:3, :3] @ self.basis[k][:3, 3]
            m = m @ local
        return m

    def _rest_hinge(self):
        """The axis (lower bone frame) the limb bends about in the rest pose; for a straight rest
        pose the bone's X axis (Blender's convention for knees and elbows)."""
        sk = self.skeleton
        h, k, a = (sk.rest[j][:3, 3] for j in (self.upper, self.lower, self.end))
        n = np.cross(k - h, a - k)
        if np.linalg.norm(n) < np.sin(np.radians(1.0)) * np.linalg.norm(k - h) * np.linalg.norm(a - k):
            return np.array([1.0, 0.0, 0.0])
        return _unit(sk.rest[self.lower][:3, :3].T @ n)

    def _reference_direction(self):
        """Swivel reference (parent frame): the zero-pose knee direction tipped towards the hip."""
        upper0 = self.upper_zero(np.eye(4))
        ankle = self.ankle_in_upper(self.knee_angle_rest())
        axis = _unit(ankle)
        bend = self._bend_direction(ankle, 0.0)
        return upper0[:3, :3] @ _unit(bend - axis)

    def knee_angle_rest(self):
        return 0.0

    # ---- geometry ----

    def upper_zero(self, parent):
        """World frame of the upper bone at zero rotation, from its parent's world frame."""
        sk, j = self.skeleton, self.upper
        local = sk.rest_local[j].copy()
        local[:3, 3] += sk.rest_local[j][:3, :3] @ self.basis[j][:3, 3]
        return np.asarray(parent, float) @ local

    def ankle_in_upper(self, phi):
        """The ankle in the upper bone's frame with the knee bent by `phi` about its hinge."""
        c = self.upper_chain
        return c[:3, 3] + c[:3, :3] @ _rot(self.hinge, phi) @ self.ankle

    def _bend_direction(self, ankle_u, phi):
        """Unit offset of the knee from the hip-ankle line (upper frame); for a straight limb, the
        way the knee would move off the line as it bends."""
        a = _unit(ankle_u)
        off = self.knee - (self.knee @ a) * a
        if np.linalg.norm(off) > 1e-9 * np.linalg.norm(self.knee):
            return _unit(off)
        c = self.upper_chain[:3, :3] @ _rot(self.hinge, phi)
        move = c @ np.cross(self.hinge, self.ankle)
        return _unit(-(move - (move @ a) * a))

    def knee_angle(self, distance):
        """Hinge angle giving the hip-ankle distance, on the bending side; (angle, reachable)."""
        c, k = self.upper_chain[:3, :3], self.knee
        par = self.hinge * (self.hinge @ self.ankle)
        perp = self.ankle - par
        base = k @ k + self.ankle @ self.ankle + 2 * k @ c @ par
        b_cos = 2 * k @ c @ perp
        b_sin = 2 * k @ c @ np.cross(self.hinge, self.ankle)
        amp = np.hypot(b_cos, b_sin)
        psi = np.arctan2(b_sin, b_cos)  # the straightest angle
        x = (distance ** 2 - base) / amp
        return psi + np.arccos(np.clip(x, -1.0, 1.0)), bool(-1.0 <= x <= 1.0)

    # ---- IK and its inverse ----

    def solve(self, parent, end_frame, swivel):
        """Local rotations (upper, lower, end) as quaternions and whether the target was reached
        (otherwise the limb is straightened, or folded, towards it)."""
        upper0 = self.upper_zero(parent)
        hip = upper0[:3, 3]
        target = np.asarray(end_frame, float)[:3, 3]
        phi, reached = self.knee_angle(np.linalg.norm(target - hip))
        ankle_u = self.ankle_in_upper(phi)
        src = _frame(ankle_u, self._bend_direction(ankle_u, phi))
        axis = target - hip
        dst = _frame(upper0[:3, :3].T @ axis, upper0[:3, :3].T @ self.swivel_direction(parent, axis, swivel))
        r_upper = dst @ src.T
        lower_world = upper0[:3, :3] @ r_upper @ self.upper_chain[:3, :3] @ _rot(self.hinge, phi)
        r_end = (lower_world @ self.lower_chain[:3, :3]).T @ np.asarray(end_frame, float)[:3, :3]
        quats = rotations.from_matrix(np.array([r_upper, _rot(self.hinge, phi), r_end]))
        return quats, phi, reached

    def swivel_basis(self, parent, axis):
        n = _unit(axis)
        ref = np.asarray(parent, float)[:3, :3] @ self.reference
        u = _unit(ref - (ref @ n) * n)
        return n, u, np.cross(n, u)

    def swivel_direction(self, parent, axis, swivel):
        n, u, v = self.swivel_basis(parent, axis)
        return np.cos(swivel) * u + np.sin(swivel) * v

    def swivel(self, world):
        """Swivel angle of a posed skeleton's world frames (J, 4, 4)."""
        parent = self.parent_frame(world)
        hip, knee, ankle = (world[j][:3, 3] for j in (self.upper, self.lower, self.end))
        n, u, v = self.swivel_basis(parent, ankle - hip)
        off = knee - hip
        if np.linalg.norm(off - (off @ n) * n) < 1e-9:  # straight: the bend direction
            rel = world[self.upper][:3, :3]
            phi = self.hinge_angle(world)
            off = rel @ self._bend_direction(rel.T @ (ankle - hip), phi)
        return float(np.arctan2(off @ v, off @ u))

    def hinge_angle(self, world):
        rel = np.linalg.solve(world[self.upper] @ self.upper_chain, world[self.lower])[:3, :3]
        return float(np.arctan2(0.5 * np.trace(spatial.skew(self.hinge).T @ rel), 0.5 * (np.trace(rel) - 1.0)))

    def parent_frame(self, world):
        p = self.skeleton.parents[self.upper]
        return np.eye(4) if p < 0 else world[p]

    def pose(self, basis, quats, armature_to_world=None):
        """World frames (J, 4, 4) of `basis` with the limb's three rotations replaced."""
        b = np.array(basis, float)
        for j, q in zip((self.upper, self.lower, self.end), quats):
            b[j, :3, :3] = rotations.to_matrix(q)
        return self.skeleton.world_frames(b, armature_to_world), b

    # ---- acceleration form (sec. 2.4.2) ----

    def rates(self, parent, end_frame, swivel, parent_rates, end_rates, swivel_rates, h=1e-3):
        """Local angular velocities and accelerations (3, 3) each (upper, lower, end; bone axes)
        of the IK solution moving with the given rates.

        parent_rates / end_rates: (linear velocity, angular velocity, linear acceleration, angular
        acceleration), world; swivel_rates: (s', s''). Computed exactly up to O(h^2) by central
        differences of the analytic solution along the quadratic path x(t) = x (+) (x' t + x'' t^2/2)
        at t = -h, 0, h (for a rotation R(t) = exp(w t + a t^2/2) R, the angular velocity and
        acceleration at 0 are w and a; likewise the joint's log(R0^T R(t)) has first and second
        derivatives equal to its local angular velocity and acceleration at 0)."""
        def at(t):
            p = _advance(parent, parent_rates, t)
            e = _advance(end_frame, end_rates, t)
            return self.solve(p, e, swivel + swivel_rates[0] * t + 0.5 * swivel_rates[1] * t * t)[0]
        q0, qp, qm = at(0.0), at(h), at(-h)
        lp = spatial.quat_log(spatial.quat_multiply(spatial.quat_conjugate(q0), qp))
        lm = spatial.quat_log(spatial.quat_multiply(spatial.quat_conjugate(q0), qm))
        return (lp - lm) / (2 * h), (lp + lm) / h ** 2


def _advance(frame, rates, t):
    """A world frame moved for time t along its quadratic path."""
    vel, omega, acc, alpha = (np.asarray(r, float) for r in rates)
    out = np.array(frame, float)
    out[:3, 3] += vel * t + 0.5 * acc * t * t
    out[:3, :3] = rotations.to_matrix(spatial.quat_exp(omega * t + 0.5 * alpha * t * t)) @ out[:3, :3]
    return out
