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
    """Spheres at both ends of every massive bone, and a sole of four points under each foot
    (role foot.L/R): heel 5 cm behind the ankle, ball 5 cm ahead of the foot bone's tail, 9 cm wide,
    `sole_offset` below the tail, flat in the rest pose (armature Z up). A toe gets two points
    under its tip, level with its foot's sole in the rest pose (a sphere at the tip would reach
    below the sole and carry the body's weight on the lightest segment).

    Limb spheres are no wider than half their bone's length, so that fingers (3 cm bones) get 1.5 cm
    spheres rather than the forearm's 4 cm and the hand rests on its palm, not on a cloud of
    finger spheres.

    Massless bones riding on a segment (a face's nose and lips, helper bones) get one small
    sphere at their tail, so that no bone the animator sees passes through the floor."""
    sk = model.skeleton
    joints, points, radii = [], [], []
    roles = {}
    for role, names in sk.roles.bones.items():
        for n in names:
            roles[n] = role.split(".")[0]
    for j in np.flatnonzero(model.joint_body >= 0):
        if sk.mass[j] <= 0.0:
            if sk.lengths[j] > 1e-3:
                joints.append(j), points.append((0.0, sk.lengths[j], 0.0))
                radii.append(min(0.02, 0.5 * sk.lengths[j]))
            continue
        role = roles.get(sk.names[j])
        if role == "foot":
            for p in _sole(sk.rest[j], sk.lengths[j], sole_offset):
                joints.append(j), points.append(p), radii.append(0.0)
            continue
        if role == "toe":
            for p in _toe_tip(sk, j, roles, sole_offset):
                joints.append(j), points.append(p), radii.append(0.0)
            continue
        ends = [(0.0, 0.0, 0.0), (0.0, sk.lengths[j], 0.0)]
        r = _TRUNK[role] if role in _TRUNK else min(limb_radius, 0.5 * sk.lengths[j])
        for p in ends:
            joints.append(j), points.append(p), radii.append(r)
    return ContactGeometry(joints, points, radii)


def _toe_tip(sk, j, roles, sole_offset, half_width=0.03):
    """Two points (toe frame) under the toe's tip, `half_width` apart sideways, at the height of
    the sole of the foot above it (or `sole_offset` below the tip without a foot)."""
    rest = sk.rest[j]
    head = rest[:3, 3]
    tip = rest[:3, :3] @ np.array([0.0, sk.lengths[j], 0.0]) + head
    z = tip[2] - sole_offset
    for a in sk.ancestors(j):
        if roles.get(sk.names[a]) == "foot":
            z = (sk.rest[a, :3, :3] @ np.array([0.0, sk.lengths[a], 0.0]) + sk.rest[a, :3, 3])[2] - sole_offset
            break
    forward = np.array([tip[0] - head[0], tip[1] - head[1], 0.0])
    forward /= max(np.linalg.norm(forward), 1e-9)
    side = np.cross(forward, [0.0, 0.0, 1.0])
    return [rest[:3, :3].T @ (np.array([tip[0], tip[1], z]) + s * side - head)
            for s in (-half_width, half_width)]


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
    # stiff enough that a falling body sinks ~2 cm on impact (4e4 let it sink 7 cm); stable
    # because the step takes contact stiffness and damping implicitly. 5e5 made a lying body jitter
    stiffness: float = 2e5  # N/m per sphere
    damping: float = 2000.0  # N s/m per sphere
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
        elastic parts, and for the damped parts (normal damping, then friction along world x and
        y of every active point: viscous below Coulomb's cap, at the cap a viscous gain that gives
        mu N at the current slip) the point Jacobians (m, nv) and damping gains (m,) of
        force = -gain * (J v) along world axes.

        Damping of light segments (a foot rolling on its sole) is far too stiff for an explicit
        step of a millisecond; taken implicitly it is unconditionally stable."""
        return self.linearised_forces(model, data, q, v, contacts)[:3]

    def linearised_forces(self, model, data, q, v, contacts: ContactGeometry):
        """split_forces() and the normal stiffness of each row (m,) (0 on friction rows): the
        elastic force changes by -stiffness * (J dx) when the points move by dx, which a step can
        take implicitly too (the penalty spring on a toe or a finger is as stiff as its damping)."""
        bodies, x = contacts.world(model, data, q)
        depth = self.height - x[:, 2]
        touching = depth > 0.0
        empty = np.zeros((0, model.nv)), np.zeros(0), np.zeros(0)
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
        wrench = np.zeros((model.nb, 6))
        np.add.at(wrench, bodies, np.concatenate((spatial.cross(xt, f), f), axis=1))
        # sliding friction as a viscous force whose gain mu N / |slip| (< friction_damping) gives
        # Coulomb's force at the current slip: explicit, its direction would flip every step
        # on a light segment (a toe sliding on the floor)
        tangential = np.where(sliding, self.friction * normal / np.maximum(speed, 1e-12), self.friction_damping)
        n_active = int(active.sum())
        rows = [jac[active, 2], jac[active, 0], jac[active, 1]]
        gains = [np.full(n_active, self.damping), tangential[active], tangential[active]]
        stiffness = np.concatenate((np.full(n_active, self.stiffness), np.zeros(2 * n_active)))
        return wrench, np.concatenate(rows), np.concatenate(gains), stiffness


def point_jacobians(model, data, q, bodies, points):
    """(k, 3, nv) Jacobians of world points (k, 3) moving with bodies (k,)."""
    cols = motion_subspace(model, data, q)  # (nv, 6)
    lin = cols[None, :, 3:] + spatial.cross(cols[None, :, :3], np.asarray(points)[:, None, :])
    mask = model.ancestors[np.asarray(bodies)][:, model.dof_body]
    return np.swapaxes(lin * mask[:, :, None], 1, 2)
