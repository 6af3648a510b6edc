"""Inverse dynamics by the recursive Newton-Euler algorithm (Luh, Walker and Paul 1980; Huang
1996 appendix B), O(n), in world coordinates and vectorised over bodies.

The outward recursion (velocities and accelerations) is a sum of joint contributions over each
body's ancestors and the inward recursion (forces) a sum over each body's subtree; both are one
product with the model's ancestor matrix, so no Python loop runs over bodies.
"""

import numpy as np

from . import spatial
from .kinematics import joint_velocity_products, update_frames



def external_wrenches(model, data, q, joints, points, forces, torques=None):
    """World wrenches (nb, 6) about the origin of forces (k, 3, world) applied at points (k, 3)
    given in the frames of bones `joints` (k,), plus optional pure torques (k, 3, world)."""
    from .kinematics import point_positions
    joints = np.atleast_1d(np.asarray(joints, dtype=int))
    forces = np.asarray(forces, dtype=float).reshape(-1, 3)
    x = point_positions(model, data, q, joints, points)
    w = np.concatenate((spatial.cross(x, forces), forces), axis=1)
    if torques is not None:
        w[:, :3] += np.asarray(torques, dtype=float).reshape(-1, 3)
    out = np.zeros((model.nb, 6))
    np.add.at(out, model.joint_body[joints], w)
    return out


def world_point_wrenches(model, bodies, points, forces):
    """World wrenches (nb, 6) of forces (k, 3) acting at world points (k, 3) on bodies (k,)."""
    forces = np.asarray(forces, dtype=float).reshape(-1, 3)
    w = np.concatenate((spatial.cross(np.asarray(points, float).reshape(-1, 3), forces), forces), axis=1)
    out = np.zeros((model.nb, 6))
    np.add.at(out, np.asarray(bodies, int), w)
    return out


def rnea(model, data, q, v, a, f_ext=None, gravity=None, return_wrenches=False):
    """Generalised forces tau (nv,) with tau = H a + C + G + F.

    tau[:6] is the wrench the base would need (root axes: torque, then force); it vanishes
    for a motion that the joint torques, gravity and f_ext can produce alone. f_ext (nb, 6)
    world wrenches on bodies (see external_wrenches). With return_wrenches, also the world
    wrench (nb, 6) each body receives from its parent (index 0: from the outside world).
    """
    total = subtree_wrenches(model, data, q, v, a, f_ext, gravity)
    tau6 = (data.joint_motion.swapaxes(1, 2) @ total[:, :, None])[:, :, 0]
    tau = tau6.ravel()[model.flat_dof] + model.armature_v * a
    return (tau, total) if return_wrenches else tau


def velocity_terms(model, data, q, v):
    """Per body: world spatial velocity (nb, 6), its cross-product operator crm (nb, 6, 6) and
    the velocity-product acceleration v x (joint velocity) (nb, 6); cached in `data` for the same
    q and v (several inverse-dynamics passes of one control step share them)."""
    update_frames(model, data, q)
    v = np.asarray(v, float)
    key = v.tobytes()
    cached = data.velocity
    if cached is not None and cached[0] == key:
        return cached[1]
    u = (data.joint_motion @ model.expand(v)[:, :, None])[:, :, 0]
    vel = model.ancestors @ u
    cr = spatial.crm(vel)
    out = (vel, cr, (cr @ u[:, :, None])[:, :, 0] + joint_velocity_products(model, data, v))
    data.velocity = (key, out)
    return out


def subtree_wrenches(model, data, q, v, a, f_ext=None, gravity=None):
    """RNEA's wrenches (nb, 6): what each body receives from its parent (world, about the origin);
    tau is each DOF's motion subspace against its body's entry (plus the armature's a)."""
    vel, cr, product = velocity_terms(model, data, q, v)
    g = model.gravity if gravity is None else np.asarray(gravity, dtype=float)
    own = (data.joint_motion @ model.expand(np.asarray(a, float))[:, :, None])[:, :, 0] + product
    av = np.empty((model.nb, 6, 2))
    av[:, :, 0] = model.ancestors @ own
    av[:, 3:, 0] -= g  # gravity as an upward acceleration of the whole body (Luh et al.)
    av[:, :, 1] = vel
    ia = data.inertia @ av  # I a and the momentum I v
    f = ia[:, :, 0] - _momentum_forces(data, cr, ia)
    if f_ext is not None:
        f = f - f_ext
    return model.subtree_sum.dot(f)  # each body's subtree


def _momentum_forces(data, cr, ia):
    """crf(v) I v (nb, 6), from subtree_wrenches' I [a, v] (ia): the same for every acceleration at
    one q and v (a matrix product's columns do not mix), so remembered with the velocity terms
    (keyed on their crm, `cr`): the control step's later inverse-dynamics passes skip its product."""
    known = data.momentum_forces
    if known is not None and known[0] is cr:
        return known[1]
    out = (cr.swapaxes(1, 2) @ ia[:, :, 1:])[:, :, 0]
    data.momentum_forces = (cr, out)
    return out
