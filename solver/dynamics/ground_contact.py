"""Ground contact for forward simulation: a penalty force field with damping and Coulomb friction
(Huang 1996, sec. 3.6: "a force field is defined for the floor ... the penetration distance is
used to calculate the response forces"), on spheres attached to the segments."""

from dataclasses import dataclass

import numpy as np

from . import spatial
from .kinematics import body_velocities, motion_subspace, points_on_bodies, update_frames

_TRUNK = {"pelvis": 0.10, "spine": 0.10, "chest": 0.11, "neck": 0.05, "head": 0.09}


@dataclass
class ContactGeometry:
    """Contact spheres: bone (k,), centre in the bone's frame (k, 3), radius (k,) in metres."""

    joints: np.ndarray
    points: np.ndarray
    radii: np.ndarray

    def __post_init__(self):
        self.joints = np.asarray(self.joints, dtype=int)
        self.points = np.asarray(self.points, dtype=float).reshape(-1, 3)
        self.radii = np.asarray(self.radii, dtype=float)
        self._on = (None, None)

    def on(self, model):
        """Bodies (k,) and body-frame centres (k, 3) of the spheres in a model (cached)."""
        if self._on[0] is not model:
            self._on = (model, points_on_bodies(model, self.joints, self.points))
        return self._on[1]

    def world(self, model, data, q):
        """Bodies (k,) and world contact points (k, 3): the bottom of each sphere."""
        bodies, local = self.on(model)
        update_frames(model, data, q)
        f = data.frames[bodies]
        x = (f[:, :3, :3] @ local[:, :, None])[:, :, 0] + f[:, :3, 3]
        x[:, 2] -= self.radii
        return bodies, x


def default_contacts(model, limb_radius=0.04, sole_offset=0.02):
    """Spheres at both ends of every massive bone, and a sole of four small spheres under each foot
    (role foot.L/R): heel 5 cm behind the ankle, ball 5 cm ahead of the foot bone's tail, 9 cm wide,
    `sole_offset` below the tail, flat in the rest pose (armature Z up). Toes get their tip."""
    sk = model.skeleton
    joints, points, radii = [], [], []
    roles = {}
    for role, names in sk.roles.bones.items():
        for n in names:
            roles[n] = role.split(".")[0]
    for j in np.flatnonzero(model.joint_body >= 0):
        if sk.mass[j] <= 0.0:
            continue
        role = roles.get(sk.names[j])
        if role == "foot":
            for p in _sole(sk.rest[j], sk.lengths[j], sole_offset):
                joints.append(j), points.append(p), radii.append(0.0)
            continue
        ends = [(0.0, 0.0, 0.0), (0.0, sk.lengths[j], 0.0)]
        if role == "toe":
            ends = ends[1:]
        r = _TRUNK.get(role, limb_radius)
        for p in ends:
            joints.append(j), points.append(p), radii.append(r)
    return ContactGeometry(joints, points, radii)


def _sole(rest, length, sole_offset):
    head = rest[:3, 3]
    tail = rest[:3, :3] @ np.array([0.0, length, 0.0]) + head
    forward = np.array([tail[0] - head[0], tail[1] - head[1], 0.0])
    forward /= max(np.linalg.norm(forward), 1e-9)
    side = np.cross(forward, [0.0, 0.0, 1.0])
    z = tail[2] - sole_offset
    out = []
    for base, ahead in ((head, -0.05), (tail, 0.05)):
        for s in (-0.045, 0.045):
            p = np.array([base[0], base[1], z]) + ahead * forward + s * side
            out.append(rest[:3, :3].T @ (p - head))
    return out


@dataclass
class GroundModel:
    """Penalty ground: normal force k d + c d' (never pulling), friction capped at mu N and
    viscous (gain `friction_damping`) below the cap, which regularises Coulomb's stick."""

    height: float = 0.0
    stiffness: float = 4e4  # N/m per sphere
    damping: float = 400.0  # N s/m per sphere
    friction: float = 0.8
    friction_damping: float = 800.0  # N s/m

    def forces(self, model, data, q, v, contacts: ContactGeometry):
        """World wrenches (nb, 6) on the bodies, and the world contact points (k, 3) and forces
        (k, 3) of every sphere (zero where it does not touch)."""
        bodies, x = contacts.world(model, data, q)
        depth = self.height - x[:, 2]
        force = np.zeros_like(x)
        touching = depth > 0.0
        if not touching.any():
            return np.zeros((model.nb, 6)), x, force
        vel = body_velocities(model, data, q, v)[bodies[touching]]
        xt = x[touching]
        xd = vel[:, 3:] + spatial.cross(vel[:, :3], xt)
        normal = np.maximum(self.stiffness * depth[touching] - self.damping * xd[:, 2], 0.0)
        slip = xd[:, :2]
        speed = np.linalg.norm(slip, axis=1)
        gain = np.minimum(self.friction_damping, self.friction * normal / np.maximum(speed, 1e-12))
        f = np.zeros_like(xt)
        f[:, :2] = -gain[:, None] * slip
        f[:, 2] = normal
        force[touching] = f
        wrench = np.zeros((model.nb, 6))
        np.add.at(wrench, bodies[touching], np.concatenate((spatial.cross(xt, f), f), axis=1))
        return wrench, x, force

    def split_forces(self, model, data, q, v, contacts: ContactGeometry):
        """The contact forces split for a step with implicit damping: world wrenches (nb, 6) of the
        elastic and saturated-friction parts, and for the damped parts the point Jacobians
        (m, nv) and damping gains (m,) of force = -gain * (J v) along world axes.

        Damping of light segments (a foot rolling on its sole) is far too stiff for an explicit
        step of a millisecond; taken implicitly it is unconditionally stable."""
        bodies, x = contacts.world(model, data, q)
        depth = self.height - x[:, 2]
        touching = depth > 0.0
        empty = np.zeros((0, model.nv)), np.zeros(0)
        if not touching.any():
            return (np.zeros((model.nb, 6)),) + empty
        bodies = bodies[touching]
        xt = x[touching]
        jac = point_jacobians(model, data, q, bodies, xt)  # (k, 3, nv)
        xd = jac @ v
        normal = self.stiffness * depth[touching] - self.damping * xd[:, 2]
        active = normal > 0.0
        speed = np.linalg.norm(xd[:, :2], axis=1)
        sliding = active & (self.friction * normal < self.friction_damping * speed)
        f = np.zeros_like(xt)
        f[:, 2] = np.where(active, self.stiffness * depth[touching], 0.0)
        f[sliding, :2] = -self.friction * (normal[sliding] / speed[sliding])[:, None] * xd[sliding, :2]
        wrench = np.zeros((model.nb, 6))
        np.add.at(wrench, bodies, np.concatenate((spatial.cross(xt, f), f), axis=1))
        sticking = active & ~sliding
        rows = [jac[active, 2], jac[sticking, 0], jac[sticking, 1]]
        gains = [np.full(active.sum(), self.damping), np.full(2 * sticking.sum(), self.friction_damping)]
        return wrench, np.concatenate(rows), np.concatenate(gains)


def point_jacobians(model, data, q, bodies, points):
    """(k, 3, nv) Jacobians of world points (k, 3) moving with bodies (k,)."""
    cols = motion_subspace(model, data, q)  # (nv, 6)
    lin = cols[None, :, 3:] + spatial.cross(cols[None, :, :3], np.asarray(points)[:, None, :])
    mask = model.ancestors[np.asarray(bodies)][:, model.dof_body]
    return np.swapaxes(lin * mask[:, :, None], 1, 2)
