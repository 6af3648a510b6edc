"""Forward kinematics: frames, spatial velocities and accelerations of every body, points on
segments, Jacobians and the whole-body centre of mass.

Everything is vectorised over bodies: velocities are sums of joint contributions over each body's
ancestors, which is one product with the model's ancestor matrix, and frames come from a few
batched products by pointer doubling. World spatial vectors are (omega, v) at the world origin.
"""

import numpy as np

from . import spatial
from .model import Data, Model


def update_frames(model: Model, data: Data, q):
    """World frames (nb, 4, 4), spatial transforms and world inertias for configuration q; cached
    in `data` until q changes (the world inertias are computed on first use, Data.inertia)."""
    q = np.asarray(q, dtype=float)
    key = q.tobytes()  # the configuration's bytes: the cache key
    if key == data.key:
        return data
    nb = model.nb
    local = data.local
    quats = q[3:].reshape(nb, 4)
    outer = (quats[:, :, None] * quats[:, None, :]).reshape(nb, 1, 16)
    # tree_rotation @ quat_to_matrix(quats) in one product: per body, the quaternion's outer
    # product to the rotated matrix's entries (Model.tree_q2r)
    local[:nb, :3, :3] = (outer @ model.tree_q2r).reshape(nb, 3, 3)
    local[0, :3, 3] = q[:3]
    frames = local
    for a in model.doubling:
        frames = frames[a] @ frames
    frames = frames[:nb]
    data.frames = frames
    rot = frames[:, :3, :3]
    lever = frames[:, :3, 3].dot(spatial._SKEW_MAP).reshape(nb, 3, 3) @ rot
    parts = np.concatenate((rot.reshape(nb, 9), lever.reshape(nb, 9), data.zero_column), axis=1)
    # parts[:, motion_gather], laid out column by column (the products on it keep their
    # arithmetic only on that layout)
    data.motion = parts.T[model.motion_gather].T.reshape(nb, 6, 6)
    data.joint_motion = _joint_motion(model, data.motion, outer)
    data.universal_cross = None
    data.set_force_transforms(parts)  # gathered when the world inertias are first asked for
    data.subspace = None
    data.velocity = None
    data.key = key
    return data


def _joint_motion(model, motion, outer):
    """Xm (nb, 6, 6) with each universal joint's parent-side column i replaced by the world
    motion of that axis, Xm's angular block times R^T e_i (row i of the joint's rotation R, from
    the quaternions' outer products `outer` (nb, 1, 16))."""
    ub = model.universal_body
    if not len(ub):
        return motion
    out = motion.copy()
    i = model.universal_axes[:, 0]
    rows = outer[ub] @ model.universal_row  # (n_u, 1, 3): R^T e_i
    out[ub, :, i] = (motion[ub, :, :3] @ rows.swapaxes(1, 2))[:, :, 0]
    return out


def joint_contributions(model, data, v):
    """Per-body spatial velocity added by its own joint, world (nb, 6)."""
    return (data.joint_motion @ model.expand(v)[:, :, None])[:, :, 0]


def joint_velocity_products(model, data, v):
    """What a universal joint adds to the velocity-product acceleration (nb, 6), world, or 0.0
    without them: its parent-side column s_i turns with the parent, not with the bone, so
    d/dt (S qdot) has da/dt db/dt (s_i x s_k) besides the bone's own v x (S qdot)."""
    ub = model.universal_body
    if not len(ub):
        return 0.0
    if data.universal_cross is None:  # s_i x s_k depends on q alone: once per configuration
        s_i = data.joint_motion[ub, :, model.universal_axes[:, 0]]  # (n_u, 6) world (omega, v)
        s_k = data.joint_motion[ub, :, model.universal_axes[:, 1]]
        # (w_i, v_i) x (w_k, v_k) = (w_i x w_k, w_i x v_k + v_i x w_k)
        w_i, w_k = s_i[:, :3], s_k[:, :3]
        data.universal_cross = np.concatenate(
            (spatial.cross(w_i, w_k), spatial.cross(w_i, s_k[:, 3:]) + spatial.cross(s_i[:, 3:], w_k)), axis=1)
    v = np.asarray(v, float)
    out = np.zeros((model.nb, 6))
    out[ub] = (v[model.universal_v[0]] * v[model.universal_v[1]])[:, None] * data.universal_cross
    return out


def body_velocities(model, data, q, v):
    """World spatial velocities (nb, 6) of every body."""
    update_frames(model, data, q)
    return model.ancestors.dot(joint_contributions(model, data, v))


def body_accelerations(model, data, q, v, a):
    """World spatial velocities and accelerations (nb, 6) of every body (gravity not included)."""
    update_frames(model, data, q)
    u = joint_contributions(model, data, v)
    vel = model.ancestors @ u
    own = np.einsum("bij,bj->bi", data.joint_motion, model.expand(a)) \
        + np.einsum("bij,bj->bi", spatial.crm(vel), u) + joint_velocity_products(model, data, v)
    return vel, model.ancestors @ own


def joint_frames(model, data, q):
    """World frames (J, 4, 4) of every bone inside the dynamic body (identity outside it)."""
    update_frames(model, data, q)
    inside = model.joint_body >= 0
    out = np.broadcast_to(np.eye(4), model.joint_offset.shape).copy()
    out[inside] = data.frames[model.joint_body[inside]] @ model.joint_offset[inside]
    return out


def points_on_bodies(model, joints, points):
    """Bodies (k,) and body-frame points (k, 3) of points given in bones' own frames."""
    joints = np.atleast_1d(np.asarray(joints, dtype=int))
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    bodies = model.joint_body[joints]
    if np.any(bodies < 0):
        raise ValueError("a point lies on a bone outside the dynamic body")
    off = model.joint_offset[joints]
    return bodies, np.einsum("kij,kj->ki", off[:, :3, :3], points) + off[:, :3, 3]


def body_points(data, bodies, homogeneous):
    """World positions (k, 3) at data's frames of points fixed in bodies (k,), given as
    (x, y, z, 1) rows (k, 4)."""
    return np.einsum("kij,kj->ki", data.frames[bodies][:, :3, :], homogeneous)


def point_positions(model, data, q, joints, points):
    """World positions (k, 3) of points given in the frames of bones `joints`."""
    update_frames(model, data, q)
    bodies, local = points_on_bodies(model, joints, points)
    f = data.frames.take(bodies, axis=0)
    return np.einsum("kij,kj->ki", f[:, :3, :3], local) + f[:, :3, 3]


def point_velocities(model, data, q, v, joints, points):
    """World velocities (k, 3) of points on bones."""
    x = point_positions(model, data, q, joints, points)
    vel = body_velocities(model, data, q, v)[model.joint_body[np.atleast_1d(joints)]]
    return vel[:, 3:] + spatial.cross(vel[:, :3], x)


def point_accelerations(model, data, q, v, a, joints, points):
    """World accelerations (k, 3) of points on bones: a_O + alpha x x + omega x (velocity)."""
    x = point_positions(model, data, q, joints, points)
    vel, acc = body_accelerations(model, data, q, v, a)
    b = model.joint_body[np.atleast_1d(joints)]
    vel, acc = vel[b], acc[b]
    xdot = vel[:, 3:] + spatial.cross(vel[:, :3], x)
    return acc[:, 3:] + spatial.cross(acc[:, :3], x) + spatial.cross(vel[:, :3], xdot)


def motion_subspace(model, data, q):
    """World motion subspace columns (nv, 6): the spatial velocity each DOF gives its body."""
    update_frames(model, data, q)
    if data.subspace is None:  # cached with the frames (read-only: shared by every caller)
        data.subspace = data.joint_motion.swapaxes(1, 2).reshape(-1, 6).take(model.flat_dof, axis=0)
        data.subspace.flags.writeable = False
    return data.subspace


def body_jacobian(model, data, q, body):
    """(6, nv) map from v to the world spatial velocity (omega, v at the origin) of one body."""
    cols = motion_subspace(model, data, q)
    mask = model.ancestors[body][model.dof_body]
    return (cols * mask[:, None]).T


def point_jacobian(model, data, q, joint, point):
    """(3, nv) map from v to the world velocity of a point given in a bone's frame."""
    body, local = points_on_bodies(model, [joint], [point])
    x = point_positions(model, data, q, [joint], [point])[0]
    j6 = body_jacobian(model, data, q, body[0])
    return j6[3:] - spatial.skew(x) @ j6[:3]


def segment_jacobian(model, data, q, joint):
    """(6, nv) map from v to a bone's world angular velocity (rows 0-2) and the velocity of its
    head, the bone frame's origin (rows 3-5)."""
    body = model.joint_body[joint]
    x = joint_frames(model, data, q)[joint, :3, 3]
    j6 = body_jacobian(model, data, q, body)
    return np.vstack((j6[:3], j6[3:] - spatial.skew(x) @ j6[:3]))


def body_com(model, data, q):
    """World centre of mass of every body (nb, 3)."""
    update_frames(model, data, q)
    f = data.frames
    return np.einsum("bij,bj->bi", f[:, :3, :3], model.com) + f[:, :3, 3]


def center_of_mass(model, data, q):
    """Whole-body centre of mass (3,), world."""
    return model.mass @ body_com(model, data, q) / model.mass.sum()


def com_jacobian(model, data, q):
    """(3, nv) map from v to the velocity of the whole-body centre of mass.

    Column of DOF c: its motion (omega_c, v_c) moves every body below it, so the momentum it
    creates is m_sub v_c + omega_c x (m c)_sub, summed over the subtree of its body."""
    c = body_com(model, data, q)
    m = model.mass
    sub_m = model.ancestors.T @ m  # subtree masses
    sub_mc = model.ancestors.T @ (m[:, None] * c)
    cols = motion_subspace(model, data, q)
    b = model.dof_body
    lin = sub_m[b, None] * cols[:, 3:] + spatial.cross(cols[:, :3], sub_mc[b])
    return (lin / m.sum()).T


def spatial_momentum(model, data, q, v):
    """Total world spatial momentum (angular about the origin, linear) (6,)."""
    vel = body_velocities(model, data, q, v)
    return np.einsum("bij,bj->i", data.inertia, vel)


def kinetic_energy(model, data, q, v):
    vel = body_velocities(model, data, q, v)
    return 0.5 * np.einsum("bi,bij,bj->", vel, data.inertia, vel)


def potential_energy(model, data, q, gravity=None):
    g = model.gravity if gravity is None else np.asarray(gravity, float)
    return -float(model.mass @ body_com(model, data, q) @ g)


def integrate(model, q, v, dt=1.0):
    """q (+) v dt on the configuration manifold: the root moves along its own axes, every
    quaternion turns by exp of its local angular velocity (locked axes stay at zero), and a
    universal joint's angles (a, b) become (a + da, b + db): R_i(da) R R_k(db), still on its set."""
    q = np.asarray(q, dtype=float)
    v = np.asarray(v, float)
    nb = model.nb
    full = model.expand(v if dt == 1.0 else v * dt)
    out = np.empty(len(q))
    # the root's translation along its own axes
    out[:3] = q[:3] + spatial.quat_to_matrix(q[3:7]) @ full[0, 3:]
    # Kept fused (benchmarks/dynamics.py: the plain form made a closed-loop step about 10 % slower).
    # The plain formula: q <- normalize(spatial.quat_multiply(q, spatial.quat_exp(w))) per body,
    # here with quat_exp's arithmetic inlined, the products as one 2-D product of the quaternions'
    # outer products (spatial._QMUL_OUTER).
    turn = full[:, :3]
    angle = np.sqrt((turn * turn).sum(axis=1))
    half = 0.5 * angle
    small = angle < 1e-6  # sin(a/2)/a by its Taylor series there (and no division by zero)
    exp = np.empty((nb, 4))
    exp[:, 0] = np.cos(half)
    exp[:, 1:] = np.where(small, 0.5 - angle * angle / 48.0, np.sin(half) / np.maximum(angle, 1e-6))[:, None] * turn
    quats = q[3:].reshape(nb, 4)
    turned = (quats[:, :, None] * exp[:, None, :]).reshape(nb, 16).dot(spatial._QMUL_OUTER)
    ub = model.universal_body
    if len(ub):  # R_i(da) q R_k(db), the products on outer products as above
        step = v if dt == 1.0 else v * dt
        half_a, half_b = 0.5 * step[model.universal_v[0]], 0.5 * step[model.universal_v[1]]
        n = len(ub)
        left = np.zeros((n, 4))
        right = np.zeros((n, 4))
        left[:, 0], right[:, 0] = np.cos(half_a), np.cos(half_b)
        left.flat[model.universal_qi] = np.sin(half_a)
        right.flat[model.universal_qk] = np.sin(half_b)
        mid = (left[:, :, None] * quats[ub][:, None, :]).reshape(n, 16).dot(spatial._QMUL_OUTER)
        turned[ub] = (mid[:, :, None] * right[:, None, :]).reshape(n, 16).dot(spatial._QMUL_OUTER)
    out[3:] = (turned / np.sqrt((turned * turned).sum(axis=1))[:, None]).ravel()
    return out


def difference(model, q0, q1):
    """The velocity-space step v with integrate(q0, v) ~ q1 (exact for the rotations on free
    axes; for a universal joint the differences of its angles, wrapped to (-pi, pi]; the root
    translation is expressed in the root axes of q0). q0, q1 may be stacks (..., nq) (one
    batched pass over a motion's frames)."""
    q0 = np.asarray(q0, float)
    q1 = np.asarray(q1, float)
    lead = q0.shape[:-1]
    a = q0[..., 3:].reshape(lead + (model.nb, 4))
    b = q1[..., 3:].reshape(lead + (model.nb, 4))
    full = np.zeros(lead + (model.nb, 6))
    full[..., :3] = spatial.quat_log(spatial.quat_multiply(spatial.quat_conjugate(a), b))
    ub = model.universal_body
    if len(ub):
        a0, b0 = model.universal_angles(a[..., ub, :])
        a1, b1 = model.universal_angles(b[..., ub, :])
        axes = model.universal_axes
        turns = np.zeros(lead + (len(ub), 3))
        n = np.arange(len(ub))
        turns[..., n, axes[:, 0]] = _wrap(a1 - a0)
        turns[..., n, axes[:, 1]] = _wrap(b1 - b0)
        full[..., ub, :3] = turns
    if lead:
        rot = spatial.quat_to_matrix(a[..., 0, :])
        full[..., 0, 3:] = (np.swapaxes(rot, -1, -2) @ (q1[..., :3] - q0[..., :3])[..., None])[..., 0]
    else:
        full[0, 3:] = spatial.quat_to_matrix(a[0]).T @ (q1[:3] - q0[:3])
    return full.reshape(lead + (-1,))[..., model.flat_dof].copy()


def _wrap(angle):
    """Angles in (-pi, pi]."""
    return np.pi - np.mod(np.pi - angle, 2.0 * np.pi)


def batch_frames(model, qs):
    """World frames (F, nb, 4, 4) of a stack of configurations (F, nq): update_frames' products
    for every frame of a motion at once."""
    qs = np.asarray(qs, float)
    nf, nb = len(qs), model.nb
    local = np.empty((nf, nb + 1, 4, 4))
    local[:, :nb] = model.tree
    local[:, nb] = np.eye(4)
    quats = qs[:, 3:].reshape(nf, nb, 4)
    outer = (quats[..., :, None] * quats[..., None, :]).reshape(nf, nb, 1, 16)
    local[:, :nb, :3, :3] = (outer @ model.tree_q2r).reshape(nf, nb, 3, 3)
    local[:, 0, :3, 3] = qs[:, :3]
    frames = local
    for a in model.doubling:
        frames = frames[:, a] @ frames
    return frames[:, :nb]


def batch_point_positions(model, qs, joints, points):
    """World positions (F, k, 3) of points on bones (point_positions) for a stack of
    configurations (F, nq)."""
    bodies, local = points_on_bodies(model, joints, points)
    f = batch_frames(model, qs)[:, bodies]
    return np.einsum("fkij,kj->fki", f[..., :3, :3], local) + f[..., :3, 3]


def configuration_rate(model, q, v):
    """dq/dt in the embedding coordinates of q (for Runge-Kutta integration)."""
    full = model.expand(v)
    quats = np.asarray(q, float)[3:].reshape(model.nb, 4)
    out = np.empty(model.nq)
    out[:3] = spatial.quat_to_matrix(quats[0]) @ full[0, 3:]
    pure = np.concatenate((np.zeros((model.nb, 1)), full[:, :3]), axis=1)
    rate = 0.5 * spatial.quat_multiply(quats, pure)
    ub = model.universal_body
    if len(ub):  # d/dt R_i(a) R_k(b) = (da/dt e_i q + q db/dt e_k) / 2
        i, k = model.universal_axes[:, 0], model.universal_axes[:, 1]
        n = np.arange(len(ub))
        left = np.zeros((len(ub), 4))
        right = np.zeros((len(ub), 4))
        left[n, 1 + i] = full[ub, i]
        right[n, 1 + k] = full[ub, k]
        rate[ub] = 0.5 * (spatial.quat_multiply(left, quats[ub]) + spatial.quat_multiply(quats[ub], right))
    out[3:] = rate.ravel()
    return out
