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
    c, s = np.cos(e), np.sin(e)
    ca, cb, cc = c[..., 0], c[..., 1], c[..., 2]
    sa, sb, sc = s[..., 0], s[..., 1], s[..., 2]
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


def cross(a, b):
    """np.cross of (..., 3) arrays without its axis bookkeeping (a hot spot on small arrays)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    out = np.empty(np.broadcast(a, b).shape)
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


def rot_angle(r):
    """Angle (...,) of rotation matrices (..., 3, 3)."""
    c = 0.5 * (r[..., 0, 0] + r[..., 1, 1] + r[..., 2, 2] - 1.0)
    s = 0.5 * np.sqrt((r[..., 2, 1] - r[..., 1, 2]) ** 2 + (r[..., 0, 2] - r[..., 2, 0]) ** 2
                      + (r[..., 1, 0] - r[..., 0, 1]) ** 2)
    return np.arctan2(s, c)


def rot_log(r):
    """World axis-angle vector of a rotation matrix."""
    v = np.array((r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]))
    s = 0.5 * np.sqrt(v @ v)
    c = 0.5 * (r[0, 0] + r[1, 1] + r[2, 2] - 1.0)
    th = np.arctan2(s, c)
    if th < 1e-6:
        return 0.5 * v
    if th < np.pi - 1e-3:
        return v * (th / (2.0 * s))
    return Rotation.from_matrix(r).as_rotvec()  # near a half turn the skew part loses the axis


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
        self._rest_r = self.rest_local[:, :3, :3].copy()
        self._rest_t = self.rest_local[:, :3, 3].copy()
        self.n = len(self.dofs)
        self._k = np.array([k for k, _ in self.dofs], int)
        self._a = np.array([a for _, a in self.dofs], int)
        self._tip_k = self.joints.index(self.tip)
        # the damping thresholds are set for an arm (~0.6 m); a finger's Jacobian is ten times
        # smaller and would be damped everywhere, creeping to its target
        reach = sum(np.linalg.norm(self._rest_t[1:], axis=1)) + np.linalg.norm(self.point)
        self.scale = float(np.clip(reach / 0.6, 0.5, 1.0))

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
        local = matrix_xyz(eul)  # (n, 3, 3): Rx Ry Rz per bone
        bt = basis[self.joints, :3, 3]
        world = np.zeros((n, 4, 4))
        world[:, 3, 3] = 1.0
        pre = np.empty((n, 3, 3))  # each bone's rest orientation in world, before its own turn
        pr, pp = base[:3, :3], base[:3, 3]
        for k in range(n):
            r = pr @ self._rest_r[k]
            pp = pr @ self._rest_t[k] + pp + r @ bt[k]
            pr = r @ local[k]
            pre[k] = r
            world[k, :3, :3] = pr
            world[k, :3, 3] = pp
        # the world directions of each bone's X, Y' and Z'' axes (intrinsic X-Y-Z)
        axes = np.empty((n, 3, 3))
        axes[:, 0] = pre[:, :, 0]
        a = eul[:, 0]
        axes[:, 1] = pre[:, :, 1] * np.cos(a)[:, None] + pre[:, :, 2] * np.sin(a)[:, None]
        axes[:, 2] = world[:, :3, 2]
        return world, axes

    def effector(self, world):
        f = world[self._tip_k]
        return f[:3, :3] @ self.point + f[:3, 3], f[:3, :3]

    def jacobian(self, world, axes, target_point=None):
        """(6, n): angular (rows 0-2) and linear velocity of a point (default the effector)."""
        x = self.effector(world)[0] if target_point is None else target_point
        w = axes[self._k, self._a]
        jac = np.empty((6, self.n))
        jac[:3] = w.T
        jac[3:] = cross(w, x - world[self._k, :3, 3]).T
        return jac


def damped_pinv(jac, epsilon=0.02, lam_max=0.05):
    """Damped least-squares pseudo-inverse: no damping while the smallest singular value is
    above `epsilon`, growing to `lam_max` at a singularity."""
    u, s, vt = np.linalg.svd(jac, full_matrices=False)
    smin = s[-1] if len(s) else 0.0
    lam2 = 0.0 if smin >= epsilon else lam_max ** 2 * (1.0 - (smin / epsilon) ** 2)
    return (vt.T * (s / (s ** 2 + lam2))) @ u.T


def null_space_step(jac, dx, dz=None, active=None, eye=None, **kw):
    """Eq. 2-1 with joint limits: columns of inactive DOFs are zeroed (they do not move)."""
    n = jac.shape[1]
    if active is None:  # every DOF free: no masking
        jp = damped_pinv(jac, **kw)
        dq = jp @ dx
        if dz is not None:
            dz = np.asarray(dz)
            dq = dq + dz - jp @ (jac @ dz)
        return dq
    mask = active
    jm = jac * mask
    jp = damped_pinv(jm, **kw)
    dq = jp @ dx
    if dz is not None:
        dq = dq + ((np.eye(n) if eye is None else eye) - jp @ jm) @ (np.asarray(dz) * mask)
    return dq * mask


STILL = 1e-7  # radians: a step that moves no DOF more than this ends the solve
STALL = (1e-6, 1e-5)  # metres, radians: an iteration changing the errors less than this ends it


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
    eul0 = euler_xyz(basis[chain.joints, :3, :3])  # the angles the chain does not drive stay
    theta = eul0[chain._k, chain._a] if theta0 is None else np.array(theta0, float)
    pos = np.asarray(target_pos, float)
    rows = slice(0, 6) if target_rot is not None else slice(3, 6)
    eye = np.eye(chain.n)

    def pose(th):
        eul = eul0.copy()
        eul[chain._k, chain._a] = th
        return chain.frames(eul, basis, base)

    it = 0
    zero3 = np.zeros(3)
    prev = None
    for it in range(iterations):
        world, axes = pose(theta)
        x, r = chain.effector(world)
        ep = pos - x
        er = rot_log(target_rot @ r.T) if target_rot is not None else zero3
        norm, rnorm = np.sqrt(ep @ ep), np.sqrt(er @ er)
        if norm < tol and rnorm < rot_tol and secondary is None:
            break
        if secondary is None and prev is not None and abs(prev[0] - norm) < STALL[0] and abs(prev[1] - rnorm) < STALL[1]:
            break  # an unreachable target: the error no longer changes
        prev = (norm, rnorm)
        if norm > max_step:
            ep = ep * (max_step / norm)
        dx = np.concatenate((er * rot_weight, ep))[rows]
        jac = chain.jacobian(world, axes)
        jac[:3] *= rot_weight
        jac = jac[rows]
        dz = secondary(theta, world, axes) if secondary is not None else None
        active = None
        for _ in range(3):
            dq = null_space_step(jac, dx, dz, active, eye=eye, epsilon=0.02 * chain.scale, lam_max=0.05 * chain.scale)
            new = theta + dq
            out = ((new < chain.lower) & (dq < 0)) | ((new > chain.upper) & (dq > 0))
            if not out.any():
                break
            active = ~out if active is None else active & ~out
        new = np.clip(theta + dq, chain.lower, chain.upper)
        moved = np.abs(new - theta).max(initial=0.0)
        theta = new
        if moved < STILL:  # converged (or stuck at a limit): more steps would not move it
            break
    world, _ = pose(theta)
    x, r = chain.effector(world)
    rerr = np.linalg.norm(rot_log(target_rot @ r.T)) if target_rot is not None else 0.0
    return IKResult(chain.apply(theta, basis), theta, float(np.linalg.norm(pos - x)), float(rerr), it + 1)


def _below(skeleton, joints):
    """The joints and every descendant, parents first (cached per skeleton)."""
    cache = skeleton.__dict__.setdefault("_hands_below", {})
    key = tuple(sorted(set(int(j) for j in joints)))
    if key not in cache:
        below = set(key)
        for j in range(skeleton.joint_count):  # parents come before their children
            if skeleton.parents[j] in below:
                below.add(j)
        cache[key] = [j for j in range(skeleton.joint_count) if j in below]
    return cache[key]


def update_world(skeleton, basis, world, joints, armature_to_world=None):
    """World frames (..., J, 4, 4) of `basis` (..., J, 4, 4) where only `joints` differ from the
    pose whose world frames are `world`: those joints and their descendants are recomputed, the
    others copied (a hand's or a chain's share of forward kinematics, not the whole body's). A
    root among them (a control rig's spine chain can start at one) needs `armature_to_world`."""
    basis = np.asarray(basis, float)
    out = np.array(np.broadcast_to(world, basis.shape))
    rest_local, parents = skeleton.rest_local, skeleton.parents
    for j in _below(skeleton, joints):
        p = parents[j]
        if p >= 0:
            parent = out[..., p, :, :]
        elif armature_to_world is not None:
            parent = np.asarray(armature_to_world, float)
        else:
            raise ValueError("update_world needs armature_to_world to move a root")
        out[..., j, :, :] = parent @ (rest_local[j] @ basis[..., j, :, :])
    return out


def chain_base(chain, world_all):
    p = chain.skeleton.parents[chain.joints[0]]
    return np.eye(4) if p < 0 else world_all[p]
