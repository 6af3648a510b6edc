"""Integrating the flexible character (thesis §4.8): each step solves M u_dot = b with
b = Q + velocity terms (eq. 4.21).

Integrators:
- "thesis": the explicit scheme of eq. 4.22-4.23 (finite differences: q_n - 2 q_{n-1} + q_{n-2}
  = dt^2 q_dd, so q_dot_n = q_dot_{n-1} + dt q_dd and q_n = q_{n-1} + dt q_dot_n).
- "implicit" (default): the implicit midpoint rule, solved by a linearly implicit trapezoidal
  predictor (M + dt/2 C + dt^2/4 K) du = dt (b - dt/2 K u) and one Newton corrector about the
  predicted midpoint, where K and C are the stiffness and damping of the stiff forces (modes, PD
  controllers, ground springs and dampers). The corrector is a simplified Newton step: it reuses
  the predictor's matrix (its Cholesky factor), so it costs a second evaluation of the forces but
  no second matrix and factorisation; the energy is kept as with the full Newton step (drift
  0.007 % over the 10 s tumbling test at 5 ms, 0.04 % at 10 ms, 0.3 % at 20 ms). It adds no
  numerical damping and stays stable with stiff modes and ground at steps where the thesis
  scheme blows up.
- "semi_implicit": the predictor alone (one evaluation per step, about half the cost): as stable
  with stiff forces, but the velocity terms are explicit, so a tumbling body gains energy (6 % in
  the same test); meant for the many forward simulations of the annealing.

Simulator.run takes its steps with the fused kernel (kernel.py): the same equations as
accelerations()/step() below (the readable reference, kept for checking it: reference_run()),
laid out as a few products on preallocated buffers (benchmarks/flexible.py measures the kernel's
speed-up over the reference). The condition number of M is sampled every `cond_every` steps
(§4.10.3)."""

from dataclasses import dataclass, field

import math

import numpy as np
from scipy.linalg import cho_factor, cho_solve

from ..progress import run_to_end
from .body import FlexibleError, check_modes, quat_from_rotvec, quat_matrix, quat_multiply, skew
from .forces import GRAVITY, Contacts, ModeGains
from .kernel import Kernel

INTEGRATORS = ("implicit", "semi_implicit", "thesis")
DEFAULT_DT = 0.005


@dataclass
class State:
    t: np.ndarray
    quat: np.ndarray
    gamma: np.ndarray
    v: np.ndarray          # body-frame velocity of the body origin
    w: np.ndarray          # body-frame angular velocity
    gdot: np.ndarray

    @classmethod
    def rest(cls, modes, t=(0, 0, 0), quat=(1, 0, 0, 0)):
        return cls(np.asarray(t, float).copy(), np.asarray(quat, float).copy(), np.zeros(modes),
                   np.zeros(3), np.zeros(3), np.zeros(modes))

    def world_velocity(self):
        return quat_matrix(self.quat) @ self.v

    def copy(self):
        return State(*(np.array(a, float) for a in (self.t, self.quat, self.gamma, self.v, self.w, self.gdot)))

    @property
    def u(self):
        return np.concatenate([self.v, self.w, self.gdot])


@dataclass
class Settings:
    dt: float = DEFAULT_DT
    integrator: str = "implicit"
    gravity: tuple = tuple(GRAVITY)
    ground: object = None              # forces.Ground or None
    springs: list = field(default_factory=list)
    cond_every: int = 10
    cond_limit: float = 1e8
    check_modes: bool = True


class Controller:
    """PD control of the active modes towards the current pose of a cyclic pose graph (ch. 5):
    Qr = -(C (gamma - gamma0) + D gamma_dot)."""

    def __init__(self, active, poses, durations, kp, kd):
        self.active = np.asarray(active, int)
        self.poses = np.atleast_2d(np.asarray(poses, float))
        self.durations = np.asarray(durations, float).ravel()
        if self.poses.shape != (len(self.durations), len(self.active)):
            raise FlexibleError(f"pose graph: {len(self.durations)} poses need "
                                f"{len(self.active)} amplitudes each")
        if np.any(self.durations <= 0):
            raise FlexibleError("pose graph: every pose needs a positive duration")
        self.kp = np.broadcast_to(np.asarray(kp, float), self.active.shape).copy()
        self.kd = np.broadcast_to(np.asarray(kd, float), self.active.shape).copy()
        self._ends = np.cumsum(self.durations)

    def pose_index(self, time):
        phase = time % self._ends[-1]
        return min(int(np.searchsorted(self._ends, phase, side="right")), len(self._ends) - 1)

    def target(self, time):
        return self.poses[self.pose_index(time)]

    def with_parameters(self, poses, durations):
        return Controller(self.active, poses, durations, self.kp, self.kd)


@dataclass
class Result:
    times: np.ndarray
    t: np.ndarray
    quat: np.ndarray
    gamma: np.ndarray
    com: np.ndarray
    energy: np.ndarray                 # mechanical energy at the recorded times
    consumed_energy: float             # J done by mode forces (passive and PD), sum of |Q gamma_dot| dt
    cond_max: float
    cond_samples: np.ndarray
    final: State
    end_com_velocity: np.ndarray
    warnings: list
    handover_index: int = 0


def solve_spd(A, b):
    """A x = b for the (symmetric positive definite) system matrix by its Cholesky factorisation;
    by np.linalg.solve when it is not positive definite."""
    try:
        return cho_solve(cho_factor(A, check_finite=False), b, check_finite=False)
    except np.linalg.LinAlgError:
        return np.linalg.solve(A, b)


class Simulator:
    """Internally the velocities are in the body frame, u = (v_body, omega_body, gamma_dot), so
    that J = R [I, -[y]x, B] and M = sum m G^T G with G = [I, -[y]x, B] depends on gamma alone:
    M(gamma) = M0 + sum_k gamma_k M1_k + sum_kl gamma_k gamma_l M2_kl, precomputed once. It is
    the thesis's M (eq. 4.10) with the translation columns rotated into the body frame."""

    def __init__(self, body, gains=None, settings=None, controller=None):
        self.body = body
        self.settings = settings or Settings()
        if self.settings.integrator not in INTEGRATORS:
            raise FlexibleError(f"integrator must be one of {INTEGRATORS}")
        D = body.mode_count
        self.gains = gains or ModeGains(np.zeros(D), np.zeros(D))
        self.controller = controller
        if self.settings.check_modes:
            problems = _mode_problems(body)
            if problems:
                raise FlexibleError("deformation modes can't be simulated: " + "; ".join(problems))
        self._prepare_points()
        self._kernel = None

    def _prepare_points(self):
        body, s = self.body, self.settings
        springs = s.springs
        from .ffd import lattice_weights
        if springs:  # spring attachment points ride along as massless points
            W = lattice_weights(np.array([sp.uvw for sp in springs], float), body.dims)
            self.X0 = np.vstack([body.X0, W @ body.rest_lattice])
            Bs = np.einsum("pn,dnc->dpc", W, body.modes)
            self.B = np.concatenate([body.B, Bs], axis=1)
            self.m = np.concatenate([body.masses, np.zeros(len(springs))])
            collides = np.concatenate([body.collides, np.zeros(len(springs), bool)])
        else:
            self.X0, self.B, self.m = body.X0, body.B, body.masses
            collides = body.collides
        self.P = P = len(self.X0)
        D = body.mode_count
        self.n = 6 + D
        self.Bflat = self.B.reshape(D, 3 * P)
        self.Bt = self.B.transpose(1, 2, 0).copy()              # (P, 3, D)
        self.mcol = self.m[:, None]
        self.g = np.asarray(s.gravity, float)
        self.spring_idx = np.arange(len(body.masses), P)
        self._polys = None
        self._finish_prepare(collides)

    def _polynomials(self):
        """M(gamma) and the per-point G^T G as polynomials in gamma, for the reference step and
        energy(): made on first use (the fused kernel needs neither, and annealing makes a
        Simulator per trial)."""
        if self._polys is not None:
            return self._polys
        P, D, n = self.P, self.body.mode_count, self.n
        # M(gamma) as a quadratic polynomial: G = G0 + sum gamma_k G1_k
        G0 = self._rows(self.X0, np.arange(P))
        G1 = np.zeros((D, P, 3, n))
        for k in range(D):
            G1[k, :, :, 3:6] = -skew(self.B[k])
        mG0 = self.m[:, None, None] * G0
        M0 = np.einsum("pia,pib->ab", mG0, G0)
        N = np.einsum("pia,kpib->kab", mG0, G1)
        M1 = (N + N.transpose(0, 2, 1)).reshape(D, n * n)
        M2 = np.einsum("p,kpia,lpib->klab", self.m, G1, G1).reshape(D * D, n * n)
        M_poly = np.vstack([M0.reshape(1, n * n), M1, M2])         # rows: 1, gamma, gamma gamma
        # the same polynomial per point with unit mass, for the contact stiffness sum G^T G
        # (kept when small: P (1 + D + D^2) n^2 numbers)
        G_poly = None
        if P * (1 + D + D * D) * n * n <= 400_000:
            g0 = np.einsum("pia,pib->pab", G0, G0).reshape(P, 1, n * n)
            N = np.einsum("pia,kpib->pkab", G0, G1)
            g1 = (N + N.transpose(0, 1, 3, 2)).reshape(P, D, n * n)
            g2 = np.einsum("kpia,lpib->pklab", G1, G1).reshape(P, D * D, n * n)
            G_poly = np.concatenate([g0, g1, g2], axis=1)
        self._polys = (M_poly, G_poly)
        return self._polys

    @property
    def M_poly(self):
        return self._polynomials()[0]

    @property
    def G_poly(self):
        return self._polynomials()[1]

    def _finish_prepare(self, collides):
        body, s = self.body, self.settings
        n = self.n
        self.implicit = s.integrator in ("implicit", "semi_implicit")
        self.midpoint = s.integrator == "implicit"
        # 10x the stiffest mode or controller, at least a 5 Hz mode of its own modal mass
        modal = body.modal_masses()
        floor = modal * (2 * np.pi * 5.0) ** 2
        top = np.asarray(self.gains.stiffness, float).copy()
        if self.controller is not None:
            top[self.controller.active] += self.controller.kp
        self.limit_stiffness = np.maximum(10 * top, floor)
        self._kd_gamma = -np.asarray(self.gains.stiffness, float)
        self._cd_gamma = -np.asarray(self.gains.damping, float)
        self.K_base = np.zeros((n, n))
        self.C_base = np.zeros((n, n))
        dg = np.arange(6, n)
        self.K_base[dg, dg] = self.gains.stiffness
        self.C_base[dg, dg] = self.gains.damping
        if self.controller is not None:
            act = 6 + self.controller.active
            self.K_base[act, act] += self.controller.kp
            self.C_base[act, act] += self.controller.kd
        self.diag = np.arange(6, n)
        self.contacts = None
        if s.ground is not None:
            saved = body.collides
            body.collides = collides
            self.contacts = Contacts(body, s.ground)
            body.collides = saved

    def _rows(self, y, idx):
        """G rows (c, 3, n) of points idx at body-frame positions y (c, 3)."""
        G = np.zeros((len(idx), 3, self.n))
        G[:, :, 0:3] = np.eye(3)
        G[:, :, 3:6] = -skew(y)
        G[:, :, 6:] = self.Bt[idx]
        return G

    def mass_matrix(self, gamma):
        return (self._monomials(gamma) @ self.M_poly).reshape(self.n, self.n)

    @staticmethod
    def _monomials(gamma):
        return np.concatenate([(1.0,), gamma, np.outer(gamma, gamma).ravel()])

    def accelerations(self, st, time):
        """(M, b, K, C, mode power) at state st: M u_dot = b; K, C the stiffness and damping
        of the stiff forces (for the implicit step; None for the thesis scheme)."""
        R = quat_matrix(st.quat)
        gamma, gdot, w, vb = st.gamma, st.gdot, st.w, st.v
        mono = self._monomials(gamma)
        M = (mono @ self.M_poly).reshape(self.n, self.n)
        y = self.X0 + (gamma @ self.Bflat).reshape(self.P, 3)
        ydot = (gdot @ self.Bflat).reshape(self.P, 3)
        w0, w1, w2 = w.tolist()
        wx = np.array([[0.0, -w2, w1], [w2, 0.0, -w0], [-w1, w0, 0.0]])
        # velocity-dependent point accelerations: w x v + w x (w x y) + 2 w x y_dot (Kane's form
        # of the velocity terms of eq. 4.21); the uniform part goes with gravity
        uniform = self.g @ R - wx @ vb
        z = self.mcol * (y @ (wx @ wx).T + ydot @ (2.0 * wx).T)
        touching = None
        if self.contacts is not None:
            x = st.t + y @ R.T

            def velocity(idx):
                return (vb + y[idx] @ wx.T + ydot[idx]) @ R.T
            touching = self.contacts.forces(x, velocity)
            if touching is not None:
                z[touching[0]] -= touching[3] @ R
        if self.settings.springs:
            self._spring_forces(st, y, ydot, wx, R, z, time)
        S = y.T @ z
        b = M[:, 0:3] @ uniform
        b[0:3] -= z.sum(axis=0)
        (s00, s01, s02), (s10, s11, s12), (s20, s21, s22) = S.tolist()
        b[3:6] -= (s12 - s21, s20 - s02, s01 - s10)
        b[6:] -= self.Bflat @ z.ravel()
        qm = self._kd_gamma * gamma + self._cd_gamma * gdot
        ctl = self.controller
        if ctl is not None:
            a = ctl.active
            qm[a] += ctl.kp * ctl.target(time) - ctl.kp * gamma[a] - ctl.kd * gdot[a]
        # amplitudes live in [-1, 1] (thesis §4.3): a stiff one-sided spring beyond
        over = gamma - np.clip(gamma, -1.0, 1.0)
        limited = over.any()
        if limited:
            qm -= self.limit_stiffness * over
        b[6:] += qm
        K = C = None
        if self.implicit:
            K, C = self.K_base.copy(), self.C_base.copy()
            if limited:
                K[self.diag, self.diag] += self.limit_stiffness * (over != 0)
            if touching is not None:
                self._contact_matrices(touching, y, R, K, C, mono)
        power = float(np.abs(qm * gdot).sum())
        return M, b, K, C, power

    def _spring_forces(self, st, y, ydot, wx, R, z, time):
        x = st.t + y[self.spring_idx] @ R.T
        for j, sp in enumerate(self.settings.springs):
            i = self.spring_idx[j]
            anchor = sp.anchor(time) if callable(sp.anchor) else sp.anchor
            d = np.asarray(anchor, float) - x[j]
            dist = float(np.linalg.norm(d))
            vel = R @ (st.v + wx @ y[i] + ydot[i])
            direction = d / dist if dist > 1e-12 else np.zeros(3)
            f = sp.stiffness * (dist - sp.rest_length) * direction - sp.damping * vel
            z[i] -= f @ R

    def _contact_matrices(self, touching, y, R, K, C, mono):
        """Stiffness and damping of the touching points' springs and dampers in generalised
        coordinates: sticking points an isotropic spring with normal and friction damping,
        sliding points only the normal spring and damper (the capped friction force doesn't
        grow with the motion)."""
        idx, normals, sliding, _ = touching
        c = self.contacts
        if self.G_poly is not None:
            GtG = (mono @ self.G_poly[idx].sum(axis=0)).reshape(self.n, self.n)
        else:
            Gf = self._rows(y[idx], idx).reshape(-1, self.n)
            GtG = Gf.T @ Gf
        if normals.ndim == 1:
            nb = normals @ R                               # the normal in the body frame
            Gn = np.empty((len(idx), self.n))
            Gn[:, 0:3] = nb
            Gn[:, 3:6] = y[idx] @ skew(nb)                 # rows of (y x n)
            Gn[:, 6:] = self.Bt[idx].transpose(0, 2, 1) @ nb
        else:
            Gn = (self._rows(y[idx], idx) * (normals @ R)[..., None]).sum(axis=-2)
        GnGn = Gn.T @ Gn
        if sliding.any():
            Gs = self._rows(y[idx[sliding]], idx[sliding]).reshape(-1, self.n)
            Gns = Gn[sliding]
            slide_t = Gs.T @ Gs - Gns.T @ Gns              # the tangential part of sliding points
            K += c.k * (GtG - slide_t)
            C += c.ct * (GtG - GnGn - slide_t) + c.cn * GnGn
        else:
            K += c.k * GtG
            C += c.ct * (GtG - GnGn) + c.cn * GnGn

    def step(self, st, time):
        """Advance st by one step in place; returns (M, mode power)."""
        h = self.settings.dt
        M, b, K, C, power = self.accelerations(st, time)
        u = np.concatenate([st.v, st.w, st.gdot])
        if K is None:
            u_new = u + h * solve_spd(M, b)
            self._move(st, h * u_new, u_new)
        else:
            # predictor: the linearly implicit trapezoidal step
            A = M + (0.5 * h) * C + (0.25 * h * h) * K
            u_star = u + solve_spd(A, h * (b - (0.5 * h) * (K @ u)))
            if not self.midpoint:
                self._move(st, (0.5 * h) * (u + u_star), u_star)
                if not np.all(np.abs(u_star) < 1e6):
                    raise FlexibleError(f"the simulation diverged at {time:.3f} s: try a smaller time step")
                return M, power
            # corrector: one Newton step of the implicit midpoint rule about the predicted
            # midpoint (symplectic, no numerical damping, A-stable)
            mid = st.copy()
            self._move(mid, (0.25 * h) * (u + u_star), 0.5 * (u + u_star))
            Mp, bp, Kp, Cp, power = self.accelerations(mid, time + 0.5 * h)
            u_new = u_star + solve_spd(A, h * bp - Mp @ (u_star - u))
            self._move(st, (0.5 * h) * (u + u_new), u_new)
            M = Mp
        if not np.all(np.abs(u_new) < 1e6):  # also NaN; stops before numbers overflow
            raise FlexibleError(f"the simulation diverged at {time:.3f} s: try a smaller time step, "
                                f"the implicit integrator, or softer ground/modes")
        return M, power

    @staticmethod
    def _move(st, move, u_new):
        """Translate by R_mid v, rotate about the body axes, deform; R_mid is the orientation
        half way through the rotation, so translation and rotation stay in step."""
        phi = move[3:6].tolist()
        half = quat_multiply(st.quat, quat_from_rotvec([0.5 * phi[0], 0.5 * phi[1], 0.5 * phi[2]]))
        st.t = st.t + quat_matrix(half) @ move[0:3]     # |half| = 1 to rounding
        q = quat_multiply(st.quat, quat_from_rotvec(phi))   # fold phi into R_ref
        st.quat = q / math.sqrt(q @ q)
        st.gamma = st.gamma + move[6:]
        st.v, st.w, st.gdot = u_new[0:3], u_new[3:6], u_new[6:]

    # -- energy, centre of mass -------------------------------------------------------------
    def energy(self, st):
        """Kinetic + mode potential + gravity potential (J)."""
        u = st.u
        e = 0.5 * u @ self.mass_matrix(st.gamma) @ u + 0.5 * float(self.gains.stiffness @ st.gamma ** 2)
        return e - self.body.total_mass * float(self.com(st) @ self.g)

    def com(self, st):
        R = quat_matrix(st.quat)
        x = self.body.positions(st.t, R, st.gamma)
        return self.body.masses @ x / self.body.total_mass

    def com_velocity(self, st):
        R = quat_matrix(st.quat)
        y = self.body.local_points(st.gamma)
        ydot = (st.gdot @ self.body._B_flat).reshape(y.shape)
        v = (st.v + np.cross(st.w, y) + ydot) @ R.T
        return self.body.masses @ v / self.body.total_mass

    # -- runs -------------------------------------------------------------------------------
    def run(self, state, duration, record_every=None, start_time=0.0, track_energy=False):
        """Simulate `duration` seconds from `state`; record every `record_every` steps (default:
        only the ends). Returns a Result."""
        return run_to_end(self.iter_run(state, duration, record_every, start_time, track_energy))

    def iter_run(self, state, duration, record_every=None, start_time=0.0, track_energy=False):
        """run() as a step generator (yields progress in [0, 1], returns the Result). The steps
        are taken by the fused kernel (kernel.py), the same equations as step()."""
        steps = int(round(duration / self.settings.dt))
        if self.contacts is not None:
            self.contacts.reset()
        if self._kernel is None:
            self._kernel = Kernel(self)
        records, consumed, conds, final = yield from self._kernel.run(
            state, steps, start_time, record_every, self.settings.cond_every,
            lambda st, time: _snapshot(self, st, time, track_energy))
        return _result(self, records, consumed, conds, final)

    def reference_run(self, state, duration, record_every=None, start_time=0.0, track_energy=False):
        """The same run with the readable reference step() (for checking the kernel)."""
        h = self.settings.dt
        steps = int(round(duration / h))
        every = record_every or max(steps, 1)
        st = state.copy()
        if self.contacts is not None:
            self.contacts.reset()
        rec = [_snapshot(self, st, start_time, track_energy)]
        consumed, conds = 0.0, []
        cond_every = self.settings.cond_every
        for i in range(steps):
            time = start_time + i * h
            M, power = self.step(st, time)
            consumed += power * h
            if cond_every and i % cond_every == 0:
                conds.append(np.linalg.cond(M))
            if (i + 1) % every == 0 or i + 1 == steps:
                rec.append(_snapshot(self, st, start_time + (i + 1) * h, track_energy))
        return _result(self, rec, consumed, conds, st)


def _mode_problems(body):
    """check_modes once per body (annealing builds a Simulator per trial of the same body)."""
    key = (body.modes.tobytes(), body.masses.tobytes(), body.uvw.tobytes())
    cached = getattr(body, "_mode_check", None)
    if cached is None or cached[0] != key:
        cached = (key, check_modes(body))
        body._mode_check = cached
    return cached[1]


def _snapshot(sim, st, time, track_energy):
    return (time, st.t.copy(), st.quat.copy(), st.gamma.copy(), sim.com(st),
            sim.energy(st) if track_energy else np.nan)


def _result(sim, rec, consumed, conds, st, warnings=None):
    conds = np.asarray(conds, float)
    cond_max = float(conds.max()) if len(conds) else float(np.linalg.cond(
        sim.body.mass_matrix(st.gamma, quat_matrix(st.quat))))
    warnings = list(warnings or [])
    if cond_max > sim.settings.cond_limit:
        warnings.append(f"mass matrix condition number reached {cond_max:.3g}: modes are close "
                        f"to each other or to a rigid motion (thesis §4.10.3)")
    cols = list(zip(*rec))
    return Result(np.array(cols[0]), np.array(cols[1]), np.array(cols[2]), np.array(cols[3]),
                  np.array(cols[4]), np.array(cols[5]), consumed, cond_max, conds, st,
                  sim.com_velocity(st), warnings)
