"""The fused time step of the flexible character: the hot loop of Simulator.run.

The reference step (Simulator.accelerations / Simulator.step) is written for reading: 60-110 small
numpy calls a step. On a 10-coordinate character each call costs about a microsecond and the
arithmetic almost nothing, so a step's time is its number of calls. Here the same equations are laid
out so a semi-implicit step on the ground is 27 calls on preallocated buffers (a LAPACK solve
among them), all in the ground plane's frame (the world frame when there is no ground or several
planes):

- The point Jacobians in body velocities, G = [I, -[y]x, B] (3P x n), and the body points y are
  linear in gamma: one product [1, gamma] . GY gives both, one more rotates them into the plane
  frame (Gq = R' G, R' = R_plane R), coordinate by coordinate: rows (x of all points, y of all, z).
- One product of [du, the y column, u, u with gamma_dot doubled] with Gq gives the points' G du
  (du: the corrector's increment, else 0), positions, velocities and v + y_dot (the velocity terms
  are w x (v_point + y_dot)) as rows of one table.
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
  (quaternion, translation) is a few dozen float operations in plain Python, cheaper than numpy
  calls on 3- and 4-vectors.
- One LAPACK Cholesky solve (dposv) a step, in place on preallocated buffers (lapack.py); the
  implicit corrector reuses its factor (dpotrs).
- Many points (Kernel.big): the products are past the point where their arithmetic, not their
  count, is the cost. M(gamma) then comes from its polynomial in gamma (sums over the points made
  once: M = sum_ab c_a c_b M_ab, c = [1, gamma]; rotation-free, since R'^T R' = I) and the
  ground's share of A from the touching points alone.

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
    # rot_list, inline (a call costs as much as a few products here)
    x2, y2, z2 = x + x, y + y, z + z
    xx, yy, zz, xy, xz, yz = x * x2, y * y2, z * z2, x * y2, x * z2, y * z2
    wx, wy, wz = w * x2, w * y2, w * z2
    return [1 - (yy + zz), xy - wz, xz + wy, xy + wz, 1 - (xx + zz), yz - wx, xz - wy, yz + wx, 1 - (xx + yy)]


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
        from .simulate import State
        sim = self.sim
        P, D, n, nz = self.P, self.D, self.n, self.nz
        P3 = 3 * P
        h = sim.settings.dt
        integrator = sim.settings.integrator
        thesis, midpoint = integrator == "thesis", integrator == "implicit"
        GY, Q, A0, limit = self.GY, self.Q, self.A0, self.limit
        big, Yp = self.big, self.Yp
        half_h_stiff = self.half_h_stiff
        T_upd = self.T_thesis if thesis else self.T_step
        T_mid = self.T_mid
        # [F (3P, plane frame, coordinate-major) | 0 (D) | z (nz) | b, then x (n), 0, Q z (D)]
        Wd = self.width                                          # G's row width: [G (n) | y | 0 (D)]
        ALL = np.zeros(P3 + D + nz + Wd)
        Fq = ALL[:P3].reshape(3, P)
        Fz = ALL[:P3 + D + nz]
        z = ALL[P3 + D:P3 + D + nz]
        ZX = ALL[P3 + D:P3 + D + nz + n]
        bx = ALL[P3 + D + nz:]
        x = bx[:n]
        qm = np.empty(D) if big else bx[n + 1:]                 # the mode forces Q z (not Qp z)
        z[0] = 1.0
        g1, gam, u, gd = z[:1 + D], z[1:1 + D], z[1 + D:], z[7 + D:]
        gam[:] = state.gamma
        u[0:3], u[3:6], gd[:] = state.v, state.w, state.gdot
        t = [float(c) for c in state.t]
        q = [float(c) for c in state.quat]
        Rl = rot_list(*q)
        # G and y in the body frame, then [Gq; E; Qp^T | Q^T] (plane frame) stacked for
        # [b, Q z] = [F, 0, z] . GQ; E (D rows of unit vectors) carries the modes' constant share A0
        # of the system matrix into the same product as Gq^T W Gq
        Gb = self.G_const.copy()
        Gb2 = Gb.reshape(3, P * Wd)
        Gb3 = Gb.reshape(3, P, Wd)
        yb = np.empty((3, P))
        zrow = P3 + D
        GQ = np.zeros((zrow + nz, Wd))
        GQ[P3 + np.arange(D), 6 + np.arange(D)] = 1.0
        GQ[zrow:, 6:n] = self.Qp.T
        if big:
            Q = Q.copy()                                         # its column 0: the PD targets
        else:
            GQ[zrow:, n + 1:] = Q.T
        Gqe = GQ[:P3].reshape(3, P * Wd)
        GqeT = Gqe.reshape(P3, Wd).T
        Gq2 = GQ[:P3, :n]
        GqA = GQ[:zrow, :n]
        Gq3 = Gq2.reshape(3, P, n)
        GQF, GQZ = GQ[:P3], GQ[zrow:]
        Fflat = Fq.reshape(-1)
        WGA = np.zeros((zrow, n))                                # [W Gq; A0 rows]
        WGA[P3 + np.arange(D), 6 + np.arange(D)] = np.diag(A0)[6:]
        WG = WGA[:P3]
        WG3 = WG.reshape(3, P, n)
        Ab = np.empty((n, n))                                   # the system matrix, then its factor
        chol = CholeskySolver(Ab, x)
        extra = [None, None, None]                              # A's general-contact, limit, ground terms
        if big:
            # many points: M(gamma) = sum m G^T G (rotation-free: R'^T R' = I) from its polynomial
            # in gamma (constant sums over the points, self.M_cc), the ground's share of A from the
            # touching points alone
            Mpoly = self.M_cc
            Mh_poly = Mpoly / h
            Mh_poly[0] += A0.ravel()                            # c_0 c_0 = 1
            MONO = np.empty((1 + D) ** 2)                       # c c
            MONO2 = MONO.reshape(1 + D, 1 + D)
            Abf = Ab.reshape(-1)
            EW = np.empty((3, P))
        # the table: rows anchors (2), G du (3, the corrector's increment), y (3), v (3), v + y_dot (3),
        # 1, contact force (3), mu f_n, the plane's distance s, a' = w x (v + y_dot) + G du / h - g
        # (3); all in the plane frame
        BIG = np.zeros((23, P))
        BIG[14] = 1.0
        VYC = BIG[2:14].reshape(4, P3)
        U3T = np.zeros((4, Wd))                                  # rows: du, the y column, u, u with 2 gamma_dot
        U3T[1, n] = 1.0
        DU = U3T[0, :n]                                          # zero but in the corrector
        U2 = U3T[2:4, :n]
        ones_twos = np.ones((2, n))
        ones_twos[1, 6:] = 2.0
        anchor, Yq, Vq, B15 = BIG[0:2], BIG[5:8], BIG[8:11], BIG[:15]
        f, fcap, cap, dist, acc = BIG[15:18], BIG[15:19], BIG[18], BIG[19], BIG[20:23]
        fnc, fB, ft = BIG[17:19], BIG[15:23], BIG[15:17]
        # one matrix FW (8 x 15) takes BIG[:15] to the contact forces, mu f_n, s and a'; stored
        # transposed, its last four rows (the v + y_dot and 1 columns: w x, the body origin, g) and
        # R' after them are what changes: one assignment a step from Python floats
        PS = np.zeros(120 + 9)
        FT = PS[:120].reshape(15, 8)
        FW = FT.T
        Rq = PS[120:].reshape(3, 3)
        FW[4, 7] = 1.0                                           # s = y_z + t_z
        FW[5:8, 2:5] = np.eye(3) / h                             # a' += G du / h: - M du / h in F
        g0, g1_, g2 = (-self.g_plane).tolist()
        mrow = self.m[None, :]
        negm = -mrow
        m_h = mrow / h
        mq_step = (self.m / h)[None, :, None]                 # the masses' weights in A / h
        mq_thesis = self.m[None, :, None]
        Rp, flat, org = self.Rp, self.flat, self.origin
        Rpl = Rp.ravel().tolist()
        contact = self.single
        turn = 0
        onesP = np.ones(P)
        k = muk = 0.0
        if contact:
            c = self.contacts
            k, cn, ct, mu = c.k, c.cn, c.ct, c.mu
            muk = mu * k
            collidesf = c.collides.astype(float)
            all_collide = bool(c.collides.all())
            for i, damping in enumerate((ct, ct, cn)):
                FW[i, 8 + i] = -damping
                FW[i, 5 + i] = -k
            FW[0, 0] = FW[1, 1] = k
            FW[3, :11] = mu * FW[2, :11]
            MV = np.zeros((2, 23))                             # a slid anchor: x_t + (f_t + ct v_t) / k
            MV[0, [5, 15, 8]] = 1.0, 1.0 / k, ct / k
            MV[1, [6, 16, 9]] = 1.0, 1.0 / k, ct / k
            ftn = np.empty(P)
            moved = np.empty((2, P))
            hk = 0.5 * h * k
            a_stick = 0.5 * ct + 0.25 * h * k                  # per h: (h/2 ct + h^2/4 k) / h
            n_stick = 0.5 * (cn - ct)
            n_slide = 0.5 * cn + 0.25 * h * k
            # (stick, slide, mass) -> the -h/2 K u multipliers (3 rows) and the weights of A / h (3);
            # taken from (touching, sliding, mass): stick = touching - sliding
            CW = np.array([[-hk, 0, 0], [-hk, 0, 0], [-hk, -hk, 0],
                           [a_stick, 0, 1 / h], [a_stick, 0, 1 / h], [a_stick + n_stick, n_slide, 1 / h]])
            CW[:, 1] -= CW[:, 0]
            # (touching, sliding, mass) rows: two tables used in turn, so the last evaluation's
            # touching points (where anchors are set) stay at hand without a copy
            SBs = (np.zeros((3, P)), np.zeros((3, P)))
            for SB in SBs:
                SB[2] = self.m
            MW = np.empty((6, P))
            KU, W3e = MW[:3], MW[3:, :, None]
            newb = np.empty(P, bool)
            slideb = np.empty(P, bool)
            scale = np.empty(P)
            tp01 = np.empty((2, 1))
            kv = np.empty((3, P))
        general = self.contacts is not None and not contact
        springs = self.springs
        ctl = sim.controller
        current = -1
        if ctl is not None:
            times = start_time + np.arange(steps) * h
            pose_now = self.schedule(times)
            pose_mid = self.schedule(times + 0.5 * h) if midpoint else None
            kpt = self.targets()

        def set_pose(index):
            GQ[zrow, 6:n] = kpt[index]
            if big:
                Q[:, 0] = kpt[index]
            else:
                GQ[zrow, n + 1:] = kpt[index]
            return index

        def evaluate(Rl, zl, time, kind):
            """b at the current z and rigid frame into bx (and Q z after it), for kind 0 (thesis: b),
            1 (predictor: (b - h/2 K u), with the system matrix (M + h/2 C + h^2/4 K) / h returned)
            or 2 (corrector: b - M du / h, du in DU). Returns (A or None, power)."""
            nonlocal turn
            # the rotation into the plane frame, the body origin in it, w in it
            if flat:
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
            a0 = Rql[0] * w0 + Rql[1] * w1 + Rql[2] * w2      # w in the plane frame
            a1 = Rql[3] * w0 + Rql[4] * w1 + Rql[5] * w2
            a2 = Rql[6] * w0 + Rql[7] * w1 + Rql[8] * w2
            # FW's columns of v + y_dot (w x) and of 1 (the body origin's share of the springs and s;
            # -g), then R'
            PS[88:] = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, a2, -a1, 0.0, 0.0, 0.0, 0.0, 0.0, -a2, 0.0, a0,
                       0.0, 0.0, 0.0, 0.0, 0.0, a1, -a0, 0.0,
                       -k * tx, -k * ty, -k * tz, -muk * tz, tz, g0, g1_, g2] + Rql
            # G, y (body), then plane frame; positions, velocities, v + y_dot
            if big:                                            # y, then the columns -[y]x and y of G
                g1.dot(Yp, out=yb.reshape(-1))
                Gb3[:, :, n] = yb
                Gb3[0, :, 4] = yb[2]
                np.negative(yb[1], out=Gb3[0, :, 5])
                np.negative(yb[2], out=Gb3[1, :, 3])
                Gb3[1, :, 5] = yb[0]
                Gb3[2, :, 3] = yb[1]
                np.negative(yb[0], out=Gb3[2, :, 4])
            else:
                g1.dot(GY, out=Gb)
            Rq.dot(Gb2, out=Gqe)
            np.multiply(u, ones_twos, out=U2)
            U3T.dot(GqeT, out=VYC)
            FW.dot(B15, out=fB)                                 # springs and dampers from the anchors; s; a'
            touching = False
            if contact:
                SB = SBs[turn]
                touchf, slidef, anchored = SB[0], SB[1], SBs[1 - turn][0]
                turn = 1 - turn
                np.less(dist, 0.0, out=touchf)
                if not all_collide:
                    np.multiply(touchf, collidesf, out=touchf)
                count = touchf.dot(onesP)                      # (np.count_nonzero wraps in Python)
                touching = count > 0
            if touching:
                if touchf.dot(anchored) < count:               # the point of entry: where it crossed the plane
                    np.greater(touchf, anchored, out=newb)
                    tp01[0, 0], tp01[1, 0] = tx, ty
                    np.copyto(anchor, Yq[0:2] + tp01, where=newb)
                    FW[0:2].dot(B15, out=ft)
                np.maximum(fnc, 0.0, out=fnc)                   # the ground only pushes
                np.multiply(fcap, touchf, out=fcap)
                np.hypot(f[0], f[1], out=ftn)
                np.greater(ftn, cap, out=slidef)
                if slidef.dot(onesP):                          # Coulomb: cap the friction force
                    np.greater(slidef, 0.0, out=slideb)
                    scale.fill(1.0)
                    np.divide(cap, ftn, out=scale, where=slideb)
                    ft[...] *= scale
                    # slide the anchor so the spring alone gives the capped force next time
                    MV[0, 14], MV[1, 14] = tx, ty
                    MV.dot(BIG, out=moved)
                    np.copyto(anchor, moved, where=slideb)
                np.multiply(acc, negm, out=Fq)                 # m (g - w x (v + y_dot) - G du / h)
                np.add(Fq, f, out=Fq)
                if kind == 1:
                    CW.dot(SB, out=MW)
                    np.multiply(Vq, KU, out=kv)                # - h/2 K u of the ground springs
                    np.add(Fq, kv, out=Fq)
            else:
                np.multiply(acc, negm, out=Fq)
                if general:
                    touching = self._general_contacts(Rq, t, Yq, Vq, Fq, kind == 1, h)
            if springs:
                Fq[:, self.spring_idx] += self._spring_forces(t, Yq, Vq, time)
            if big:
                np.add(Fflat.dot(GQF), z.dot(GQZ), out=bx)
                Q.dot(z, out=qm)
                qml = qm.tolist()
            else:
                Fz.dot(GQ, out=bx)                              # [Gq^T F + Qp z, -, Q z]
                qml = bx.tolist()[n + 1:]
            power = sum(map(abs, map(mul, qml, zl[7 + D:])))
            if kind != 1:                                       # Q z, not Qp z
                x[6:] += half_h_stiff * gd
            gl = zl[1:1 + D]
            lim = None
            if gl and (max(gl) > 1.0 or min(gl) < -1.0):
                # amplitudes live in [-1, 1] (thesis 4.3): a stiff one-sided spring beyond
                over = gam - np.clip(gam, -1.0, 1.0)
                lim = limit * (over != 0)
                x[6:] -= limit * over
                power = float(np.abs((qm - limit * over) * gd).sum())
                if kind == 1:
                    x[6:] -= 0.5 * h * lim * gd
            if big:
                np.multiply.outer(g1, g1, out=MONO2)
            if kind != 1:
                return None, power
            if big:
                extra[2] = None
                if touching and contact:                       # the ground's weights beyond m / h
                    idx = np.flatnonzero(touchf)
                    np.subtract(W3e[:, :, 0], m_h, out=EW)
                    Gt = Gq3[:, idx, :]
                    extra[2] = Gt.reshape(-1, n).T.dot((Gt * EW[:, idx, None]).reshape(-1, n))
            elif touching and contact:
                np.multiply(Gq3, W3e, out=WG3)
            else:
                np.multiply(Gq3, mq_step, out=WG3)
            extra[0] = self._general_matrix(Gq3, h) if touching and general else None
            extra[1] = lim
            return system_matrix(), power

        def system_matrix():
            """(M + h/2 C + h^2/4 K) / h into Ab from W Gq and the extra terms of the last evaluate."""
            if big:
                MONO.dot(Mh_poly, out=Abf)                      # M / h + A0
            else:
                GqA.T.dot(WGA, out=Ab)                          # Gq^T W Gq + A0
            if extra[0] is not None:
                np.add(Ab, extra[0], out=Ab)
            if extra[2] is not None:
                np.add(Ab, extra[2], out=Ab)
            if extra[1] is not None:
                Ab[6 + np.arange(D), 6 + np.arange(D)] += 0.25 * h * extra[1]
            return Ab

        def mass_matrix():
            """M at the last evaluation's gamma."""
            if big:
                MONO.dot(Mpoly, out=Abf)
                return Ab
            np.multiply(Gq3, mq_thesis, out=WG3)
            Gq2.T.dot(WG, out=Ab)
            return Ab

        def diverged(time):
            raise FlexibleError(f"the simulation diverged at {time:.3f} s: try a smaller time step, "
                                f"the implicit integrator, or softer ground/modes")

        def fallback_solve(A, b, time):
            if not (np.isfinite(A).all() and np.isfinite(b).all()):
                diverged(time)
            try:
                return np.linalg.solve(A, b)
            except np.linalg.LinAlgError:
                diverged(time)

        def current_state():
            return State(np.array(t), np.array(q), gam.copy(), u[0:3].copy(), u[3:6].copy(), gd.copy())

        every = record_every or max(steps, 1)
        chunk = max(steps // 50, 1)
        records = [snapshot(current_state(), start_time)]
        consumed, conds = 0.0, []
        ZM = np.empty(nz + 6)                                    # [z_new, rigid increment]
        ZMz = ZM[:nz]
        zl = z.tolist()
        for i in range(steps):
            time = start_time + i * h
            if ctl is not None and pose_now[i] != current:
                current = set_pose(pose_now[i])
            if thesis:
                _, power = evaluate(Rl, zl, time, 0)
                mass_matrix()
                if not chol.solve():                           # x <- M^-1 b (T_thesis scales by h)
                    x[:] = fallback_solve(mass_matrix().copy(), x, time)
            else:
                A, power = evaluate(Rl, zl, time, 1)
                factored = chol.solve()                        # x <- A^-1 x in place, A <- its factor
                if not factored:                               # a degenerate body, or numbers blew up
                    A = system_matrix().copy()
                    x[:] = fallback_solve(A, x, time)
                if midpoint:
                    # predictor u* = u + du; the implicit midpoint rule's corrector: one Newton step
                    # about the midpoint, with the predictor's matrix (its Cholesky factor reused)
                    DU[:] = x                                  # du rides in U3T: G du for - M du / h
                    z0, t0, q0 = z.copy(), t[:], q[:]
                    T_mid.dot(ZX, out=ZM)
                    z[:] = ZMz
                    zml = ZM.tolist()
                    Rm = rigid_move(q, t, zml[nz:])
                    if ctl is not None and pose_mid[i] != current:
                        current = set_pose(pose_mid[i])
                    _, power = evaluate(Rm, zml[:nz], time + 0.5 * h, 2)
                    if factored:
                        chol.resolve()                         # x <- A^-1 x with the predictor's factor
                    else:
                        x[:] = fallback_solve(A, x, time)
                    np.add(DU, x, out=x)                       # u_new - u
                    DU.fill(0.0)
                    z[:] = z0
                    t[:], q[:] = t0, q0
            T_upd.dot(ZX, out=ZM)
            z[:] = ZMz
            zml = ZM.tolist()
            zl = zml[:nz]
            Rl = rigid_move(q, t, zml[nz:])
            if not (i & 7 and i + 1 < steps) and not u.dot(u) < 1e12:
                diverged(time)                                 # also NaN (every 8 steps is soon enough)
            consumed += power * h
            if cond_every and i % cond_every == 0:
                conds.append(np.linalg.cond(mass_matrix()))
            if (i + 1) % every == 0 or i + 1 == steps:
                records.append(snapshot(current_state(), start_time + (i + 1) * h))
            if i % chunk == 0:
                yield i / max(steps, 1)
        return records, consumed, conds, current_state()

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
