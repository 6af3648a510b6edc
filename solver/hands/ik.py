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

import math
from dataclasses import dataclass

import numpy as np
from scipy.linalg import cho_factor, cho_solve
from scipy.spatial.transform import Rotation

from ..body_roles import sided
from ..errors import RigError
from ..vectors import cross


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
    out = np.empty(r.shape[:-1])
    out[..., 0] = np.arctan2(-r[..., 1, 2], r[..., 2, 2])
    out[..., 1] = np.arcsin(np.minimum(np.maximum(r[..., 0, 2], -1.0), 1.0))
    out[..., 2] = np.arctan2(-r[..., 0, 1], r[..., 0, 0])
    return out


def _xyz_map():
    """The 9 entries of Rx(a) Ry(b) Rz(c) as a linear map of the 27 products u_a u_b u_c, with
    u = (1, cos, sin) of each angle: one product instead of a dozen small ones."""
    m = np.zeros((3, 3, 3, 3, 3))
    one, c, s = 0, 1, 2
    terms = {(0, 0): [(1, (one, c, c))], (0, 1): [(-1, (one, c, s))], (0, 2): [(1, (one, s, one))],
             (1, 0): [(1, (c, one, s)), (1, (s, s, c))], (1, 1): [(1, (c, one, c)), (-1, (s, s, s))],
             (1, 2): [(-1, (s, c, one))],
             (2, 0): [(1, (s, one, s)), (-1, (c, s, c))], (2, 1): [(1, (s, one, c)), (1, (c, s, s))],
             (2, 2): [(1, (c, c, one))]}
    for (row, col), products in terms.items():
        for sign, (i, j, k) in products:
            m[i, j, k, row, col] = sign
    return m.reshape(27, 9)


_XYZ = _xyz_map()


def _unit_trig(e):
    """(..., 3, 3): (1, cos, sin) of each angle of (..., 3)."""
    u = np.empty(e.shape + (3,))
    u[..., 0] = 1.0
    u[..., 1] = np.cos(e)
    u[..., 2] = np.sin(e)
    return u


def _matrix_xyz(u):
    lead = u.shape[:-2]
    m = u[..., 0, :, None, None] * u[..., 1, None, :, None] * u[..., 2, None, None, :]
    return (m.reshape(lead + (27,)) @ _XYZ).reshape(lead + (3, 3))


def matrix_xyz(e):
    """Rotations (..., 3, 3) of intrinsic X-Y-Z angles (..., 3)."""
    return _matrix_xyz(_unit_trig(np.asarray(e, float)))


def rot_angle(r):
    """Angle (...,) of rotation matrices (..., 3, 3)."""
    c = 0.5 * (r[..., 0, 0] + r[..., 1, 1] + r[..., 2, 2] - 1.0)
    s = 0.5 * np.sqrt((r[..., 2, 1] - r[..., 1, 2]) ** 2 + (r[..., 0, 2] - r[..., 2, 0]) ** 2
                      + (r[..., 1, 0] - r[..., 0, 1]) ** 2)
    return np.arctan2(s, c)


def rot_log(r):
    """World axis-angle vector of a rotation matrix."""
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = r.tolist()
    vx, vy, vz = r21 - r12, r02 - r20, r10 - r01
    s = 0.5 * math.sqrt(vx * vx + vy * vy + vz * vz)
    th = math.atan2(s, 0.5 * (r00 + r11 + r22 - 1.0))
    if th < 1e-6:
        return np.array((0.5 * vx, 0.5 * vy, 0.5 * vz))
    if th < math.pi - 1e-3:
        f = th / (2.0 * s)
        return np.array((vx * f, vy * f, vz * f))
    return Rotation.from_matrix(r).as_rotvec()  # near a half turn the skew part loses the axis


def rot_log_many(r):
    """rot_log of (B, 3, 3) rotations."""
    v = np.stack((r[:, 2, 1] - r[:, 1, 2], r[:, 0, 2] - r[:, 2, 0], r[:, 1, 0] - r[:, 0, 1]), axis=1)
    s = 0.5 * np.sqrt(np.einsum("bi,bi->b", v, v))
    th = np.arctan2(s, 0.5 * (r[:, 0, 0] + r[:, 1, 1] + r[:, 2, 2] - 1.0))
    out = v * np.where(th < 1e-6, 0.5, th / (2.0 * np.maximum(s, 1e-300)))[:, None]
    for i in np.flatnonzero(th >= np.pi - 1e-3):  # near a half turn the skew part loses the axis
        out[i] = rot_log(r[i])
    return out


def chain_frames(eul, rest_r, offsets, base):
    """World frames (..., n, 4, 4) of a chain's bones and the world directions (..., n, 3, 3) of
    each bone's X, Y' and Z'' axes (intrinsic X-Y-Z), for angles eul (..., n, 3); each bone's
    head is `offsets` (..., n, 3) from its parent's (the rest offset plus the pose's
    translation), the first bone's parent frame is `base` (..., 4, 4).

    The rotations down the chain are a prefix product, taken as a scan (log2 n batched products,
    not n small ones): a chain's kinematics is a few dozen numpy calls whatever its length."""
    n = eul.shape[-2]
    u = _unit_trig(eul)
    q = rest_r @ _matrix_xyz(u)  # each bone's turn in its parent's frame
    step = 1
    while step < n:  # q[k] <- q[k - step] q[k]: products over ever longer runs ending at k
        q[..., step:, :, :] = q[..., :-step, :, :] @ q[..., step:, :, :]
        step *= 2
    base = np.asarray(base, float)
    rot = base[..., None, :3, :3] @ q  # world rotations
    before = np.concatenate((base[..., None, :3, :3], rot[..., :-1, :, :]), axis=-3)  # the parents'
    pre = before @ rest_r  # each bone's rest orientation in world, before its own turn
    world = np.zeros(rot.shape[:-2] + (4, 4))
    world[..., :3, :3] = rot
    world[..., :3, 3] = np.cumsum((before @ offsets[..., None])[..., 0], axis=-2) + base[..., None, :3, 3]
    world[..., 3, 3] = 1.0
    axes = np.empty(rot.shape)
    axes[..., 0, :] = pre[..., :, 0]
    axes[..., 1, :] = pre[..., :, 1] * u[..., 0, 1, None] + pre[..., :, 2] * u[..., 0, 2, None]
    axes[..., 2, :] = rot[..., :, 2]
    return world, axes


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
    # (all three take poses (..., J, 4, 4) and angles (..., n): one pose or a motion's frames)
    def angles(self, basis):
        eul = euler_xyz(np.asarray(basis)[..., self.joints, :3, :3])
        return eul[..., self._k, self._a]

    def euler(self, theta, basis):
        eul = euler_xyz(np.asarray(basis)[..., self.joints, :3, :3])
        eul[..., self._k, self._a] = theta
        return eul

    def apply(self, theta, basis):
        out = np.array(basis, float)
        out[..., self.joints, :3, :3] = matrix_xyz(self.euler(theta, basis))
        return out

    # --- kinematics -------------------------------------------------------------------
    def offsets(self, basis):
        """Each bone's head from its parent's frame (n, 3): rest offset plus the pose's translation."""
        return self._rest_t + (self._rest_r @ basis[self.joints][:, :3, 3, None])[:, :, 0]

    def frames(self, eul, basis, base, offsets=None):
        """World frames of the chain's bones, and the world rotation of each DOF's axis
        (`offsets`: self.offsets(basis), when the caller has them)."""
        return chain_frames(eul, self._rest_r, self.offsets(basis) if offsets is None else offsets, base)

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


def null_space_step(jac, dx, dz=None, active=None, epsilon=0.02, lam_max=0.05):
    """Eq. 2-1 with joint limits: columns of inactive DOFs are zeroed (they do not move).

    The same step as damped_pinv's, through the normal equations: J+ = J^T (J J^T + l^2 I)^-1
    (or (J^T J + l^2 I)^-1 J^T for fewer DOFs than rows), the smallest singular value from the
    eigenvalues of that small symmetric matrix and one Cholesky solve for both terms: a third
    of an SVD's numpy calls."""
    if active is not None:
        jac = jac * active
        if dz is not None:
            dz = np.asarray(dz, float) * active
    rows, n = jac.shape
    wide = n >= rows
    g = jac @ jac.T if wide else jac.T @ jac
    smin2 = np.linalg.eigvalsh(g)[0] if len(g) else 0.0
    eps2 = epsilon * epsilon
    lam2 = 0.0 if smin2 >= eps2 else lam_max ** 2 * (1.0 - max(smin2, 0.0) / eps2)
    g.flat[::len(g) + 1] += lam2
    if dz is not None:
        dz = np.asarray(dz, float)
    task = dx if dz is None else dx - jac @ dz
    try:  # (check_finite=False: a NaN goes on as LAPACK's own would)
        factor = cho_factor(g, check_finite=False)
        if wide:  # dq = J^T y with (J J^T + l^2) y = dx (- J dz for the secondary task)
            dq = jac.T @ cho_solve(factor, task, check_finite=False)
        else:
            dq = cho_solve(factor, jac.T @ task, check_finite=False)
    except np.linalg.LinAlgError:  # not positive definite to rounding (no damping on an exactly singular J): the SVD
        dq = damped_pinv(jac, epsilon, lam_max) @ task
    if dz is not None:
        dq = dq + dz
    return dq if active is None else dq * active


def null_space_steps(jac, dx, dz=None, epsilon=0.02, lam_max=0.05):
    """null_space_step (no joint-limit masking) for a batch: jac (B, r, n), dx (B, r), dz (B, n);
    each pose damped by its own smallest singular value."""
    jt = np.swapaxes(jac, 1, 2)
    rhs = dx if dz is None else dx - (jac @ dz[:, :, None])[:, :, 0]
    wide = jac.shape[2] >= jac.shape[1]
    g = jac @ jt if wide else jt @ jac
    eps2 = epsilon * epsilon
    eye = np.eye(g.shape[1])
    try:  # every smallest singular value above epsilon (the usual case): no damping, no eigenvalues
        np.linalg.cholesky(g - eps2 * eye)
    except np.linalg.LinAlgError:
        smin2 = np.maximum(np.linalg.eigvalsh(g)[:, 0], 0.0)
        g = g + np.where(smin2 >= eps2, 0.0, lam_max ** 2 * (1.0 - smin2 / eps2))[:, None, None] * eye
    if wide:
        dq = (jt @ np.linalg.solve(g, rhs[:, :, None]))[:, :, 0]
    else:
        dq = np.linalg.solve(g, jt @ rhs[:, :, None])[:, :, 0]
    return dq if dz is None else dq + dz


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

    offsets = chain.offsets(basis)

    def pose(th):
        eul = eul0.copy()
        eul[chain._k, chain._a] = th
        return chain.frames(eul, basis, base, offsets)

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
            dq = null_space_step(jac, dx, dz, active, epsilon=0.02 * chain.scale, lam_max=0.05 * chain.scale)
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


def _levels(skeleton, joints):
    """The joints and every descendant (_below) in levels: each level's parents are in an earlier
    level or outside the set, so a level is one batched product (cached per skeleton)."""
    cache = skeleton.__dict__.setdefault("_hands_levels", {})
    key = tuple(sorted(set(int(j) for j in joints)))
    if key not in cache:
        depth = {}
        for j in _below(skeleton, key):  # parents first
            p = skeleton.parents[j]
            depth[j] = depth[p] + 1 if p in depth else 0
        cache[key] = [(np.array(js), np.array([skeleton.parents[j] for j in js]))
                      for js in ([j for j in depth if depth[j] == d] for d in range(max(depth.values(), default=-1) + 1))]
    return cache[key]


def update_world(skeleton, basis, world, joints, armature_to_world=None):
    """World frames (..., J, 4, 4) of `basis` (..., J, 4, 4) where only `joints` differ from the
    pose whose world frames are `world`: those joints and their descendants are recomputed, the
    others copied (a hand's or a chain's share of forward kinematics, not the whole body's). A
    root among them (a control rig's spine chain can start at one) needs `armature_to_world`."""
    basis = np.asarray(basis, float)
    out = np.array(np.broadcast_to(world, basis.shape))
    for js, parents in _levels(skeleton, joints):
        local = skeleton.rest_local[js] @ basis[..., js, :, :]
        roots = parents < 0
        if not roots.any():
            out[..., js, :, :] = out[..., parents, :, :] @ local
            continue
        if armature_to_world is None:
            raise ValueError("update_world needs armature_to_world to move a root")
        parent = out[..., np.maximum(parents, 0), :, :]
        parent[..., roots, :, :] = np.asarray(armature_to_world, float)[..., None, :, :]
        out[..., js, :, :] = parent @ local
    return out


def chain_base(chain, world_all):
    p = chain.skeleton.parents[chain.joints[0]]
    return np.eye(4) if p < 0 else world_all[p]
