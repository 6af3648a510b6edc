"""Muscle strength: the maximum and minimum torque a joint axis can produce, as functions of joint
angle and angular velocity (Oshita 2003, eq. 2.2, after Pandya et al. 1992), and joint limits.

    tau_max = s T0 A(theta) V(omega),   tau_min = -s T0 A(theta) V(-omega)

T0: peak isometric torque of the axis; s: the global strength scale.
A(theta) = max(0.3, cos(0.6 theta)): the cosine torque-angle relation of Anderson, Madigan and
    Nussbaum (2007, J. Biomech. 40:3105-3113, "Maximum voluntary joint torque as a function of
    joint angle and angular velocity"), with generic coefficients (optimum at the rest pose).
V(omega): Hill's torque-velocity relation (Hill 1938): (1 - w) / (1 + w / 0.25) with
    w = omega / omega_max for shortening (omega with the torque; floored at 0.1 so that noisy
    motion above omega_max stays controllable), rising to 1.3 x isometric for lengthening:
    1.3 - 0.3 / (1 + 10 |omega| / omega_max).
    omega_max is a joint-level value, not a muscle fibre's: series elasticity and several
    muscles per joint make joint torque fall off far more slowly with speed. It is set so that
    V is about 0.65 at 180 deg/s and 0.5 at 300 deg/s, the ratios isokinetic dynamometry
    typically reports for knee extension; this puts omega_max near 30 rad/s for the legs.

Peak isometric torques (N m) are rounded from values reported for healthy young men by Anderson
et al. (2007) for hip, knee and ankle (flexion/extension averaged) and by Pandya et al. (1992,
"Correlation and prediction of dynamic human isolated joint strength from lean body mass", NASA
TP-3207) for the shoulder, elbow and wrist; trunk and neck values are typical of the
literature. They apply to a bone's local X axis (flexion in Blender rigs); the twist axis Y gets
40 % and the Z axis 60 %. Bones without a known role get 2.5 times the static moment of their
subtree held horizontally, so they can always hold themselves up. This is an approximation:
angles are the rotation-vector components of a bone's local rotation, not anatomical angles.
"""

from dataclasses import dataclass

import numpy as np

from . import spatial

# role: (peak isometric torque about local X in N m, maximum shortening velocity in rad/s)
PEAK_TORQUE = {
    "spine": (250.0, 20.0), "chest": (200.0, 20.0), "neck": (40.0, 25.0), "head": (30.0, 25.0),
    "clavicle": (80.0, 25.0), "upper_arm": (90.0, 32.0), "forearm": (70.0, 36.0),
    "hand": (15.0, 40.0), "thigh": (200.0, 28.0), "shin": (190.0, 32.0), "foot": (140.0, 28.0),
    "toe": (20.0, 28.0), "thumb": (5.0, 40.0), "index": (3.0, 40.0), "middle": (3.0, 40.0),
    "ring": (2.0, 40.0), "pinky": (2.0, 40.0),
}
DEFAULT_MAX_VELOCITY = 28.0  # rad/s, bones without a known role
AXIS_SHARE = np.array([1.0, 0.4, 0.6])


@dataclass
class StrengthModel:
    """Per bone and local axis: peak isometric torque (J, 3) N m and maximum velocity (J, 3) rad/s
    (or any matching shapes, see select)."""

    peak: np.ndarray
    max_velocity: np.ndarray
    scale: float = 1.0

    def limits(self, angles, velocities):
        """(tau_min, tau_max) (..., J, 3) for joint angles and angular velocities (..., J, 3)."""
        angle = np.maximum(0.3, np.cos(0.6 * np.clip(np.asarray(angles, float), -np.pi, np.pi)))
        w = np.asarray(velocities, float) / self.max_velocity
        return torque_range(self.scale * self.peak * angle, w)

    def select(self, joints, axes):
        """The strength of single DOFs (bone, local axis), e.g. a model's actuated DOFs."""
        return StrengthModel(self.peak[joints, axes], self.max_velocity[joints, axes], self.scale)

    def clamp(self, tau, angles, velocities):
        """tau clamped to the available range, and the usage tau / available (> 1 when clamped)."""
        low, high = self.limits(angles, velocities)
        usage = np.where(tau >= 0.0, tau / np.maximum(high, 1e-12), tau / np.minimum(low, -1e-12))
        return np.clip(tau, low, high), usage


def torque_range(top, w):
    """(tau_min, tau_max) of DOFs whose isometric strength at their angle is `top`, at normalised
    velocities w: the Hill torque-velocity factors of w and -w from |w| in one pass. One direction
    shortens (max((1 - w) / (1 + 4 w), 0.1)), the other lengthens (1.3 - 0.3 / (1 + 10 w)); both
    are 1 at rest."""
    p = np.abs(w)
    short = np.maximum((1.0 - p) / (1.0 + 4.0 * p), 0.1)
    long = 1.3 - 0.3 / (1.0 + 10.0 * p)
    pos = w >= 0.0
    return -top * np.where(pos, long, short), top * np.where(pos, short, long)


def default_strength(model, scale=1.0, gravity=9.81):
    """Strength for every bone of a model's skeleton, from its body roles (see module docstring)."""
    sk = model.skeleton
    J = sk.joint_count
    peak = np.zeros((J, 3))
    vmax = np.full((J, 3), DEFAULT_MAX_VELOCITY)
    roles = {}
    for role, names in sk.roles.bones.items():
        for n in names:
            roles[n] = role.split(".")[0]
    static = _static_moments(sk) * gravity
    for j in range(J):
        entry = PEAK_TORQUE.get(roles.get(sk.names[j]) or _trunk_role(sk, j, roles))
        if entry is None:
            peak[j] = max(2.5 * static[j], 5.0) * AXIS_SHARE
        else:
            peak[j] = entry[0] * AXIS_SHARE
            vmax[j] = entry[1]
    return StrengthModel(peak=peak, max_velocity=vmax, scale=float(scale))


def _trunk_role(sk, j, roles):
    """The role of the trunk bone below an unnamed bone that lies on the trunk (between the spine
    or chest and the neck: CMU's Chest2, a spine.002 the role tables left out): it carries the
    same upper body, so it gets the same strength."""
    below = next((roles.get(sk.names[a]) for a in sk.ancestors(j) if roles.get(sk.names[a])), None)
    above = {roles.get(sk.names[d]) for d in sk.descendants(j)}
    return below if below in ("spine", "chest") and above & {"chest", "neck", "head"} else None


def _static_moments(sk):
    """Sum over each bone's subtree of mass x distance from the bone's head (rest pose), kg m."""
    heads = sk.rest[:, :3, 3]
    coms = np.einsum("jab,jb->ja", sk.rest[:, :3, :3], sk.com) + heads
    out = np.zeros(sk.joint_count)
    for j in range(sk.joint_count):
        sub = [j] + list(sk.descendants(j))
        out[j] = np.sum(sk.mass[sub] * np.linalg.norm(coms[sub] - heads[j], axis=1))
    return out


def joint_angles(model, q):
    """Rotation-vector components (J, 3) of every bone's local rotation (zero for the base and
    bones that do not move), the angles of the strength model and the joint limits."""
    out = np.zeros((model.skeleton.joint_count, 3))
    quats = np.asarray(q, float)[7:].reshape(-1, 4)
    out[model.body_joint[1:]] = spatial.quat_log(quats)
    return out


def limit_torques(model, q, v, stiffness=200.0, damping=10.0):
    """Generalised forces (nv,) of stiff spring-dampers that stop joints at the skeleton's limits
    (per local axis on the rotation-vector angles), zero inside the limits."""
    sk = model.skeleton
    angles = joint_angles(model, q)[model.dof_joint[6:], model.dof_slot[6:]]
    lim = sk.limits[model.dof_joint[6:], model.dof_slot[6:]]
    over = np.minimum(angles - lim[:, 0], 0.0) + np.maximum(angles - lim[:, 1], 0.0)
    vel = np.asarray(v, float)[6:]
    tau = np.zeros(model.nv)
    tau[6:] = np.where(over != 0.0, -stiffness * over - damping * vel * (np.sign(over) == np.sign(vel)), 0.0)
    return tau
