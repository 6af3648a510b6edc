"""The joint-space inertia matrix H(q) by composite rigid bodies, and the bias C + G + F.

With composite inertias Ic_b = sum of the world inertias of b's subtree, H[c, d] = S_c' Ic S_d
for DOF d on the path from the base to DOF c's body (Featherstone's CRBA); everything is one
subtree sum and two small matrix products, and single columns or blocks cost only their entries.
"""

import numpy as np

from .inverse_dynamics import rnea
from .kinematics import motion_subspace, update_frames


def composite_inertias(model, data, q):
    """World spatial inertia (nb, 6, 6) of each body's subtree, about the origin."""
    update_frames(model, data, q)
    return data.composite  # cached with the frames (read-only)


def crba(model, data, q):
    """H(q) (nv, nv): symmetric positive definite, with tau = H a + bias."""
    cols = motion_subspace(model, data, q)
    ic = composite_inertias(model, data, q)
    forces = (ic[model.dof_body] @ cols[:, :, None])[:, :, 0]
    m = forces @ cols.T  # m[c, d] = S_c' Ic_(body c) S_d, valid when d is above c
    h = np.where(model.dof_ancestor, m, m.T)
    h *= model.dof_related
    h.flat[::model.nv + 1] += model.armature_v
    return h


def inertia_block(model, data, q, rows, cols):
    """H[rows][:, cols] without building H: O(len(rows) * len(cols)) after the subtree sums.
    A single column (Oshita eq. 2.10: the torque change per unit acceleration of one DOF) is
    inertia_block(model, data, q, slice(None), [c])."""
    rows = np.arange(model.nv)[rows]
    cols = np.arange(model.nv)[cols]
    s = motion_subspace(model, data, q)
    ic = composite_inertias(model, data, q)
    br, bc = model.dof_body[rows], model.dof_body[cols]
    below = model.dof_ancestor[np.ix_(rows, cols)]  # column DOF above (or at) the row DOF's body
    # entries use the composite inertia of the deeper of the two bodies
    deep = np.where(below, br[:, None], bc[None, :])
    out = np.einsum("ri,rcij,cj->rc", s[rows], ic[deep], s[cols])
    out *= model.dof_related[np.ix_(rows, cols)]
    out += np.where(rows[:, None] == cols[None, :], model.armature_v[rows][:, None], 0.0)
    return out


def bias_forces(model, data, q, v, f_ext=None, gravity=None):
    """C + G + F: the generalised forces at zero acceleration (Coriolis and centrifugal, gravity,
    and minus the effect of external wrenches), so that tau = H a + bias."""
    return rnea(model, data, q, v, np.zeros(model.nv), f_ext=f_ext, gravity=gravity)


def gravity_forces(model, data, q, gravity=None):
    """G alone."""
    z = np.zeros(model.nv)
    return rnea(model, data, q, z, z, gravity=gravity)


def external_forces(model, data, q, f_ext):
    """F alone: -J' f_ext, the generalised forces external wrenches save the actuators."""
    z = np.zeros(model.nv)
    return rnea(model, data, q, z, z, f_ext=f_ext, gravity=np.zeros(3))
