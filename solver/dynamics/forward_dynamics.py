"""Forward dynamics: the articulated-body algorithm (Featherstone 1983), the modern O(n) form of
the Armstrong-Green method Huang uses (1996, ch. 3.4 and appendix A), for a floating base.

Armstrong and Green's coefficients K, d (angular acceleration from the hinge acceleration) and
M, f' (force on the parent from the hinge acceleration) are the articulated inertia I^A and bias
force p^A of each subtree. The inward pass works one tree depth at a time (all bodies of a depth
at once), in world coordinates so that a child's articulated inertia adds to its parent's without
a change of frame; the base is a free rigid body whose 6x6 articulated inertia is solved last.
"""

import numpy as np
from scipy.linalg import cho_factor, cho_solve

from . import spatial
from .inertia_matrix import bias_forces, crba
from .kinematics import joint_contributions, joint_velocity_products, update_frames


def aba(model, data, q, v, tau, f_ext=None, gravity=None):
    """Accelerations a (nv,) with H a + bias = tau. tau[:6] is a wrench on the base (root axes,
    usually zero); f_ext (nb, 6) world wrenches."""
    update_frames(model, data, q)
    g = model.gravity if gravity is None else np.asarray(gravity, dtype=float)
    xm = data.joint_motion
    u = joint_contributions(model, data, v)
    vel = model.ancestors @ u
    cr = spatial.crm(vel)
    c = (cr @ u[:, :, None])  # velocity-product acceleration of each joint, (nb, 6, 1)
    c[:, :, 0] += joint_velocity_products(model, data, v)
    inertia = data.inertia
    momentum = inertia @ vel[:, :, None]
    bias = -(np.swapaxes(cr, 1, 2) @ momentum) - inertia[:, :, 3:] @ g[:, None]  # (nb, 6, 1)
    if f_ext is not None:
        bias = bias - f_ext[:, :, None]
    art = inertia.copy()
    tau_full = model.expand(tau)[:, :, None]
    s = xm[:, :, :3] * model.free_mask  # joint motion subspaces, locked axes zeroed
    st = np.swapaxes(s, 1, 2)
    saved = []
    for sl, psl, to_parent in reversed(model.levels):
        ia = art[sl]
        ui = ia @ s[sl]
        dinv = np.linalg.inv(st[sl] @ ui + model.axis_pad[sl][:, :, None] * np.eye(3))
        uu = tau_full[sl, :3] - st[sl] @ bias[sl]
        ud = ui @ dinv
        ia_child = ia - ud @ np.swapaxes(ui, 1, 2)
        pa_child = bias[sl] + ia_child @ c[sl] + ud @ uu
        k = ia_child.shape[0]
        art[psl] += (to_parent @ ia_child.reshape(k, 36)).reshape(-1, 6, 6)
        bias[psl] += (to_parent @ pa_child.reshape(k, 6))[:, :, None]
        saved.append((ui, dinv, uu))
    s0 = xm[0]
    base = np.linalg.solve(s0.T @ art[0] @ s0, tau_full[0, :, 0] - s0.T @ bias[0, :, 0])
    out = np.zeros((model.nb, 6))
    out[0] = base
    acc = np.empty((model.nb, 6, 1))
    acc[0, :, 0] = s0 @ base  # the base's own velocity product is zero
    for (sl, psl, to_parent), (ui, dinv, uu) in zip(model.levels, reversed(saved)):
        ai = (to_parent.T @ acc[psl, :, 0])[:, :, None] + c[sl]
        qdd = dinv @ (uu - np.swapaxes(ui, 1, 2) @ ai)
        out[sl, :3] = qdd[:, :, 0]
        acc[sl] = ai + s[sl] @ qdd
    return out.ravel()[model.flat_dof]


def forward_dynamics_dense(model, data, q, v, tau, f_ext=None, gravity=None):
    """The same accelerations by solving H a = tau - bias with a Cholesky factorisation: O(n^3)
    but few numpy calls, so competitive for small bodies."""
    h = crba(model, data, q)
    rhs = tau - bias_forces(model, data, q, v, f_ext=f_ext, gravity=gravity)
    return cholesky_solve(h, rhs)


def cholesky_solve(a, b):
    """Solve a x = b for symmetric positive definite a by its Cholesky factorisation."""
    return cho_solve(cho_factor(a, lower=True, check_finite=False), b, check_finite=False)


def rk4_step(model, data, q, v, tau, dt, f_ext=None, gravity=None, forward=aba):
    """One classical Runge-Kutta step of q' = G(q) v, v' = forward dynamics, in the embedding
    coordinates of q with quaternions renormalised at each stage (for accurate passive motion;
    the closed-loop simulation uses a semi-implicit step)."""
    from .kinematics import configuration_rate

    def unit(x):  # back on the configuration manifold: unit quaternions, universal joints on their set
        x = x.copy()
        quats = x[3:].reshape(model.nb, 4)
        quats /= np.linalg.norm(quats, axis=1, keepdims=True)
        return model.project(x)

    def deriv(qs, vs):
        acc = forward(model, data, qs, vs, tau, f_ext=f_ext, gravity=gravity)
        return configuration_rate(model, qs, vs), acc

    k1q, k1v = deriv(q, v)
    k2q, k2v = deriv(unit(q + 0.5 * dt * k1q), v + 0.5 * dt * k1v)
    k3q, k3v = deriv(unit(q + 0.5 * dt * k2q), v + 0.5 * dt * k2v)
    k4q, k4v = deriv(unit(q + dt * k3q), v + dt * k3v)
    return (unit(q + dt / 6.0 * (k1q + 2 * k2q + 2 * k3q + k4q)),
            v + dt / 6.0 * (k1v + 2 * k2v + 2 * k3v + k4v))
