"""Oshita's tracking control (Oshita 2003, sec. 2.4.1): the output acceleration of every DOF from
a Ferguson (cubic Hermite) curve that runs from the current state to a target point of the desired
trajectory, so that a figure whose velocity was changed by a collision keeps approaching the input
motion instead of snapping back to it.

With the current state (theta, theta') and the target (theta_t, theta'_t) T seconds ahead, the
curve's second derivative at its start is (eq. 2.4-2.6, with the T factors of the derivative terms
that eq. 2.6 leaves implicit)

    theta'' = (6 (theta_t - theta) - (2 theta'_t + 4 theta') T) / T^2.

On the configuration manifold
-----------------------------
The DOF are the dynamics Model's velocity coordinates: the root's angular and linear velocity in
its own axes, then each joint body's local angular velocity on its free axes. "theta_t - theta" is
the log map kinematics.difference(q, q_t) (a rotation vector in the current bone axes; the root
translation in the current root axes), and the target velocity is carried into the same axes.

Extremum in 3-D: a DOF's target is the next *extremum* of its desired trajectory, i.e. the first
frame after the current time where that component of the desired velocity changes sign (a local
angular velocity component for a joint axis, a root-axes component for the root): for a 1-DOF
joint that is exactly the next extremum of its angle, for a ball joint it is the extremum of the
rotation-vector component about that bone axis, measured relative to the current pose. Its
velocity there is about zero, which is what makes the Ferguson target a natural "turning point".

Horizon: T = target time - current time is kept within [min_horizon, max_horizon]. Without a near
extremum (a root moving steadily forward) the target is the desired state max_horizon ahead; when
the extremum is closer than min_horizon, the target is the desired state min_horizon ahead (with
its non-zero velocity), because the curve's gains 6/T^2 and 4/T grow without bound as T -> 0 and
an Euler step of length dt is stable only for T > 2 dt (semi-implicit Euler; explicit Euler for
T > 1.5 dt), hence at least three frames. MIN_HORIZON raises that floor to 0.2 s. The input
itself is followed exactly by the feedforward term whatever T is (step_consistent), so T only
sets how hard a disturbance is corrected: a -4 e'/T pull on a velocity error. With CMU's 120 fps
three frames are 25 ms, and a push's velocity change was corrected within 1/15 s: 1000 rad/s^2
at the neck, which passive and comfort control turned into chaos (1 kN m of ankle stress, ZMPs
metres off). 0.2 s, a human reaction time, keeps the thesis's squat results (a 15 N s push is
back within 2 deg in 1.7 s rather than 1.9) and the CMU demo's pushes under 100 N m of stress.
"""

import math

import numpy as np

from ..dynamics import kinematics, spatial
from ..dynamics.closed_loop import desired_motion

MIN_HORIZON = 0.2  # s, a floor for the default min_horizon (module notes)


def step_consistent(model, q_d, v_c, a_c, dt):
    """The input's velocities and accelerations as the control loop's Euler step reads them:
    v[f] is the step from frame f-1 to f (kinematics.difference, in frame f-1's axes) over dt and
    a[f] = (v[f+1] - v[f]) / dt, so that v' = v + a dt, q' = q (+) v' dt reproduces the input's
    frames and velocities exactly. Central differences (v_c, a_c) reproduce the frames but not the
    velocities: on a captured motion's jittery light bones (CMU toes, 900 rad/s^2 from frame to
    frame) the velocity error then feeds back through the tracking and drifts by degrees."""
    nf = len(q_d)
    if nf < 3:
        return q_d, v_c, a_c, dt
    v = np.empty_like(v_c)
    v[1:] = kinematics.difference(model, q_d[:-1], q_d[1:]) / dt  # every frame at once
    v[0] = v[1]
    a = np.empty_like(a_c)
    a[:-1] = (v[1:] - v[:-1]) / dt
    a[-1] = a[-2]  # the last frame is not stepped from; its diagnostics see the motion going on
    return q_d, v, a, dt


class TrackingController:
    """Tracking control of every DOF of `model` towards `trajectories` (sec. 2.4.1).

    Times t are seconds from the motion's first frame. min_horizon / max_horizon in seconds;
    min_horizon defaults to three frames, at least MIN_HORIZON (see the module notes)."""

    def __init__(self, model, skeleton, trajectories, min_horizon=None, max_horizon=0.5,
                 feedforward=True):
        self.model = model
        self.feedforward = bool(feedforward)
        self.q_d, self.v_d, self.a_d, self.dt = step_consistent(model, *desired_motion(model, skeleton, trajectories))
        self.min_horizon = max(3.0 * self.dt, MIN_HORIZON) if min_horizon is None else float(min_horizon)
        self.max_horizon = float(max_horizon)
        if not 0.0 < self.min_horizon <= self.max_horizon:
            raise ValueError("need 0 < min_horizon <= max_horizon")
        self.duration = (len(self.q_d) - 1) * self.dt
        self.next_extremum = next_extremum_times(self.v_d, self.dt)
        self._quats = self.q_d[:, 3:].reshape(len(self.q_d), model.nb, 4)
        self._precompute_frames()
        self._precompute_indices()

    # ---- targets ----

    def target_times(self, t):
        """Per DOF (nv,) the time of its target point: the next extremum after t, kept within
        [t + min_horizon, t + max_horizon]."""
        f = min(max(int(math.floor(t / self.dt + 1e-9)), 0), len(self.q_d) - 1)
        return np.clip(self.next_extremum[f], t + self.min_horizon, t + self.max_horizon)

    def _sample(self, times):
        """Desired state at per-DOF times (..., nv): the body quaternion (..., nv, 4) and root
        position (..., nv, 3) of each DOF's body, and its desired velocity (..., nv) in the
        target's own axes; beyond the end of the motion the last frame holds."""
        m = self.model
        x = np.clip(np.asarray(times) / self.dt, 0.0, len(self.q_d) - 1)
        f0 = np.minimum(np.floor(x).astype(int), len(self.q_d) - 2) if len(self.q_d) > 1 else np.zeros(x.shape, int)
        f1 = np.minimum(f0 + 1, len(self.q_d) - 1)
        w = (x - f0)[..., None]
        body = m.dof_body
        qa, qb = self._quats[f0, body], self._quats[f1, body]
        # slerp on each DOF's body quaternion (the frames are close, the log is short)
        step = spatial.quat_log(spatial.quat_multiply(spatial.quat_conjugate(qa), qb))
        quat = spatial.quat_multiply(qa, spatial.quat_exp(w * step))
        pos = (1.0 - w) * self.q_d[f0, :3] + w * self.q_d[f1, :3]
        k = np.arange(m.nv)
        vel = (1.0 - w[..., 0]) * self.v_d[f0, k] + w[..., 0] * self.v_d[f1, k]
        return quat, pos, vel

    def on_frame(self, t):
        """The frame index when t is on the input's frame grid (within 1e-7 frames), else None."""
        x = t / self.dt
        f = int(round(x))
        return f if abs(x - f) < 1e-7 and 0 <= f < len(self.q_d) else None

    def _precompute_frames(self):
        """Per input frame: the targets, horizons and feedforward term of acceleration(), which
        depend on the input alone (one batched pass instead of two per control step)."""
        nf = len(self.q_d)
        t = np.arange(nf) * self.dt
        times = np.clip(self.next_extremum, t[:, None] + self.min_horizon, t[:, None] + self.max_horizon)
        horizon = times - t[:, None]
        target = self._sample(times)
        ff = self.a_d - self._ferguson(self.q_d, self.v_d, target, horizon) if self.feedforward else None
        self._frame_data = (target, horizon, ff)

    def _precompute_indices(self):
        """Index arrays and constants of the per-step error (_frame_error), once per model."""
        m = self.model
        slot = m.dof_slot
        lin = slot >= 3
        axis = np.where(lin, slot - 3, slot)
        # each DOF's body quaternion in q, and the rows of the root translation's DOFs
        # (as (nv, 4, 1): the outer products below take it without a new view)
        self._cur_index = (3 + 4 * m.dof_body[:, None] + np.arange(4)[None, :])[:, :, None]
        self._k = np.arange(m.nv)
        self._rel_axis = 1 + np.minimum(axis, 2)  # each DOF's component of its relative quaternion
        self._rel_flat = 4 * self._k + self._rel_axis  # ... in the flattened (nv, 4) quaternions
        self._lin = np.flatnonzero(lin)
        self._lin_axis = slot[lin] - 3
        self._has_lin = bool(lin.any())
        # the diagonal entry R[axis, axis] of a quaternion's rotation matrix: w^2 + c_axis^2 - the
        # other two components squared (quat_to_matrix's terms)
        sign = -np.ones((m.nv, 4))
        sign[:, 0] = 1.0
        sign[self._k, 1 + axis] = 1.0
        self._diag_sign = sign
        target, horizon, ff = self._frame_data
        # conj(cur) * target as one product of the (nv, 16) outer products cur_j target_l with
        # the Hamilton product's constant (16, 4) map, the conjugation folded in (a reduction
        # over a small last axis costs ~4x a 2-D product)
        self._frame_target = np.ascontiguousarray(target[0])[:, :, None, :]  # (F, nv, 1, 4)
        self._frame_h2 = horizon ** 2
        # the root translation's DOFs: their target positions per frame (floats) and the
        # current root axis each one reads (its column of the root's rotation)
        self._lin_targets = target[1][:, self._lin].tolist() if self._has_lin else None
        self._lin_cols = self._lin_axis.tolist()
        lin = self._lin
        self._lin_slice = slice(int(lin[0]), int(lin[-1]) + 1) if (
            len(lin) and np.array_equal(lin, np.arange(lin[0], lin[-1] + 1))) else lin

    # ---- control ----

    def acceleration(self, t, q, v):
        """Output acceleration (nv,) at time t for the current state (q, v) (eq. 2.6, plus the
        feedforward correction when `feedforward` is on)."""
        f = self.on_frame(t)
        if f is not None:  # on the frame grid (every step without substeps): precomputed
            target, horizon, ff = self._frame_data
            error, vel_t = self._frame_error(f, q)
            h = horizon[f]
            out = (6.0 * error - (2.0 * vel_t + 4.0 * np.asarray(v, float)) * h) / self._frame_h2[f]
            return out + ff[f] if self.feedforward else out
        times = self.target_times(t)
        horizon = times - t
        target = self._sample(times)
        out = self._ferguson(q, v, target, horizon)
        if self.feedforward:
            q_d, v_d, a_d = self.desired_state(t)
            out += a_d - self._ferguson(q_d, v_d, target, horizon)
        return out

    def _ferguson(self, q, v, target, horizon):
        """Second derivative at s = 0 of the Ferguson curve from (q, v) to the targets."""
        quat, pos, vel_t = target
        error, vel_t = self._error(q, quat, pos, vel_t)
        return (6.0 * error - (2.0 * vel_t + 4.0 * np.asarray(v, float)) * horizon) / horizon ** 2

    def desired_state(self, t):
        """Desired q, v, a at time t (linear on the manifold between frames)."""
        f = self.on_frame(t)
        if f is not None:
            return self.q_d[f].copy(), self.v_d[f].copy(), self.a_d[f].copy()
        x = float(np.clip(t / self.dt, 0.0, len(self.q_d) - 1))
        f0 = min(int(np.floor(x)), max(len(self.q_d) - 2, 0))
        f1 = min(f0 + 1, len(self.q_d) - 1)
        w = x - f0
        q = kinematics.integrate(self.model, self.q_d[f0], kinematics.difference(self.model, self.q_d[f0], self.q_d[f1]) * w)
        return q, (1 - w) * self.v_d[f0] + w * self.v_d[f1], (1 - w) * self.a_d[f0] + w * self.a_d[f1]

    def _frame_error(self, f, q):
        """_error for one configuration q against frame f's precomputed targets (the same
        arithmetic in about a third of the numpy calls)."""
        target = self._frame_data[0]
        q = np.asarray(q, float)
        cur = q.take(self._cur_index)  # (nv, 4, 1)
        nv = len(cur)
        # conj(cur) * target
        rel = (cur * self._frame_target[f]).reshape(nv, 16).dot(spatial._CONJ_QMUL_OUTER)
        # quat_log's arithmetic on the one component each DOF needs (its sign: the short way)
        w = rel[:, 0]
        xyz = rel[:, 1:]
        s = np.sqrt((xyz * xyz).sum(axis=1))
        comp = rel.take(self._rel_flat)  # rel[k, rel_axis] (flat)
        # (log_scale >= 0: copysign gives it w's sign, the where(w < 0, -comp, comp) of before in
        # two fewer calls; they differ only at w = -0.0, a half turn)
        error = np.copysign(spatial.log_scale(s, np.abs(w)), w) * comp
        # target angular velocity carried into the current axes: R(rel)[axis, axis] * vel_t
        vel = (rel * rel * self._diag_sign).sum(axis=1) * target[2][f]
        if self._has_lin:
            # the root's world offset to its targets in the current root axes, r0.T @ (p_t - p)
            p0, p1, p2, qw, qx, qy, qz = q[:7].tolist()
            r = spatial.quat_rows(qw, qx, qy, qz)
            error[self._lin_slice] = [(t0 - p0) * r[0][k] + (t1 - p1) * r[1][k] + (t2 - p2) * r[2][k]
                                      for (t0, t1, t2), k in zip(self._lin_targets[f], self._lin_cols)]
        return error, vel

    def _error(self, q, quat, pos, vel_t):
        """Per DOF "theta_t - theta" (..., nv) and the target velocity carried into current axes
        (q may be a stack (..., nq) with targets (..., nv, 4), (..., nv, 3), (..., nv))."""
        m = self.model
        q = np.asarray(q, float)
        k = np.arange(m.nv)
        slot = m.dof_slot
        cur = q[..., 3:].reshape(q.shape[:-1] + (m.nb, 4))[..., m.dof_body, :]
        rel = spatial.quat_multiply(spatial.quat_conjugate(cur), quat)  # target in current axes
        rot_err = spatial.quat_log(rel)
        error = rot_err[..., k, np.minimum(slot, 2)]
        # target angular velocity (own axes) seen in the current axes: rotate by rel
        rot = spatial.quat_to_matrix(rel)
        lin = slot >= 3
        axis = np.where(lin, slot - 3, slot)
        carried = np.zeros(rel.shape[:-1] + (3,))
        carried[..., k, axis] = vel_t
        carried = np.einsum("...kij,...kj->...ki", rot, carried)
        vel = carried[..., k, axis]
        if lin.any():
            # root translation: world offset in the current root axes
            r0 = spatial.quat_to_matrix(q[..., 3:7])
            offset = np.einsum("...li,...ij->...lj", pos[..., lin, :] - q[..., None, :3], r0)  # r0.T @ (p_t - p)
            error[..., lin] = offset[..., np.arange(lin.sum()), slot[lin] - 3]
        return error, vel




def next_extremum_times(v_d, dt):
    """(F, nv) time of the first extremum strictly after each frame, per DOF (inf if none).

    An extremum is the frame where a component of the desired velocity changes sign (the one of
    the pair with the smaller speed); a component that stays at zero has none (it needs no
    turning point: the max_horizon target keeps it still)."""
    nf, nv = v_d.shape
    out = np.full((nf, nv), np.inf)
    if nf < 2:
        return out
    a, b = v_d[:-1], v_d[1:]
    change = (a * b < 0.0) | ((b == 0.0) & (a != 0.0))
    at = np.arange(nf - 1)[:, None] + (np.abs(b) <= np.abs(a))  # frame of the turning point
    rows, cols = np.nonzero(change)
    events = np.full((nf, nv), np.inf)
    events[at[rows, cols], cols] = at[rows, cols]
    best = np.full(nv, np.inf)  # reverse running minimum: the first extremum frame > f
    for f in range(nf - 1, -1, -1):
        out[f] = best
        best = np.minimum(best, events[f])
    return out * dt
