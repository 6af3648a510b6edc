"""The fused time step of the flexible character: the hot loop of Simulator.run.

The same equations as the reference step (Simulator.accelerations / Simulator.step, written for
reading, and checked against this one by tests/solver/test_flexible_kernel_paths.py), laid out as
a few products on preallocated buffers, which benchmarks/flexible.py measures several times
faster than the reference step. Everything is in the ground plane's frame (the world frame when
there is no ground or several planes):

- The point Jacobians in body velocities, G = [I, -[y]x, B] (3P x n), and the body points y are
  linear in gamma: one product [1, gamma] . GY gives both, one more rotates them into the plane
  frame (Gq = R' G, R' = R_plane R), coordinate by coordinate: rows (x of all points, y of all, z).
- One product of [du, the y column, u, u with gamma_dot doubled] with Gq gives the points' G du
  (du: the corrector's increment, else 0), positions, velocities and v + y_dot (the velocity terms
  are w x (v_point + y_dot)) as rows of one table (PointTable).
- One 8 x 15 matrix FW times that table (plus anchors and a row of ones) gives the penalty springs
  and dampers of all points (masks, not index lists), mu f_n, the height over the plane and
  w x (v_point + y_dot) + G du / h - g (so - M du / h comes with the inertial forces). What
  changes in FW (w x, the body origin) and R' share one buffer, filled from Python floats once.
- [b, Q z] = Gq^T F + [Qp, Q] z is one product of [F, 0, z] with the stacked [Gq; E; Qp^T | Q^T],
  z = [1, gamma, v, w, gamma_dot] (Q: the passive and PD mode forces, the PD targets in its
  1-column; Qp: the predictor's, with its - h/2 K u; E: see below).
- The system matrix (M + h/2 C + h^2/4 K) / h is [Gq; E]^T [W Gq; A0] in one product: in the plane
  frame the ground's stiffness and damping are diagonal per point (tangential, normal), so they are
  per-row weights W next to the masses (W itself one 6 x 3 product of (touching, sliding, mass));
  the unit rows E pick the modes' constant share A0.
- The new state and the rigid motion's increment are one product of [z, du]; the rigid motion
  (quaternion, translation: q <- q exp(phi), t += R(q exp(phi / 2)) d) is done on Python floats.
- One Cholesky solve a step (lapack.py), in place on preallocated buffers; the implicit
  corrector reuses its factor.
- Many points (Kernel.big): M(gamma) comes from its polynomial in gamma (sums over the points
  made once: M = sum_ab c_a c_b M_ab, c = [1, gamma]; rotation-free, since R'^T R' = I) and the
  ground's share of A from the touching points alone, instead of products over all points.

Everything constant during a run (the gamma polynomial of G and y, the plane frame, the mode gains,
the pose schedule of the controller) is prepared once."""

import math
from operator import mul

import numpy as np

from .body import FlexibleError, skew
from .lapack import CholeskySolver


def rigid_move(q, t, mv):
    """Move the rigid frame in place: q (w, x, y, z) and t lists; mv = body-frame translation and
    rotation vector phi (6 floats). Translate by R(q e) d with e = exp(phi / 2) (the orientation
    half way through the rotation), then q <- q e e = q exp(phi), renormalised. Returns R(q) as a
    flat list."""
    dx, dy, dz, px, py, pz = mv
    hx, hy, hz = 0.5 * px, 0.5 * py, 0.5 * pz
    angle = math.sqrt(hx * hx + hy * hy + hz * hz)
    if angle < 1e-12:
        ew, s = 1.0, 0.5
    else:
        ew, s = math.cos(0.5 * angle), math.sin(0.5 * angle) / angle
    ex, ey, ez = s * hx, s * hy, s * hz
    w, x, y, z = q
    # the half-way orientation q e
    hw = w * ew - x * ex - y * ey - z * ez
    hx = w * ex + x * ew + y * ez - z * ey
    hy = w * ey - x * ez + y * ew + z * ex
    hz = w * ez + x * ey - y * ex + z * ew
    # d rotated by it: d + 2 w (r x d) + 2 r x (r x d)
    cx, cy, cz = hy * dz - hz * dy, hz * dx - hx * dz, hx * dy - hy * dx
    t[0] += dx + 2.0 * (hw * cx + hy * cz - hz * cy)
    t[1] += dy + 2.0 * (hw * cy + hz * cx - hx * cz)
    t[2] += dz + 2.0 * (hw * cz + hx * cy - hy * cx)
    # the whole rotation: (q e) e
    w = hw * ew - hx * ex - hy * ey - hz * ez
    x = hw * ex + hx * ew + hy * ez - hz * ey
    y = hw * ey - hx * ez + hy * ew + hz * ex
    z = hw * ez + hx * ey - hy * ex + hz * ew
    norm = 1.0 / math.sqrt(w * w + x * x + y * y + z * z)
    w, x, y, z = w * norm, x * norm, y * norm, z * norm
    q[0], q[1], q[2], q[3] = w, x, y, z
    return rot_list(w, x, y, z)


def rot_list(w, x, y, z):
    """R(q) as a flat list (row-major) for a unit quaternion; the factors 2 are exact, so the
    products may be taken with 2 x instead."""
    x2, y2, z2 = x + x, y + y, z + z
    xx, yy, zz, xy, xz, yz = x * x2, y * y2, z * z2, x * y2, x * z2, y * z2
    wx, wy, wz = w * x2, w * y2, w * z2
    return [1 - (yy + zz), xy - wz, xz + wy, xy + wz, 1 - (xx + zz), yz - wx, xz - wy, yz + wx, 1 - (xx + yy)]


class Kernel:
    """Constants of the fused step for one Simulator (see the module docstring)."""

    def __init__(self, sim):
        self.sim = sim
        s = sim.settings
        body = sim.body
        P, D, n = sim.P, body.mode_count, sim.n
        self.P, self.D, self.n = P, D, n
        self.nz = nz = 1 + D + n
        h = s.dt
        # G = G0 + sum_k gamma_k G1_k and y = X0 + sum_k gamma_k B_k, coordinate-major (3, P, n + 1 + D):
        # [row i of G_p | y_p,i | 0 (room for the mode forces Q z in the product that gives b)]
        G0 = sim._rows(sim.X0, np.arange(P))                   # (P, 3, n)
        G1 = np.zeros((D, P, 3, n))
        for k in range(D):
            G1[k, :, :, 3:6] = -skew(sim.B[k])
        # many points: products past OpenBLAS's threading threshold (m n > 9216 for a matrix-vector
        # product) go to two threads and cost several times more on small data; then G is updated
        # column-wise from y instead (only its rotation columns -[y]x and y change with gamma), b
        # is taken in two parts and Q z on its own (G's rows carry no room for it)
        self.big = (1 + D) * 3 * P * (n + 1 + D) > 9000 or (3 * P + D + self.nz) * (n + 1 + D) > 9000
        self.width = Wd = n + 1 + (0 if self.big else D)
        GY = np.zeros((1 + D, 3, P, Wd))
        GY[0, :, :, :n] = G0.transpose(1, 0, 2)
        GY[1:, :, :, :n] = G1.transpose(0, 2, 1, 3)
        GY[0, :, :, n] = sim.X0.T
        GY[1:, :, :, n] = sim.B.transpose(0, 2, 1)
        self.GY = GY.reshape(1 + D, -1)
        self.G_const = GY[0].reshape(-1).copy()
        if self.big:
            # M(gamma) = sum_ab c_a c_b M_ab with c = [1, gamma] (the monomials the step makes in one
            # outer product): the Simulator's polynomial (rows 1, gamma, gamma gamma) with its
            # gamma rows in the (0, a) places and zeros in the (a, 0) ones
            M_poly = sim.M_poly
            Mab = np.zeros((1 + D, 1 + D, n * n))
            Mab[0, 0] = M_poly[0]
            Mab[0, 1:] = M_poly[1:1 + D]
            Mab[1:, 1:] = M_poly[1 + D:].reshape(D, D, n * n)
            self.M_cc = Mab.reshape((1 + D) ** 2, n * n)
        self.Yp = np.vstack([sim.X0.T.reshape(1, 3 * P), sim.B.transpose(0, 2, 1).reshape(D, 3 * P)])
        self.m = sim.m.copy()
        # mode forces: Q z = passive springs and dampers, PD (targets in column 0), limits aside
        stiff = np.asarray(sim.gains.stiffness, float).copy()
        damp = np.asarray(sim.gains.damping, float).copy()
        ctl = sim.controller
        self.kp = np.zeros(D)
        if ctl is not None:
            np.add.at(stiff, ctl.active, ctl.kp)
            np.add.at(damp, ctl.active, ctl.kd)
            np.add.at(self.kp, ctl.active, ctl.kp)
        ar = np.arange(D)
        Q = np.zeros((D, nz))
        Q[ar, 1 + ar] = -stiff
        Q[ar, 7 + D + ar] = -damp
        self.Q = Q
        # the predictor's right side is b - h/2 K u: the mode springs' share of K u, folded into Q
        Qp = Q.copy()
        Qp[ar, 7 + D + ar] -= 0.5 * h * stiff
        self.Qp = Qp
        self.half_h_stiff = 0.5 * h * stiff                      # Q z = Qp z + this * gamma_dot
        # (M + h/2 C + h^2/4 K) / h: the modes' (constant) share
        A0 = np.zeros((n, n))
        A0[6 + ar, 6 + ar] = 0.5 * damp + 0.25 * h * stiff
        self.A0 = A0
        self.limit = sim.limit_stiffness
        # the state update [z, du] -> [z_new, translation and rotation increments (6)]
        self.T_step = self._update_map(h, 0.5 * h, 1.0)            # trapezoidal / midpoint step
        self.T_thesis = self._update_map(h, h * h, h)               # du = h x: u += h x, q += h u_new
        self.T_mid = self._update_map(0.5 * h, 0.25 * h, 0.5)       # the implicit midpoint's half step
        # the plane frame: the ground plane's (e1, e2, normal) when there is one plane, else the world
        self.contacts = sim.contacts
        self.single = self.contacts is not None and self.contacts.single
        self.Rp = np.eye(3)
        self.origin = [0.0, 0.0, 0.0]
        if self.single:
            nrm = self.contacts.normals[0]
            e1 = np.cross([0.0, 1.0, 0.0], nrm) if abs(nrm[0]) < 0.9 else np.cross(nrm, [0.0, 0.0, 1.0])
            e1 /= np.linalg.norm(e1)
            self.Rp = np.array([e1, np.cross(nrm, e1), nrm])
            self.origin = (self.contacts.offsets[0] * nrm).tolist()
        self.flat = bool(np.allclose(self.Rp, np.eye(3), rtol=0, atol=0))
        self.g_plane = self.Rp @ sim.g
        self.springs = list(s.springs)
        self.spring_idx = sim.spring_idx

    def _update_map(self, a, b, c):
        """[z, du] -> [z_new, mv]: gamma += a gamma_dot + b du_gamma, u += c du, and the rigid
        increment mv = a u[:6] + b du[:6]."""
        D, n, nz = self.D, self.n, self.nz
        T = np.zeros((nz + 6, nz + n))
        T[:nz, :nz] = np.eye(nz)
        ar = np.arange(D)
        T[1 + ar, 7 + D + ar] = a
        T[1 + ar, nz + 6 + ar] = b
        T[1 + D + np.arange(n), nz + np.arange(n)] = c
        T[nz + np.arange(6), 1 + D + np.arange(6)] = a
        T[nz + np.arange(6), nz + np.arange(6)] = b
        return T

    # -- the controller's targets, prepared for the whole run -----------------------------------------
    def schedule(self, times):
        """Pose index at each time (the controller's pose_index, vectorised)."""
        ends = self.sim.controller._ends
        phase = np.asarray(times, float) % ends[-1]
        return np.minimum(np.searchsorted(ends, phase, side="right"), len(ends) - 1).tolist()

    def targets(self):
        """kp * target on the active modes, for each pose."""
        ctl = self.sim.controller
        out = np.zeros((len(ctl.poses), self.D))
        out[:, ctl.active] = self.kp[ctl.active] * ctl.poses
        return out

    # -- the run ------------------------------------------------------------------------------------
    def run(self, state, steps, start_time, record_every, cond_every, snapshot):
        """Advance a copy of `state` by `steps` steps of the Simulator's integrator; a step generator
        (yields progress in [0, 1]) returning (records, consumed energy, condition numbers, final
        State). snapshot(state, time) is recorded at the start, every `record_every` steps and at
        the end."""
        h = self.sim.settings.dt
        step = _Step(self, state)
        ctl = self.sim.controller
        pose_now = pose_mid = None
        if ctl is not None:
            times = start_time + np.arange(steps) * h
            pose_now = self.schedule(times)
            pose_mid = self.schedule(times + 0.5 * h) if step.midpoint else None
        every = record_every or max(steps, 1)
        chunk = max(steps // 50, 1)
        records = [snapshot(step.current_state(), start_time)]
        consumed, conds = 0.0, []
        for i in range(steps):
            time = start_time + i * h
            if pose_now is not None:
                step.pose(pose_now[i])
            power = step.advance(time, None if pose_mid is None else pose_mid[i])
            if not (i & 7 and i + 1 < steps) and not step.u.dot(step.u) < 1e12:
                step.diverged(time)                            # also NaN (every 8 steps is soon enough)
            consumed += power * h
            if cond_every and i % cond_every == 0:
                conds.append(np.linalg.cond(step.mass_matrix()))
            if (i + 1) % every == 0 or i + 1 == steps:
                records.append(snapshot(step.current_state(), start_time + (i + 1) * h))
            if i % chunk == 0:
                yield i / max(steps, 1)
        return records, consumed, conds, step.current_state()

    # -- general (slower) paths: several ground planes, springs (plane frame = world here) ------------
    def _general_contacts(self, Rq, t, Yq, Vq, Fq, predictor, h):
        c = self.contacts
        x = np.asarray(t) + Yq.T
        vw = Vq.T.copy()
        touching = c.forces(x, lambda idx: vw[idx])
        if touching is None:
            self._touching = None
            return False
        idx, normals, sliding, f = touching
        if predictor:
            v = vw[idx]
            vn = (v * normals).sum(axis=1)
            f = f - 0.5 * h * c.k * np.where(sliding[:, None], vn[:, None] * normals, v)
        Fq[:, idx] += f.T
        self._touching = (idx, normals, sliding)
        return True

    def _general_matrix(self, Gq3, h):
        """The touching points' share of (h/2 C + h^2/4 K) / h with a normal per point."""
        c = self.contacts
        idx, normals, sliding = self._touching
        Gc = Gq3[:, idx, :]                                   # (3, c, n)
        Gn = np.einsum("ci,icn->cn", normals, Gc)
        stick = ~sliding
        a = np.where(stick, 0.5 * c.ct + 0.25 * h * c.k, 0.0)
        wn = np.where(stick, 0.5 * (c.cn - c.ct), 0.5 * c.cn + 0.25 * h * c.k)
        return np.einsum("c,icn,icm->nm", a, Gc, Gc) + (Gn * wn[:, None]).T @ Gn

    def _spring_forces(self, t, Yq, Vq, time):
        """Springs to anchors (world), as plane-frame forces (3, S) on the spring points."""
        idx = self.spring_idx
        Rp = self.Rp
        x = np.asarray(t) + Yq[:, idx].T @ Rp                   # world = Rp^T plane
        v = Vq[:, idx].T @ Rp
        out = np.empty((len(idx), 3))
        for j, sp in enumerate(self.springs):
            anchor = sp.anchor(time) if callable(sp.anchor) else sp.anchor
            d = np.asarray(anchor, float) - x[j]
            dist = float(np.linalg.norm(d))
            direction = d / dist if dist > 1e-12 else np.zeros(3)
            out[j] = sp.stiffness * (dist - sp.rest_length) * direction - sp.damping * v[j]
        return Rp @ out.T


class PointTable:
    """The table of per-point quantities of a step, one column per point, all in the plane frame.
    Its first 15 rows are what the penalty matrix FW takes (FW.dot(inputs) -> outputs), the
    others what it gives."""

    def __init__(self, P):
        self.rows = rows = np.zeros((23, P))
        self.anchor = rows[0:2]           # the friction springs' anchors (tangential x, y)
        self.G_du = rows[2:5]             # G du: the corrector's increment at the points
        self.y = rows[5:8]                # positions from the body origin
        self.v = rows[8:11]               # velocities
        self.v_ydot = rows[11:14]         # v + y_dot (the velocity terms are w x (v + y_dot))
        rows[14] = 1.0                    # ones: the body origin's and gravity's share
        self.inputs = rows[:15]
        self.kinematics = rows[2:14]      # G du, y, v, v + y_dot: one product with the Jacobians
        self.force = rows[15:18]          # the ground's penalty force
        self.friction = rows[15:17]       # its tangential part
        self.normal = rows[17]            # its normal part
        self.normal_cap = rows[17:19]     # f_n and mu f_n
        self.force_cap = rows[15:19]      # f and mu f_n
        self.cap = rows[18]               # mu f_n: the Coulomb cap of the friction
        self.height = rows[19]            # the height over the plane
        self.accel = rows[20:23]          # a' = w x (v + y_dot) + G du / h - g
        self.outputs = rows[15:23]


class _Step:
    """The buffers and named steps of one Kernel.run (see the module docstring for the layout).

    The state lives in z = [1, gamma, v, w, gamma_dot] (`z`, views `gamma`, `u` = [v, w, gamma_dot],
    `gamma_dot`) and the rigid frame's translation `t` and quaternion `q` (lists of floats)."""

    def __init__(self, kernel, state):
        self.kernel = kernel
        sim = kernel.sim
        P, D, n, nz = kernel.P, kernel.D, kernel.n, kernel.nz
        self.P, self.D, self.n, self.nz = P, D, n, nz
        self.h = h = sim.settings.dt
        integrator = sim.settings.integrator
        self.thesis, self.midpoint = integrator == "thesis", integrator == "implicit"
        self.big = big = kernel.big
        self.T_update = kernel.T_thesis if self.thesis else kernel.T_step
        self._state_vector(state)
        self._jacobian_buffers()
        self._penalty_matrix()
        self._ground_weights()
        self.Ab = Ab = np.empty((n, n))                          # the system matrix, then its factor
        self.chol = CholeskySolver(Ab, self.x)
        self.extra = [None, None, None]                          # A's general-contact, limit, ground terms
        if big:
            # many points: M(gamma) = sum m G^T G (rotation-free: R'^T R' = I) from its polynomial
            # in gamma (constant sums over the points, kernel.M_cc), the ground's share of A from
            # the touching points alone
            self.Mpoly = kernel.M_cc
            self.Mh_poly = kernel.M_cc / h
            self.Mh_poly[0] += kernel.A0.ravel()                 # c_0 c_0 = 1
            self.MONO = np.empty((1 + D) ** 2)                   # c c
            self.MONO2 = self.MONO.reshape(1 + D, 1 + D)
            self.Abf = Ab.reshape(-1)
            self.EW = np.empty((3, P))
        self.general = kernel.contacts is not None and not kernel.single
        self.springs = kernel.springs
        self.current_pose = -1
        if sim.controller is not None:
            self.kpt = kernel.targets()
        self.ZM = np.empty(nz + 6)                               # [z_new, rigid increment]
        self.zl = self.z.tolist()
        self.turn = 0

    # -- the buffers ------------------------------------------------------------------------------------
    def _state_vector(self, state):
        """ALL = [F (3P, plane frame, coordinate-major) | 0 (D) | z (nz) | b, then x (n), 0, Q z (D)]:
        [F, 0, z] is the left factor of the product that gives b, [z, x] the state update's input."""
        P, D, n, nz = self.P, self.D, self.n, self.nz
        P3 = 3 * P
        self.width = Wd = self.kernel.width                      # G's row width: [G (n) | y | 0 (D)]
        ALL = np.zeros(P3 + D + nz + Wd)
        self.F = ALL[:P3].reshape(3, P)                          # point forces
        self.F_flat = ALL[:P3]
        self.F_z = ALL[:P3 + D + nz]
        self.z = z = ALL[P3 + D:P3 + D + nz]
        self.z_x = ALL[P3 + D:P3 + D + nz + n]
        self.bx = bx = ALL[P3 + D + nz:]
        self.x = bx[:n]                                          # b, then the solution
        self.mode_forces = np.empty(D) if self.big else bx[n + 1:]   # Q z (not Qp z)
        z[0] = 1.0
        self.one_gamma, self.gamma, self.u, self.gamma_dot = z[:1 + D], z[1:1 + D], z[1 + D:], z[7 + D:]
        self.gamma[:] = state.gamma
        self.u[0:3], self.u[3:6], self.gamma_dot[:] = state.v, state.w, state.gdot
        self.t = [float(c) for c in state.t]
        self.q = [float(c) for c in state.quat]
        self.R = rot_list(*self.q)

    def _jacobian_buffers(self):
        """G and y in the body frame, then [Gq; E; Qp^T | Q^T] (plane frame) stacked in GQ for
        [b, Q z] = [F, 0, z] . GQ; E (D rows of unit vectors) carries the modes' constant share A0
        of the system matrix into the same product as Gq^T W Gq."""
        k = self.kernel
        P, D, n, nz, Wd = self.P, self.D, self.n, self.nz, self.width
        P3 = 3 * P
        self.Gb = Gb = k.G_const.copy()
        self.Gb2 = Gb.reshape(3, P * Wd)
        self.Gb3 = Gb.reshape(3, P, Wd)
        self.yb = np.empty((3, P))
        self.zrow = zrow = P3 + D
        self.GQ = GQ = np.zeros((zrow + nz, Wd))
        GQ[P3 + np.arange(D), 6 + np.arange(D)] = 1.0
        GQ[zrow:, 6:n] = k.Qp.T
        self.Q = k.Q
        if self.big:
            self.Q = k.Q.copy()                                  # its column 0: the PD targets
        else:
            GQ[zrow:, n + 1:] = k.Q.T
        self.Gqe = GQ[:P3].reshape(3, P * Wd)
        self.GqeT = self.Gqe.reshape(P3, Wd).T
        self.Gq2 = GQ[:P3, :n]
        self.GqA = GQ[:zrow, :n]
        self.Gq3 = self.Gq2.reshape(3, P, n)
        self.GQF, self.GQZ = GQ[:P3], GQ[zrow:]
        self.WGA = WGA = np.zeros((zrow, n))                     # [W Gq; A0 rows]
        WGA[P3 + np.arange(D), 6 + np.arange(D)] = np.diag(k.A0)[6:]
        self.WG = WGA[:P3]
        self.WG3 = self.WG.reshape(3, P, n)
        # the left factor of the point kinematics: rows du, the y column, u, u with 2 gamma_dot
        self.U3T = U3T = np.zeros((4, Wd))
        U3T[1, n] = 1.0
        self.DU = U3T[0, :n]                                     # zero but in the corrector
        self.U2 = U3T[2:4, :n]
        self.ones_twos = np.ones((2, n))
        self.ones_twos[1, 6:] = 2.0
        self.table = PointTable(P)
        self.kinematics = self.table.kinematics.reshape(4, P3)

    def _penalty_matrix(self):
        """FW (8 x 15) takes the table's inputs to the contact forces, mu f_n, the height and a'.
        Stored transposed, its columns of v + y_dot (w x) and of 1 (the body origin, g) and R'
        after them are what changes: one assignment a step from Python floats (`frame_entries`)."""
        k = self.kernel
        h = self.h
        self.PS = PS = np.zeros(120 + 9)
        self.FW = FW = PS[:120].reshape(15, 8).T
        self.frame_entries = PS[88:]                             # FW[:, 11:15] transposed, then R'
        self.Rq = PS[120:].reshape(3, 3)
        FW[4, 7] = 1.0                                           # height = y_z + t_z
        FW[5:8, 2:5] = np.eye(3) / h                             # a' += G du / h: - M du / h in F
        self.g_plane = (-k.g_plane).tolist()
        m = k.m[None, :]
        self.neg_m, self.m_h = -m, m / h
        self.mq_step = (k.m / h)[None, :, None]                  # the masses' weights in A / h
        self.mq_thesis = k.m[None, :, None]
        self.Rpl = k.Rp.ravel().tolist()
        self.contact = k.single
        self.onesP = np.ones(self.P)
        self.k = self.muk = 0.0
        if not self.contact:
            return
        c = k.contacts
        self.k, cn, ct, mu = c.k, c.cn, c.ct, c.mu
        self.muk = mu * c.k
        self.collides = c.collides.astype(float)
        self.all_collide = bool(c.collides.all())
        for i, damping in enumerate((ct, ct, cn)):
            FW[i, 8 + i] = -damping
            FW[i, 5 + i] = -c.k
        FW[0, 0] = FW[1, 1] = c.k
        FW[3, :11] = mu * FW[2, :11]
        self.MV = MV = np.zeros((2, 23))                         # a slid anchor: x_t + (f_t + ct v_t) / k
        MV[0, [5, 15, 8]] = 1.0, 1.0 / c.k, ct / c.k
        MV[1, [6, 16, 9]] = 1.0, 1.0 / c.k, ct / c.k

    def _ground_weights(self):
        """(touching, sliding, mass) per point -> the ground springs' - h/2 K u multipliers (3 rows)
        and the weights W of A / h (3 rows), by one product with CW."""
        if not self.contact:
            return
        c, h, P = self.kernel.contacts, self.h, self.P
        k, cn, ct = c.k, c.cn, c.ct
        hk = 0.5 * h * k
        a_stick = 0.5 * ct + 0.25 * h * k                        # per h: (h/2 ct + h^2/4 k) / h
        n_stick = 0.5 * (cn - ct)
        n_slide = 0.5 * cn + 0.25 * h * k
        # from (stick, slide, mass), taken from (touching, sliding, mass): stick = touching - sliding
        self.CW = CW = np.array([[-hk, 0, 0], [-hk, 0, 0], [-hk, -hk, 0],
                                 [a_stick, 0, 1 / h], [a_stick, 0, 1 / h], [a_stick + n_stick, n_slide, 1 / h]])
        CW[:, 1] -= CW[:, 0]
        # (touching, sliding, mass) rows: two tables used in turn, so the last evaluation's
        # touching points (where anchors are set) stay at hand without a copy
        self.SBs = (np.zeros((3, P)), np.zeros((3, P)))
        for SB in self.SBs:
            SB[2] = self.kernel.m
        self.MW = np.empty((6, P))
        self.KU, self.W3e = self.MW[:3], self.MW[3:, :, None]
        self.new_touch = np.empty(P, bool)
        self.sliding = np.empty(P, bool)
        self.scale = np.empty(P)
        self.tp01 = np.empty((2, 1))
        self.kv = np.empty((3, P))
        self.ftn = np.empty(P)
        self.moved = np.empty((2, P))

    # -- the state ----------------------------------------------------------------------------------------
    def current_state(self):
        from .simulate import State
        u = self.u
        return State(np.array(self.t), np.array(self.q), self.gamma.copy(), u[0:3].copy(), u[3:6].copy(),
                     self.gamma_dot.copy())

    def pose(self, index):
        """The controller's targets of pose `index` into Q's PD column (if it is not there yet)."""
        if index == self.current_pose:
            return
        n, kpt = self.n, self.kpt
        self.GQ[self.zrow, 6:n] = kpt[index]
        if self.big:
            self.Q[:, 0] = kpt[index]
        else:
            self.GQ[self.zrow, n + 1:] = kpt[index]
        self.current_pose = index

    def diverged(self, time):
        raise FlexibleError(f"the simulation diverged at {time:.3f} s: try a smaller time step, "
                            f"the implicit integrator, or softer ground/modes")

    # -- one step -----------------------------------------------------------------------------------------
    def advance(self, time, mid_pose=None):
        """One step of the integrator from `time`; returns the mode power. `mid_pose`: the
        controller's pose half a step on (the implicit midpoint's corrector)."""
        x = self.x
        if self.thesis:
            _, power = self.evaluate(self.R, self.zl, time, 0)
            self.mass_matrix()
            if not self.chol.solve():                            # x <- M^-1 b (T_thesis scales by h)
                x[:] = self._fallback_solve(self.mass_matrix().copy(), x, time)
        else:
            A, power = self.evaluate(self.R, self.zl, time, 1)
            factored = self.chol.solve()                         # x <- A^-1 x in place, A <- its factor
            if not factored:                                     # a degenerate body, or numbers blew up
                A = self.system_matrix().copy()
                x[:] = self._fallback_solve(A, x, time)
            if self.midpoint:
                power = self._midpoint_corrector(time, mid_pose, A, factored)
        self._update_state(self.T_update)
        return power

    def _midpoint_corrector(self, time, mid_pose, A, factored):
        """The implicit midpoint rule's corrector: one Newton step about the midpoint of the
        predictor u* = u + du, with the predictor's matrix (its Cholesky factor reused). Leaves
        u_new - u in x and the state as it was; returns the power at the midpoint."""
        x, z, t, q = self.x, self.z, self.t, self.q
        self.DU[:] = x                                           # du rides in U3T: G du for - M du / h
        z0, t0, q0 = z.copy(), t[:], q[:]
        zml = self._update_state(self.kernel.T_mid)
        if mid_pose is not None:
            self.pose(mid_pose)
        _, power = self.evaluate(self.R, zml[:self.nz], time + 0.5 * self.h, 2)
        if factored:
            self.chol.resolve()                                  # x <- A^-1 x with the predictor's factor
        else:
            x[:] = self._fallback_solve(A, x, time)
        np.add(self.DU, x, out=x)                                # u_new - u
        self.DU.fill(0.0)
        z[:] = z0
        t[:], q[:] = t0, q0
        return power

    def _update_state(self, T):
        """[z, du] -> [z_new, rigid increment] by the update map T, then the rigid motion."""
        ZM, nz = self.ZM, self.nz
        T.dot(self.z_x, out=ZM)
        self.z[:] = ZM[:nz]
        zml = ZM.tolist()
        self.zl = zml[:nz]
        self.R = rigid_move(self.q, self.t, zml[nz:])
        return zml

    def _fallback_solve(self, A, b, time):
        if not (np.isfinite(A).all() and np.isfinite(b).all()):
            self.diverged(time)
        try:
            return np.linalg.solve(A, b)
        except np.linalg.LinAlgError:
            self.diverged(time)

    # -- the equations of motion at the current state -----------------------------------------------
    def evaluate(self, Rl, zl, time, kind):
        """b at the current z and rigid frame into bx (and Q z after it), for kind 0 (thesis: b),
        1 (predictor: (b - h/2 K u), with the system matrix (M + h/2 C + h^2/4 K) / h returned)
        or 2 (corrector: b - M du / h, du in DU). Returns (A or None, power)."""
        tx, ty = self._plane_frame(Rl, zl)
        self._point_kinematics()
        touching = self._point_forces(kind, tx, ty, time)
        power = self._generalised_forces(kind, zl)
        lim, power = self._joint_limits(kind, zl, power)
        if self.big:
            np.multiply.outer(self.one_gamma, self.one_gamma, out=self.MONO2)
        if kind != 1:
            return None, power
        self._system_weights(touching, lim)
        return self.system_matrix(), power

    def _plane_frame(self, Rl, zl):
        """R' = R_plane R, the body origin and w in the plane frame, written into FW's changing
        columns (w x; the origin's share of the springs and of the height; -g) and R'. Returns
        the origin's tangential coordinates."""
        t, org, Rpl, D = self.t, self.kernel.origin, self.Rpl, self.D
        if self.kernel.flat:
            Rql = Rl
            tx, ty, tz = t[0] - org[0], t[1] - org[1], t[2] - org[2]
        else:
            Rql = [Rpl[3 * i] * Rl[j] + Rpl[3 * i + 1] * Rl[3 + j] + Rpl[3 * i + 2] * Rl[6 + j]
                   for i in range(3) for j in range(3)]
            ox, oy, oz = t[0] - org[0], t[1] - org[1], t[2] - org[2]
            tx = Rpl[0] * ox + Rpl[1] * oy + Rpl[2] * oz
            ty = Rpl[3] * ox + Rpl[4] * oy + Rpl[5] * oz
            tz = Rpl[6] * ox + Rpl[7] * oy + Rpl[8] * oz
        w0, w1, w2 = zl[4 + D:7 + D]
        a0 = Rql[0] * w0 + Rql[1] * w1 + Rql[2] * w2            # w in the plane frame
        a1 = Rql[3] * w0 + Rql[4] * w1 + Rql[5] * w2
        a2 = Rql[6] * w0 + Rql[7] * w1 + Rql[8] * w2
        k, muk = self.k, self.muk
        g0, g1, g2 = self.g_plane
        self.frame_entries[:] = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, a2, -a1, 0.0, 0.0, 0.0, 0.0, 0.0, -a2, 0.0, a0,
                                 0.0, 0.0, 0.0, 0.0, 0.0, a1, -a0, 0.0,
                                 -k * tx, -k * ty, -k * tz, -muk * tz, tz, g0, g1, g2] + Rql
        return tx, ty

    def _point_kinematics(self):
        """G and y at gamma (body frame), Gq = R' G (plane frame), then the table's G du, y, v and
        v + y_dot, and FW's outputs (springs and dampers from the anchors, mu f_n, height, a')."""
        n, Gb3, one_gamma = self.n, self.Gb3, self.one_gamma
        if self.big:                                             # y, then the columns -[y]x and y of G
            yb = self.yb
            one_gamma.dot(self.kernel.Yp, out=yb.reshape(-1))
            Gb3[:, :, n] = yb
            Gb3[0, :, 4] = yb[2]
            np.negative(yb[1], out=Gb3[0, :, 5])
            np.negative(yb[2], out=Gb3[1, :, 3])
            Gb3[1, :, 5] = yb[0]
            Gb3[2, :, 3] = yb[1]
            np.negative(yb[0], out=Gb3[2, :, 4])
        else:
            one_gamma.dot(self.kernel.GY, out=self.Gb)
        self.Rq.dot(self.Gb2, out=self.Gqe)
        np.multiply(self.u, self.ones_twos, out=self.U2)
        self.U3T.dot(self.GqeT, out=self.kinematics)
        tab = self.table
        self.FW.dot(tab.inputs, out=tab.outputs)

    def _point_forces(self, kind, tx, ty, time):
        """The point forces F = m (g - a') + the ground's (+ its - h/2 K u in the predictor) + the
        springs'. Returns whether the ground is touched."""
        tab, F = self.table, self.F
        touching = False
        if self.contact:
            touching = self._ground_contact(tx, ty)
        np.multiply(tab.accel, self.neg_m, out=F)               # m (g - w x (v + y_dot) - G du / h)
        if touching:
            np.add(F, tab.force, out=F)
            if kind == 1:
                kv = self.kv
                self.CW.dot(self.SB, out=self.MW)
                np.multiply(tab.v, self.KU, out=kv)              # - h/2 K u of the ground springs
                np.add(F, kv, out=F)
        elif self.general:
            touching = self.kernel._general_contacts(self.Rq, self.t, tab.y, tab.v, F, kind == 1, self.h)
        if self.springs:
            F[:, self.kernel.spring_idx] += self.kernel._spring_forces(self.t, tab.y, tab.v, time)
        return touching

    def _ground_contact(self, tx, ty):
        """Which points touch the plane; new anchors where a point crossed it; the normal force
        one-sided; friction capped at mu f_n (Coulomb), the anchor slid so the spring alone gives
        the capped force next time. Returns whether any point touches."""
        tab, onesP, turn = self.table, self.onesP, self.turn
        self.SB = SB = self.SBs[turn]
        touch, sliding, anchored = SB[0], SB[1], self.SBs[1 - turn][0]
        self.turn = 1 - turn
        np.less(tab.height, 0.0, out=touch)
        if not self.all_collide:
            np.multiply(touch, self.collides, out=touch)
        count = touch.dot(onesP)
        if not count > 0:
            return False
        self.touch = touch
        anchor, friction, cap = tab.anchor, tab.friction, tab.cap
        if touch.dot(anchored) < count:                          # the point of entry: where it crossed the plane
            new, origin = self.new_touch, self.tp01
            np.greater(touch, anchored, out=new)
            origin[0, 0], origin[1, 0] = tx, ty
            np.copyto(anchor, tab.y[0:2] + origin, where=new)
            self.FW[0:2].dot(tab.inputs, out=friction)
        np.maximum(tab.normal_cap, 0.0, out=tab.normal_cap)     # the ground only pushes
        np.multiply(tab.force_cap, touch, out=tab.force_cap)
        ftn = self.ftn
        np.hypot(friction[0], friction[1], out=ftn)
        np.greater(ftn, cap, out=sliding)
        if sliding.dot(onesP):                                   # Coulomb: cap the friction force
            slides, scale, MV = self.sliding, self.scale, self.MV
            np.greater(sliding, 0.0, out=slides)
            scale.fill(1.0)
            np.divide(cap, ftn, out=scale, where=slides)
            friction[...] *= scale
            MV[0, 14], MV[1, 14] = tx, ty
            MV.dot(tab.rows, out=self.moved)
            np.copyto(anchor, self.moved, where=slides)
        return True

    def _generalised_forces(self, kind, zl):
        """b = Gq^T F + Qp z (Q z but in the predictor) into x, Q z into mode_forces; returns the
        modes' power |Q z . gamma_dot|."""
        n, D = self.n, self.D
        x, qm, bx = self.x, self.mode_forces, self.bx
        if self.big:
            np.add(self.F_flat.dot(self.GQF), self.z.dot(self.GQZ), out=bx)
            self.Q.dot(self.z, out=qm)
            qml = qm.tolist()
        else:
            self.F_z.dot(self.GQ, out=bx)                         # [Gq^T F + Qp z, -, Q z]
            qml = bx.tolist()[n + 1:]
        power = sum(map(abs, map(mul, qml, zl[7 + D:])))
        if kind != 1:                                            # Q z, not Qp z
            x[6:] += self.kernel.half_h_stiff * self.gamma_dot
        return power

    def _joint_limits(self, kind, zl, power):
        """Amplitudes live in [-1, 1] (thesis 4.3): a stiff one-sided spring beyond, its forces
        added to b. Returns (its stiffness per mode or None when no amplitude is outside, the
        modes' power with it)."""
        gl = zl[1:1 + self.D]
        if not (gl and (max(gl) > 1.0 or min(gl) < -1.0)):
            return None, power
        limit, gam, x = self.kernel.limit, self.gamma, self.x
        over = gam - np.clip(gam, -1.0, 1.0)
        lim = limit * (over != 0)
        x[6:] -= limit * over
        power = float(np.abs((self.mode_forces - limit * over) * self.gamma_dot).sum())
        if kind == 1:
            x[6:] -= 0.5 * self.h * lim * self.gamma_dot
        return lim, power

    def _system_weights(self, touching, lim):
        """The per-row weights W of Gq (masses, and the ground's stiffness and damping where it is
        touched) and A's extra terms (general contacts, joint limits, the ground on many points)."""
        contact, extra = self.contact, self.extra
        if self.big:
            extra[2] = None
            if touching and contact:                             # the ground's weights beyond m / h
                idx = np.flatnonzero(self.touch)
                np.subtract(self.W3e[:, :, 0], self.m_h, out=self.EW)
                Gt = self.Gq3[:, idx, :]
                extra[2] = Gt.reshape(-1, self.n).T.dot((Gt * self.EW[:, idx, None]).reshape(-1, self.n))
        elif touching and contact:
            np.multiply(self.Gq3, self.W3e, out=self.WG3)
        else:
            np.multiply(self.Gq3, self.mq_step, out=self.WG3)
        extra[0] = self.kernel._general_matrix(self.Gq3, self.h) if touching and self.general else None
        extra[1] = lim

    def system_matrix(self):
        """(M + h/2 C + h^2/4 K) / h into Ab from W Gq and the extra terms of the last evaluate."""
        Ab, extra = self.Ab, self.extra
        if self.big:
            self.MONO.dot(self.Mh_poly, out=self.Abf)            # M / h + A0
        else:
            self.GqA.T.dot(self.WGA, out=Ab)                     # Gq^T W Gq + A0
        if extra[0] is not None:
            np.add(Ab, extra[0], out=Ab)
        if extra[2] is not None:
            np.add(Ab, extra[2], out=Ab)
        if extra[1] is not None:
            D = self.D
            Ab[6 + np.arange(D), 6 + np.arange(D)] += 0.25 * self.h * extra[1]
        return Ab

    def mass_matrix(self):
        """M at the last evaluation's gamma."""
        if self.big:
            self.MONO.dot(self.Mpoly, out=self.Abf)
            return self.Ab
        np.multiply(self.Gq3, self.mq_thesis, out=self.WG3)
        self.Gq2.T.dot(self.WG, out=self.Ab)
        return self.Ab
