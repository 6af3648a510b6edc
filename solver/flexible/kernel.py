"""The fused time step of the flexible character: the hot loop of Simulator.run.

The reference step (Simulator.accelerations / Simulator.step) is written for reading: 60-110 small
numpy calls a step. On a 10-coordinate character each call costs about a microsecond, the arithmetic
almost nothing, so a step's time is its number of calls. Here the same equations are laid out so a
step is a few dozen calls on preallocated buffers:

- The point Jacobians in body velocities, G = [I, -[y]x, B] (3P x n), and the body-frame points y are
  linear in gamma: one product [1, gamma] . GY gives both, written straight into a buffer.
- M, the ground's stiffness and damping are all sums of G_p^T w G_p and Gn_p^T w Gn_p (Gn_p the
  normal row of a point): the system matrix of the implicit step is one product S^T (W S) of the
  stacked rows S = [Gn; G] with their weights (mass, plus the touching points' spring and damper).
- The point velocities are G u (one product); positions and velocities are rotated into the ground
  plane's frame together (one product); the penalty forces of all points come from one 3x9 matrix
  times the stacked rows (positions, velocities, anchors, 1) with masks, not index lists.
- The velocity terms (w x v + w x (w x y) + 2 w x ydot) and gravity are one product of the
  velocities with a 4x3 matrix; the mode forces (passive, PD, predictor terms) one product with
  the state vector z = [1, gamma, v, w, gamma_dot].
- The rigid motion (quaternion and translation) is a few dozen float operations in plain Python,
  cheaper than numpy calls on 3- and 4-vectors.
- One LAPACK Cholesky solve (dposv) a step; the implicit corrector reuses its factor (dpotrs).

Everything that doesn't change during a run (the gamma polynomials of G and y, the plane frame, the
mode gains, the pose schedule of the controller) is prepared once."""

import math

import numpy as np
from scipy.linalg.lapack import dposv, dpotrs

from .body import FlexibleError, skew


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
    return [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
            2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
            2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]


class Kernel:
    """Constants of the fused step for one Simulator (see the module docstring)."""

    def __init__(self, sim):
        self.sim = sim
        s = sim.settings
        body = sim.body
        P, D, n = sim.P, body.mode_count, sim.n
        self.P, self.D, self.n = P, D, n
        # G = G0 + sum_k gamma_k G1_k and y = X0 + sum_k gamma_k B_k: rows [1, gamma] of GY
        G0 = sim._rows(sim.X0, np.arange(P))
        G1 = np.zeros((D, P, 3, n))
        for k in range(D):
            G1[k, :, :, 3:6] = -skew(sim.B[k])
        GY = np.zeros((1 + D, 3 * P * n + 3 * P))
        GY[0, :3 * P * n] = G0.ravel()
        GY[1:, :3 * P * n] = G1.reshape(D, 3 * P * n)
        GY[0, 3 * P * n:] = sim.X0.ravel()
        GY[1:, 3 * P * n:] = sim.B.reshape(D, 3 * P)
        self.GY = GY
        self.Bflat = np.ascontiguousarray(sim.Bflat)
        self.m = sim.m.copy()
        self.m3 = np.repeat(sim.m, 3)[:, None]                 # per row of G
        self.mcol = sim.m[:, None]
        self.g = [float(c) for c in sim.g]
        # mode forces qm = Q z, z = [1, gamma, v, w, gamma_dot]; column 0 holds the PD targets
        stiff = np.asarray(sim.gains.stiffness, float).copy()
        damp = np.asarray(sim.gains.damping, float).copy()
        ctl = sim.controller
        self.kp = np.zeros(D)
        if ctl is not None:
            np.add.at(stiff, ctl.active, ctl.kp)
            np.add.at(damp, ctl.active, ctl.kd)
            np.add.at(self.kp, ctl.active, ctl.kp)
        self.stiff, self.damp = stiff, damp
        h = s.dt
        Q = np.zeros((2 * D, 1 + D + n))
        ar = np.arange(D)
        Q[ar, 1 + ar] = -stiff
        Q[ar, 7 + D + ar] = -damp
        # the predictor's right side b - h/2 K u: the mode springs' share of K u
        Q[D + ar, 1 + ar] = -stiff
        Q[D + ar, 7 + D + ar] = -damp - 0.5 * h * stiff
        self.Q = Q
        # M + h/2 C + h^2/4 K: the modes' (constant) share
        A0 = np.zeros((n, n))
        A0[6 + ar, 6 + ar] = 0.5 * h * damp + 0.25 * h * h * stiff
        self.A0 = A0
        self.limit = sim.limit_stiffness
        self.passive_stiffness = np.asarray(sim.gains.stiffness, float)
        # the ground: one plane (any slope) in its own frame, fast; several planes (a ledge) through
        # forces.Contacts, general
        self.plane = None
        self.contacts = sim.contacts
        if self.contacts is not None and self.contacts.single:
            c = self.contacts
            nrm = c.normals[0]
            e1 = np.cross([0.0, 1.0, 0.0], nrm) if abs(nrm[0]) < 0.9 else np.cross(nrm, [0.0, 0.0, 1.0])
            e1 /= np.linalg.norm(e1)
            e2 = np.cross(nrm, e1)
            Rp = np.array([e1, e2, nrm])                        # world -> plane frame
            self.plane = {"Rp": Rp, "flat": bool(np.allclose(Rp, np.eye(3))),
                          "Rp_list": Rp.ravel().tolist(), "origin": (c.offsets[0] * nrm).tolist(),
                          "k": c.k, "cn": c.cn, "ct": c.ct, "mu": c.mu, "collides": c.collides.copy(),
                          "all": bool(c.collides.all())}
        self.springs = list(s.springs)
        self.spring_idx = sim.spring_idx

    # -- the controller's targets, prepared for the whole run -----------------------------------------
    def schedule(self, times):
        """Pose index at each time (the controller's pose_index, vectorised)."""
        ctl = self.sim.controller
        ends = ctl._ends
        phase = np.asarray(times, float) % ends[-1]
        return np.minimum(np.searchsorted(ends, phase, side="right"), len(ends) - 1).tolist()

    def targets(self):
        """Column 0 of Q for each pose: kp * target on the active modes."""
        ctl = self.sim.controller
        out = np.zeros((len(ctl.poses), 2 * self.D))
        for i, pose in enumerate(ctl.poses):
            t = np.zeros(self.D)
            t[ctl.active] = pose
            out[i, :self.D] = self.kp * t
            out[i, self.D:] = self.kp * t
        return out

    # -- the run ------------------------------------------------------------------------------------
    def run(self, state, steps, start_time, record_every, cond_every, snapshot):
        """Advance a copy of `state` by `steps` steps of the Simulator's integrator; a step generator
        (yields progress in [0, 1]) returning (records, consumed energy, condition numbers, final
        State). snapshot(state, time) is recorded at the start, every `record_every` steps and at
        the end."""
        from .simulate import State
        sim = self.sim
        P, D, n = self.P, self.D, self.n
        h = sim.settings.dt
        integrator = sim.settings.integrator
        thesis, midpoint = integrator == "thesis", integrator == "implicit"
        GY, Bflat, Q, A0 = self.GY, self.Bflat, self.Q.copy(), self.A0
        m3, mcol, negm = self.m3, self.mcol, -self.mcol
        m3G = np.empty((3 * P, n))
        gx, gy, gz = self.g
        limit = self.limit
        # the state: z = [1, gamma, v, w, gamma_dot] (u = z[1 + D:]), the rigid frame in Python floats
        z = np.empty(1 + D + n)
        z[0] = 1.0
        g1, gam, u = z[:1 + D], z[1:1 + D], z[1 + D:]
        gd = z[7 + D:]
        gam[:] = state.gamma
        u[0:3], u[3:6], gd[:] = state.v, state.w, state.gdot
        t = [float(c) for c in state.t]
        q = [float(c) for c in state.quat]
        Rl = rot_list(*q)
        # buffers: [Gn (P x n) | G (3P x n) | y (P x 3) | point velocities (P x 3)]
        buf = np.zeros(4 * P * n + 6 * P)
        S = buf[:4 * P * n].reshape(4 * P, n)                   # stacked [Gn; G]
        Gn = buf[:P * n].reshape(P, n)
        G = buf[P * n:4 * P * n].reshape(3 * P, n)
        G3 = G.reshape(P, 3, n)
        GYout = buf[P * n:4 * P * n + 3 * P]
        y = buf[4 * P * n:4 * P * n + 3 * P].reshape(P, 3)
        vel = buf[4 * P * n + 3 * P:]
        vel3 = vel.reshape(P, 3)
        YVt = buf[4 * P * n:].reshape(2 * P, 3).T               # (3, 2P): positions then velocities
        c4 = np.ones((P, 4))                                    # [velocity + y_dot, 1]
        c3 = c4[:, :3]
        W43 = np.zeros((4, 3))
        W4 = np.empty((4 * P, 1))
        W4G = W4[P:].reshape(P, 3)
        ydot = np.empty(3 * P)
        ydot3 = ydot.reshape(P, 3)
        # the ground plane (fast path)
        pl = self.plane
        if pl is not None:
            Rp, flat, Rpl, org = pl["Rp"], pl["flat"], pl["Rp_list"], pl["origin"]
            k, cn, ct, mu = pl["k"], pl["cn"], pl["ct"], pl["mu"]
            collides, all_collide = pl["collides"], pl["all"]
            C9 = np.zeros((9, P))                               # x0 v0 x1 v1 x2 v2 a0 a1 1
            C9[8] = 1.0
            XV = C9[:6].reshape(3, 2 * P)
            Xt, Vt, Vall, anchor = C9[0:3:2], C9[1:4:2], C9[1:6:2], C9[6:8]
            Fm = np.zeros((3, 9))
            Fm[0, [0, 1, 6]] = -k, -ct, k
            Fm[1, [2, 3, 7]] = -k, -ct, k
            Fm[2, [4, 5]] = -k, -cn
            tp01 = np.empty((2, 1))
            anchored = np.zeros(P, bool)
            touch = np.empty(P, bool)
            sliding = np.empty(P, bool)
            stick = np.empty(P, bool)
            scale = np.empty(P)
            corr = np.empty((3, P))
            a_stick = 0.5 * h * ct + 0.25 * h * h * k             # weights of G^T G and Gn^T Gn
            n_stick = 0.5 * h * (cn - ct)
            n_slide = 0.5 * h * cn + 0.25 * h * h * k
            hk = 0.5 * h * k
        general = self.contacts is not None and pl is None
        springs = self.springs
        ctl = sim.controller
        if ctl is not None:
            times = start_time + np.arange(steps) * h
            pose_now = self.schedule(times)
            pose_mid = self.schedule(times + 0.5 * h) if midpoint else None
            qcols = self.targets()
            current = -1

        def set_pose(index):
            Q[:, 0] = qcols[index]
            return index

        def evaluate(Rl, time, kind, du=None):
            """The right side at the current z and rigid frame: kind 0 = b (thesis), 1 = the
            predictor's h (b - h/2 K u) with the system matrix A, 2 = the corrector's
            h b - M du. Returns (rhs, A or None, power)."""
            np.dot(g1, GY, out=GYout)                     # G and y
            np.dot(G, u, out=vel)                         # point velocities, body frame
            R = np.array(Rl).reshape(3, 3)
            touching = False
            fb = None
            if pl is not None:
                tx, ty, tz = t[0] - org[0], t[1] - org[1], t[2] - org[2]
                if flat:
                    Rq = R
                    tp0, tp1, tp2 = tx, ty, tz
                else:
                    Rq = Rp.dot(R)
                    tp0 = Rpl[0] * tx + Rpl[1] * ty + Rpl[2] * tz
                    tp1 = Rpl[3] * tx + Rpl[4] * ty + Rpl[5] * tz
                    tp2 = Rpl[6] * tx + Rpl[7] * ty + Rpl[8] * tz
                np.dot(Rq, YVt, out=XV)                   # plane-frame positions and velocities
                np.less(C9[4], -tp2, out=touch)
                if not all_collide:
                    np.logical_and(touch, collides, out=touch)
                if np.count_nonzero(touch):
                    touching = True
                    tp01[0, 0], tp01[1, 0] = tp0, tp1
                    new = np.greater(touch, anchored)
                    if np.count_nonzero(new):            # the point of entry: where it crossed the plane
                        np.copyto(anchor, Xt + tp01, where=new)
                    Fm[:, 8] = -k * tp0, -k * tp1, -k * tp2
                    f = Fm.dot(C9)                        # -k (x - anchor) - damping v, plane frame
                    fn = f[2]
                    np.maximum(fn, 0.0, out=fn)           # the ground only pushes
                    f *= touch
                    ftn = np.hypot(f[0], f[1])
                    cap = fn * mu
                    np.greater(ftn, cap, out=sliding)
                    slides = np.count_nonzero(sliding)
                    if slides:                            # Coulomb: cap the friction force
                        scale.fill(1.0)
                        np.divide(cap, ftn, out=scale, where=sliding)
                        f[0:2] *= scale
                        # slide the anchor so the spring alone gives the capped force next time
                        moved = (Xt + tp01) + (f[0:2] + ct * Vt) * (1.0 / k)
                        np.copyto(anchor, moved, where=sliding)
                    anchored[:] = touch
                    if kind == 1:
                        # - h/2 K u: sticking points' springs in all directions, sliding ones' along n
                        np.greater(touch, sliding, out=stick)
                        np.multiply(Vall, -hk, out=corr)
                        corr[0:2] *= stick
                        corr[2] *= touch
                        f += corr
                    fb = f.T.dot(Rq)                      # body frame
                elif np.count_nonzero(anchored):
                    anchored[:] = False
            elif general:
                fb, cinfo = self._general_contacts(R, t, y, vel3, kind == 1, h)
                touching = cinfo is not None
            # velocity terms and gravity: m (g_body - w x (v_point + y_dot))
            np.dot(gd, Bflat, out=ydot)
            np.add(vel3, ydot3, out=c3)
            w0, w1, w2 = u[3:6].tolist()
            W43[0, 1], W43[0, 2] = w2, -w1
            W43[1, 0], W43[1, 2] = -w2, w0
            W43[2, 0], W43[2, 1] = w1, -w0
            W43[3] = (-(Rl[0] * gx + Rl[3] * gy + Rl[6] * gz), -(Rl[1] * gx + Rl[4] * gy + Rl[7] * gz),
                      -(Rl[2] * gx + Rl[5] * gy + Rl[8] * gz))
            F = c4.dot(W43)
            F *= negm
            if fb is not None:
                F += fb
            if springs:
                F[self.spring_idx] += self._spring_forces(R, t, y, vel3, time)
            if kind == 2:
                F *= h
                F -= mcol * G.dot(du).reshape(P, 3)       # - M du = - G^T m G du
            b = F.reshape(-1).dot(G)
            qm2 = Q.dot(z)
            qm = qm2[:D]
            lim = None
            gl = gam.tolist()
            if gl and (max(gl) > 1.0 or min(gl) < -1.0):
                # amplitudes live in [-1, 1] (thesis 4.3): a stiff one-sided spring beyond
                over = gam - np.clip(gam, -1.0, 1.0)
                lim = limit * (over != 0)
                qm = qm - limit * over
                qm2 = qm2 - np.concatenate([limit * over, limit * over + 0.5 * h * lim * gd])
            power = 0.0
            for a_, b_ in zip(qm.tolist(), gd.tolist()):
                power += abs(a_ * b_)
            if kind == 0:
                b[6:] += qm
                return b, None, power
            if kind == 2:
                b[6:] += h * qm
                return b, None, power
            b[6:] += qm2[D:]
            b *= h
            # the system matrix M + h/2 C + h^2/4 K = S^T W S + modes
            if touching and pl is not None:
                np.dot(Rq[2], G3, out=Gn)                 # normal rows n_body^T G_p
                W4[:P, 0] = stick * n_stick + sliding * n_slide
                W4G[:] = (mcol + a_stick * stick[:, None])
                A = S.T.dot(S * W4)
            elif touching:
                A = self._general_matrix(S, Gn, G3, W4, W4G, cinfo, h)
            else:
                np.multiply(G, m3, out=m3G)
                A = G.T.dot(m3G)
            A += A0
            if lim is not None:
                A[6 + np.arange(D), 6 + np.arange(D)] += 0.25 * h * h * lim
            return b, A, power

        def mass_matrix():
            np.multiply(G, m3, out=m3G)
            return G.T.dot(m3G)

        def diverged(time):
            raise FlexibleError(f"the simulation diverged at {time:.3f} s: try a smaller time step, "
                                f"the implicit integrator, or softer ground/modes")

        def current_state():
            return State(np.array(t), np.array(q), gam.copy(), u[0:3].copy(), u[3:6].copy(), gd.copy())

        every = record_every or max(steps, 1)
        chunk = max(steps // 50, 1)
        records = [snapshot(current_state(), start_time)]
        consumed, conds = 0.0, []
        for i in range(steps):
            time = start_time + i * h
            if ctl is not None and pose_now[i] != current:
                current = set_pose(pose_now[i])
            if thesis:
                b, _, power = evaluate(Rl, time, 0)
                M = mass_matrix()
                c, x, info = dposv(M, b, lower=0, overwrite_a=1, overwrite_b=0)
                if info:
                    x = np.linalg.solve(mass_matrix(), b)
                x *= h
                u += x                                     # u_new = u + h M^-1 b
                mv = u.tolist()
                gam += h * gd
                Rl = rigid_move(q, t, [h * c_ for c_ in mv[:6]])
            else:
                b, A, power = evaluate(Rl, time, 1)
                c, du, info = dposv(A, b, lower=0, overwrite_a=1, overwrite_b=1)
                if info:
                    raise FlexibleError(f"the system matrix lost positive definiteness at {time:.3f} s")
                if midpoint:
                    # predictor u* = u + du; the implicit midpoint rule's corrector: one Newton step
                    # about the midpoint, with the predictor's matrix (its Cholesky factor reused)
                    z0, t0, q0 = z.copy(), t[:], q[:]
                    half = du * 0.5
                    half += u                              # (u + u*) / 2
                    gam += (0.5 * h) * half[6:]
                    mv = (0.5 * h * half[:6]).tolist()
                    u[:] = half
                    Rm = rigid_move(q, t, mv)
                    if ctl is not None and pose_mid[i] != current:
                        current = set_pose(pose_mid[i])
                    bp, _, power = evaluate(Rm, time + 0.5 * h, 2, du)
                    fix, info = dpotrs(c, bp, lower=0, overwrite_b=1)
                    du += fix                              # u_new - u
                    z[:] = z0
                    t[:], q[:] = t0, q0
                half = du * 0.5
                half += u
                gam += h * half[6:]
                u += du
                Rl = rigid_move(q, t, (h * half[:6]).tolist())
            if not u.dot(u) < 1e12:                        # also NaN: stops before numbers overflow
                diverged(time)
            consumed += power * h
            if cond_every and i % cond_every == 0:
                conds.append(np.linalg.cond(mass_matrix()))
            if (i + 1) % every == 0 or i + 1 == steps:
                records.append(snapshot(current_state(), start_time + (i + 1) * h))
            if i % chunk == 0:
                yield i / max(steps, 1)
        return records, consumed, conds, current_state()

    # -- general (slower) paths: several ground planes, springs ---------------------------------------
    def _general_contacts(self, R, t, y, vel3, predictor, h):
        c = self.contacts
        x = np.asarray(t) + y @ R.T
        vw = vel3 @ R.T
        touching = c.forces(x, lambda idx: vw[idx])
        if touching is None:
            return None, None
        idx, normals, sliding, f = touching
        fb = np.zeros((self.P, 3))
        if predictor:
            v = vw[idx]
            vn = (v * normals).sum(axis=1)
            stick = ~sliding
            f = f - 0.5 * h * c.k * np.where(stick[:, None], v, vn[:, None] * normals)
        fb[idx] = f @ R
        return fb, (idx, normals @ R, sliding)

    def _general_matrix(self, S, Gn, G3, W4, W4G, cinfo, h):
        c = self.contacts
        idx, nb, sliding = cinfo
        Gn[:] = 0.0
        Gn[idx] = (G3[idx] * nb[:, :, None]).sum(axis=1)
        W4[:] = 0.0
        stick = ~sliding
        W4[idx, 0] = np.where(stick, 0.5 * h * (c.cn - c.ct), 0.5 * h * c.cn + 0.25 * h * h * c.k)
        W4G[:] = self.mcol
        W4G[idx] += np.where(stick, 0.5 * h * c.ct + 0.25 * h * h * c.k, 0.0)[:, None]
        return S.T.dot(S * W4)

    def _spring_forces(self, R, t, y, vel3, time):
        idx = self.spring_idx
        x = np.asarray(t) + y[idx] @ R.T
        v = vel3[idx] @ R.T
        out = np.empty((len(idx), 3))
        for j, sp in enumerate(self.springs):
            anchor = sp.anchor(time) if callable(sp.anchor) else sp.anchor
            d = np.asarray(anchor, float) - x[j]
            dist = float(np.linalg.norm(d))
            direction = d / dist if dist > 1e-12 else np.zeros(3)
            out[j] = sp.stiffness * (dist - sp.rest_length) * direction - sp.damping * v[j]
        return out @ R
