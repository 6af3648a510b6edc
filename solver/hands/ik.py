"""Inverse kinematics with a main task and a secondary task in its null space (Huang 1996 sec. 2.3,
eq. 2-1):  dq = J+ dx + (I - J+ J) dz,
with damped least squares near singularities (the damping grows as the smallest singular value
falls below a threshold, Maciejewski's rule) and joint limits (a DOF at its limit and pushed out
of range loses its column, the step is solved again).

A chain is the path of bones from a start bone to the hand, chosen by body role: shoulder
(clavicle, or the upper arm when there is none) to hand, or the spine above the pelvis included.
Each bone turns on its free axes as intrinsic X-Y-Z Euler angles, so limits are per axis and the
Jacobian is exact: the column of an axis is that axis in world (turning about the bone's head).
"""

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from ..body_roles import sided
from ..errors import RigError


def _rx(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _ry(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _rz(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def rodrigues(v):
    """Rotation matrices (..., 3, 3) of rotation vectors (..., 3)."""
    v = np.asarray(v, float)
    th = np.linalg.norm(v, axis=-1)[..., None, None]
    k = np.zeros(v.shape[:-1] + (3, 3))
    k[..., 0, 1], k[..., 0, 2], k[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
    k = k - np.swapaxes(k, -1, -2)
    small = th < 1e-12
    ths = np.where(small, 1.0, th)
    a = np.where(small, 1.0, np.sin(ths) / ths)
    b = np.where(small, 0.5, (1 - np.cos(ths)) / ths ** 2)
    return np.eye(3) + a * k + b * (k @ k)


def euler_xyz(r):
    """Intrinsic X-Y-Z angles (..., 3) of rotations (..., 3, 3): R = Rx(a) Ry(b) Rz(c)."""
    r = np.asarray(r, float)
    b = np.arcsin(np.clip(r[..., 0, 2], -1.0, 1.0))
    a = np.arctan2(-r[..., 1, 2], r[..., 2, 2])
    c = np.arctan2(-r[..., 0, 1], r[..., 0, 0])
    return np.stack((a, b, c), axis=-1)


def matrix_xyz(e):
    """Rotations (..., 3, 3) of intrinsic X-Y-Z angles (..., 3)."""
    e = np.asarray(e, float)
    ca, sa = np.cos(e[..., 0]), np.sin(e[..., 0])
    cb, sb = np.cos(e[..., 1]), np.sin(e[..., 1])
    cc, sc = np.cos(e[..., 2]), np.sin(e[..., 2])
    out = np.empty(e.shape[:-1] + (3, 3))
    out[..., 0, 0] = cb * cc
    out[..., 0, 1] = -cb * sc
    out[..., 0, 2] = sb
    out[..., 1, 0] = ca * sc + sa * sb * cc
    out[..., 1, 1] = ca * cc - sa * sb * sc
    out[..., 1, 2] = -sa * cb
    out[..., 2, 0] = sa * sc - ca * sb * cc
    out[..., 2, 1] = sa * cc + ca * sb * sc
    out[..., 2, 2] = ca * cb
    return out


def rot_log(r):
    """World axis-angle vector of a rotation matrix."""
    return Rotation.from_matrix(r).as_rotvec()


def chain_joints(skeleton, side, with_spine=False):
    """Bones from the shoulder (or the spine above the pelvis) down to the hand, parents first."""
    hand = skeleton.role_index(sided("hand", side))
    if hand is None:
        raise RigError(f"the rig has no hand.{side} role")
    if with_spine:
        pelvis = skeleton.role_index("pelvis")
        stop = lambda j: j == pelvis or j < 0  # noqa: E731
    else:
        start = skeleton.role_index(sided("clavicle", side))
        if start is None:
            start = skeleton.role_index(sided("upper_arm", side))
        if start is None:
            raise RigError(f"the rig has no upper_arm.{side} role")
        stop = lambda j: j == skeleton.parents[start] or j < 0  # noqa: E731
    path, j = [], hand
    while not stop(j):
        path.append(j)
        j = skeleton.parents[j]
    return path[::-1]


@dataclass
class Chain:
    skeleton: object
    joints: list  # bone indices, parents first, each the parent of the next
    tip: int  # bone carrying the end effector
    point: np.ndarray  # end effector in the tip bone's frame (metres)
    allowed: dict = None  # optional {joint: axes} restricting the free axes
    dofs: list = None  # (joint position in chain, axis)
    lower: np.ndarray = None
    upper: np.ndarray = None

    def __post_init__(self):
        sk = self.skeleton
        self.point = np.asarray(self.point, float)
        self.dofs = [(k, a) for k, j in enumerate(self.joints) for a in range(3) if sk.dof[j, a]
                     and (self.allowed is None or a in self.allowed.get(j, ()))]
        lim = np.array([sk.limits[self.joints[k], a] for k, a in self.dofs]).reshape(-1, 2)
        self.lower, self.upper = lim[:, 0], lim[:, 1]
        self.rest_local = sk.rest_local[self.joints]
        self.n = len(self.dofs)
        self._k = np.array([k for k, _ in self.dofs], int)
        self._a = np.array([a for _, a in self.dofs], int)

    @classmethod
    def arm(cls, skeleton, side, point=(0, 0, 0), with_spine=False, tip=None):
        joints = chain_joints(skeleton, side, with_spine)
        if tip is not None:
            joints = joints[:joints.index(tip) + 1]
        return cls(skeleton, joints, joints[-1], np.asarray(point, float))

    # --- angles <-> basis -------------------------------------------------------------
    def angles(self, basis):
        eul = euler_xyz(basis[self.joints, :3, :3])
        return eul[self._k, self._a]

    def euler(self, theta, basis):
        eul = euler_xyz(basis[self.joints, :3, :3])
        eul[self._k, self._a] = theta
        return eul

    def apply(self, theta, basis):
        out = np.array(basis, float)
        out[self.joints, :3, :3] = matrix_xyz(self.euler(theta, basis))
        return out

    # --- kinematics -------------------------------------------------------------------
    def frames(self, eul, basis, base):
        """World frames of the chain's bones, and the world rotation of each DOF's axis."""
        n = len(self.joints)
        world = np.empty((n, 4, 4))
        axes = np.empty((n, 3, 3))  # per bone, the world directions of its X, Y', Z'' axes
        parent = base
        for k, j in enumerate(self.joints):
            pre = parent @ self.rest_local[k]
            tr = np.eye(4)
            tr[:3, 3] = basis[j, :3, 3]
            pre = pre @ tr
            e = eul[k]
            r = pre[:3, :3]
            rx = r @ _rx(e[0])
            rxy = rx @ _ry(e[1])
            axes[k, 0] = r[:, 0]
            axes[k, 1] = rx[:, 1]
            axes[k, 2] = rxy[:, 2]
            world[k] = pre
            world[k, :3, :3] = rxy @ _rz(e[2])
            parent = world[k]
        return world, axes

    def effector(self, world):
        f = world[self.joints.index(self.tip)]
        return f[:3, :3] @ self.point + f[:3, 3], f[:3, :3]

    def jacobian(self, world, axes, target_point=None):
        """(6, n): angular (rows 0-2) and linear velocity of a point (default the effector)."""
        x = self.effector(world)[0] if target_point is None else target_point
        jac = np.zeros((6, self.n))
        for i, (k, a) in enumerate(self.dofs):
            w = axes[k, a]
            jac[:3, i] = w
            jac[3:, i] = np.cross(w, x - world[k, :3, 3])
        return jac


def damped_pinv(jac, epsilon=0.02, lam_max=0.05):
    """Damped least-squares pseudo-inverse: no damping while the smallest singular value is
    above `epsilon`, growing to `lam_max` at a singularity."""
    u, s, vt = np.linalg.svd(jac, full_matrices=False)
    smin = s[-1] if len(s) else 0.0
    lam2 = 0.0 if smin >= epsilon else lam_max ** 2 * (1.0 - (smin / epsilon) ** 2)
    return (vt.T * (s / (s ** 2 + lam2))) @ u.T


def null_space_step(jac, dx, dz=None, active=None, **kw):
    """Eq. 2-1 with joint limits: columns of inactive DOFs are zeroed (they do not move)."""
    n = jac.shape[1]
    mask = np.ones(n, bool) if active is None else active
    jm = jac * mask
    jp = damped_pinv(jm, **kw)
    dq = jp @ dx
    if dz is not None:
        dq = dq + (np.eye(n) - jp @ jm) @ (np.asarray(dz) * mask)
    return dq * mask


@dataclass
class IKResult:
    basis: np.ndarray
    theta: np.ndarray
    position_error: float
    rotation_error: float
    iterations: int


def solve(chain, basis, base, target_pos, target_rot=None, secondary=None, iterations=60,
          tol=2e-4, rot_tol=np.radians(0.1), max_step=0.08, rot_weight=0.15, theta0=None):
    """Move the chain's effector to `target_pos` (and orientation `target_rot`, a 3x3 world
    rotation) from `basis`; `base` is the world frame of the chain's parent bone.
    `secondary(theta, world, axes) -> dz` (joint space) is the null-space task."""
    theta = chain.angles(basis) if theta0 is None else np.array(theta0, float)
    pos = np.asarray(target_pos, float)
    rows = slice(0, 6) if target_rot is not None else slice(3, 6)
    it = 0
    for it in range(iterations):
        eul = chain.euler(theta, basis)
        world, axes = chain.frames(eul, basis, base)
        x, r = chain.effector(world)
        ep = pos - x
        er = rot_log(target_rot @ r.T) if target_rot is not None else np.zeros(3)
        if np.linalg.norm(ep) < tol and np.linalg.norm(er) < rot_tol and secondary is None:
            break
        norm = np.linalg.norm(ep)
        if norm > max_step:
            ep = ep * (max_step / norm)
        dx = np.concatenate((er * rot_weight, ep))[rows]
        jac = chain.jacobian(world, axes)
        jac[:3] *= rot_weight
        jac = jac[rows]
        dz = secondary(theta, world, axes) if secondary is not None else None
        active = np.ones(chain.n, bool)
        for _ in range(3):
            dq = null_space_step(jac, dx, dz, active)
            new = theta + dq
            out = ((new < chain.lower) & (dq < 0)) | ((new > chain.upper) & (dq > 0))
            if not out.any():
                break
            active &= ~out
        theta = np.clip(theta + dq, chain.lower, chain.upper)
    eul = chain.euler(theta, basis)
    world, _ = chain.frames(eul, basis, base)
    x, r = chain.effector(world)
    rerr = np.linalg.norm(rot_log(target_rot @ r.T)) if target_rot is not None else 0.0
    return IKResult(chain.apply(theta, basis), theta, float(np.linalg.norm(pos - x)), float(rerr), it + 1)


def chain_base(chain, world_all):
    p = chain.skeleton.parents[chain.joints[0]]
    return np.eye(4) if p < 0 else world_all[p]
