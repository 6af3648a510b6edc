"""Oshita's dynamic motion control loop (2003, ch. 2, in 3-D): per step the tracking acceleration
(sec. 2.4.1), the constrained legs (sec. 2.4.2), comfort and balance control (sec. 2.5), Euler
integration and the falling criterion (sec. 2.3.3); loads, impulses, pushes and colliders are the
environmental input.

The parts, each a module with a plain interface:

  settings.py         what is asked (ControlSettings, Load, Impulse, Collider) and answered (ControlResult)
  body.py             the body per set of active loads (ControlBody, LoadedBodies)
  tracking.py         the tracking acceleration towards the input (TrackingController)
  feet.py             planted feet and the legs' inverse kinematics (PlantedFeet)
  comfort_control.py  stress against strength, passive and comfort control (ControlState)
  balance_control.py  ZMP, support polygon, balance control, the falling rotation
  dynamic_control.py  comfort and balance in the thesis's order, one step
  modes.py            the modes over time: a part's kind with hysteresis, the blend of a mode change
  pushes.py           impulses and pushing forces
  collisions.py       swept collider contacts, projected Gauss-Seidel, the ground's impulses
  falling.py          the falling criterion (capture point) and the fallen body (ragdoll)
  controller.py       this loop: one step calls them in order and records the frame

One step (dt = frame time / substeps), ControlLoop.step:

  1. tracking acceleration of every DOF towards the input (tracking.TrackingController);
  2. constrained legs (feet.PlantedFeet.constrain): a supporting foot stays planted where it
     landed, following the input foot's own roll;
  3. dynamic control (dynamic_control: passive, comfort then balance of arms, back and legs),
     unless tracking_only, against the strength and support widened by what the input itself
     needs at that frame (input allowance); external forces (Impulse with a duration, collider
     contact forces of the previous step) enter its inverse dynamics as known wrenches; when
     balance can't be kept the tracking's return is slowed first (ControlLoop._slower_return);
  4. semi-implicit Euler on the manifold, v' = v + a dt, q' = q (+) v' dt, which with the input's
     step-consistent velocities (tracking.step_consistent) reproduces an undisturbed input
     exactly; instant impulses (pushes.apply_impulses) change the velocities before the legs'
     velocity and position projections (feet.PlantedFeet.project_velocity, predicted_resolve);
  5. contact impulses of the colliders, a swing foot's ground and a fallen body's ground
     (collisions.Collisions.collide).

Falling (falling.FallCriterion): when balance control has reported for `fall_time` (0.1 s) that
the ZMP cannot be brought inside the support polygon and the capture point lies beyond the feet,
that step's output turns the body about the MMP and the figure is released; an instant impulse
whose momentum carries the capture point that far out releases it at once (knocked over).
Released, it is a ragdoll (falling.ragdoll_velocity) at the steps its contact spheres' speed
needs, kept on the ground by inelastic contact impulses with Coulomb friction; falling is final
for the rest of the clip.

Numerical trouble (overflow, invalid values, a singular factorisation) is caught with
np.errstate around the integration and reported as a SimulationError naming the frame.

tracking_only: the tracking acceleration with the constrained legs, nothing else (no comfort,
balance or falling); stress, ZMP and balance error are still reported.
"""

from dataclasses import replace
import math

import numpy as np

from ..body_roles import SIDES
from ..dynamics import kinematics
from ..dynamics.closed_loop import SimulationError, _to_trajectories, simulated_skeleton
from ..progress import run_to_end
from .balance_control import balance_error, support_polygon
from .body import LoadedBodies
from .collisions import Collisions
from .comfort_control import joint_stress, required_torques, stress_of
from .contacts import contact_floor, support_intervals
from .dynamic_control import control_state, dynamic_control, stress_by_bone
from .falling import KNOCKED_OVER, FallCriterion, fall_steps, ragdoll_velocity
from .feet import PlantedFeet, foot_skate, frame_index, rolling_anchor, sole_points
from .modes import ModeBlend, ModeMemory
from .pushes import Push, apply_impulses, push_forces
from .settings import Collider, ControlResult, ControlSettings, Impulse, Load
from .tracking import TrackingController

__all__ = ["Collider", "ControlResult", "ControlSettings", "ControlLoop", "Impulse", "Load", "control",
           "iter_control"]

NONE, PASSIVE, COMFORT, BALANCE = 0, 1, 2, 3
RETURN_SCALES = (0.5, 0.25, 0.0)
_BALANCED = 1e-3  # m: a ZMP tolerance above this is an input allowance (ControlLoop.excess)


def control(skeleton, trajectories, settings=None, on_frame=None):
    """Dynamic motion control of a skeleton following `trajectories` (see the module notes)."""
    return run_to_end(iter_control(skeleton, trajectories, settings, on_frame))


def iter_control(skeleton, trajectories, settings=None, on_frame=None):
    """control() as steps: yields the fraction of frames done, returns the ControlResult.

    on_frame(f, q, v), optional, is called at the start of each frame with copies of the body's
    state (the model's generalised positions and velocities); when it returns a (q, v) pair the
    body continues from that state (a caller replays a state it recorded, e.g. to switch inputs)."""
    loop = ControlLoop(skeleton, trajectories, settings or ControlSettings())
    nf = loop.tr.frame_count
    for f in range(nf):
        if on_frame is not None:
            state = on_frame(f, loop.q.copy(), loop.v.copy())
            if state is not None:
                loop.q, loop.v = (np.array(x, float) for x in state)
        loop.frame(f)
        yield (f + 1) / nf
    return loop.result()


class Record:
    """The per-frame outputs of a control loop (ControlResult's arrays)."""

    def __init__(self, nf, nq, joints):
        self.q = np.zeros((nf, nq))
        self.stress = np.zeros((nf, joints, 3))
        self.err = np.zeros(nf)
        self.zmp = np.full((nf, 2), np.nan)
        self.mmp = np.full((nf, 2), np.nan)
        self.support = np.zeros((nf, 2), bool)
        self.polygon = [np.zeros((0, 2))] * nf
        self.control = np.zeros((nf, joints), np.int8)
        self.falling = np.zeros(nf, bool)
        self.slide = np.zeros((nf, 2))


class ControlLoop:
    """One control run: the body's state (q, v, t), its parts (tracking, planted feet, pushes,
    collisions, the falling criterion) and the record of every frame."""

    def __init__(self, skeleton, trajectories, st):
        tr = trajectories
        self.st, self.tr = st, tr
        sk = simulated_skeleton(skeleton, tr, st)
        self.sk = sk
        total = sk.total_mass + sum(float(l.mass) for l in st.loads)
        self.bodies = LoadedBodies(sk, st, tr.basis()[0], self._q0, st.kinematic_fraction * total)
        self.body = self.bodies.at(0.0)
        m = self.body.model
        self.ground = float(contact_floor(sk, tr) if st.ground_height is None else st.ground_height)
        sup = support_intervals(sk, tr, st.support_overrides, floor=self.ground)
        self.support_in = np.stack([sup.get(s, np.zeros(tr.frame_count, bool)) for s in SIDES], axis=1)
        self.skate = np.zeros((tr.frame_count, 2))
        self.dt_frame = 1.0 / tr.fps if tr.frame_count < 2 else float(np.mean(np.diff(tr.times)))
        if st.remove_foot_skate:
            self.skate = foot_skate(m, self.body.parts, sk, tr, self.support_in, self.dt_frame)
            pos, ori = tr.root_pose(sk)
            tr = self.tr = tr.with_root_pose(sk, pos + np.c_[self.skate, np.zeros(len(pos))], ori)
        self.tracking = TrackingController(m, sk, tr, min_horizon=st.min_horizon, max_horizon=st.max_horizon)
        self.dt_frame = self.tracking.dt
        self.pushes = [Push.of(i, sk) for i in st.impulses]
        # the input's sole points at every frame (unloaded body: one batched forward kinematics,
        # shared by the input allowance and the rolling anchor)
        rest = self.bodies.unloaded()
        k = rest.sole_split
        pts = sole_points(rest.model, self.tracking.q_d, rest.parts)
        input_soles = (pts[:, :k], pts[:, k:])
        self.fall = FallCriterion(self.ground, st.gravity, st.fall_time)
        self.criteria_by_zmp = {}  # input ZMP allowance -> criteria Settings with that tolerance
        self.allow_tau = self.allow_zmp = None
        if st.input_allowance:
            self.allow_tau, self.allow_zmp, self.fall.allow_capture = self._input_allowance(input_soles)
        weights, roll = rolling_anchor(rest.model, self.tracking.q_d, rest.parts, input_soles, self.support_in)
        self.feet = PlantedFeet(st, self.tracking, m.create_data(), self.support_in, weights, roll)
        self.feet.precompute_targets(self.body)
        self.collisions = Collisions(st, self.ground, self.dt_frame)
        self.modes, self.mode_blend = ModeMemory(), ModeBlend(st.mode_blend_time)
        self.q = self.tracking.q_d[0].copy()
        self.v = self.tracking.v_d[0].copy()
        self.t = 0.0
        self.fallen = False
        self.record = Record(tr.frame_count, m.nq, sk.joint_count)
        # stress_by_bone's entries (bone, axis) of the actuated DOFs in a frame's flat (J * 3) row
        # (every body of the loop has the same DOFs, LoadedBodies)
        self._stress_index = 3 * m.dof_joint[6:] + m.dof_slot[6:]

    # ---- set-up ----

    def _q0(self, m):
        pos, ori = self.tr.root_pose(self.sk)
        return m.configuration(pos[0], ori[0], self.tr.rotations[0])

    def _input_allowance(self, input_soles):
        """Per input frame: (nv,) torque beyond strength, the ZMP's distance outside the support
        polygon and the capture point's, of the input motion itself (unloaded body, no pushes), the
        max over frames f-1..f+1."""
        body = self.bodies.unloaded()
        m, tk = body.model, self.tracking
        nf = self.tr.frame_count
        tau_x, zmp_x, capture = np.zeros((nf, m.nv)), np.zeros(nf), np.zeros(nf)
        for f in range(nf):
            cs = control_state(m, body.data, tk.q_d[f], tk.v_d[f], self.support_in[f], body.strength,
                               ground_height=self.ground, parts=body.parts, settings=self.st.criteria,
                               constants=body.constants, soles=[input_soles[0][f], input_soles[1][f]])
            tau, wrench = required_torques(cs, tk.a_d[f])
            # beyond the knee of the strength's smooth saturation (comfort_control.saturated_stress):
            # widened by this, the knee lies at the input's torque
            tau_x[f] = np.abs(joint_stress(tau, cs.knees)) / (1.0 - cs.settings.saturation_band)
            zmp_x[f] = balance_error(cs, wrench)[2]
            capture[f] = self.fall.capture_error(cs)
        return _window_max(tau_x), _window_max(zmp_x), _window_max(capture)

    def frame_index(self, t):
        """The input frame a step at time t belongs to."""
        return frame_index(t, self.dt_frame, self.tr.frame_count)

    def allowance(self, t):
        """The input's own torque excess (nv,) at t and the criteria with its ZMP excursion."""
        if self.allow_tau is None:
            return None, self.st.criteria
        fi = self.frame_index(t)
        zmp = float(self.allow_zmp[fi])
        if zmp <= self.st.criteria.zmp_tolerance:
            return self.allow_tau[fi], self.st.criteria
        crit = self.criteria_by_zmp.get(zmp)
        if crit is None:
            crit = self.criteria_by_zmp[zmp] = replace(self.st.criteria, zmp_tolerance=zmp)
        return self.allow_tau[fi], crit

    # ---- one frame ----

    def frame(self, f):
        """Record frame f's state and diagnostics, then step to the next frame (none after the last)."""
        last = f == self.tr.frame_count - 1
        self.record.q[f] = self.q
        n = fall_steps(self.body, self.q, self.v, self.st, self.dt_frame) if self.fallen else max(1, self.st.substeps)
        for k in range(1 if last else n):
            self.step(f, self.dt_frame / n, record=k == 0, integrate=not last)

    def step(self, f, dt, record, integrate):
        """One step: the commanded acceleration, the diagnostics when `record`, and the state at t + dt
        when `integrate`."""
        body = self.body = self.bodies.at(self.t)
        q, v, t = self.q, self.v, self.t
        f_ext = push_forces(self.pushes, body, q, t)
        if self.collisions.wrench is not None:
            f_ext = self.collisions.wrench if f_ext is None else f_ext + self.collisions.wrench
        if self.fallen:
            feet = np.zeros(2, bool)
        else:
            feet = self.support_in[self.frame_index(t)].copy()
            self.feet.update(body, feet, t, q)
        planted = bool(feet[0] or feet[1])
        a, cs, fall = (None, None, None) if self.fallen else self._command(f, body, q, v, t, dt, feet, f_ext, record)
        if record:
            self._record_state(f, body, q, feet, fall)
        if not integrate:
            return
        try:
            with np.errstate(over="raise", invalid="raise"):
                q, v = self._integrate(body, q, v, t, dt, a, cs, feet, planted, fall, f_ext)
        except (np.linalg.LinAlgError, FloatingPointError) as exc:
            raise SimulationError(f"the motion control diverged at frame {self.tr.frames[f]:g}: {exc}") from None
        # (a sum of q and v is finite when both are: one overflowing sum would take values of
        # 1e306, which no body reaches without diverging first)
        if not math.isfinite(float(np.add.reduce(q)) + float(np.add.reduce(v))):
            raise SimulationError(f"the motion control diverged at frame {self.tr.frames[f]:g}")
        self.q, self.v = q, v

    def _command(self, f, body, q, v, t, dt, feet, f_ext, record):
        """The commanded acceleration of a standing figure: tracking, the planted legs, dynamic
        control and the falling criterion. Returns (a, control state, fall or None)."""
        st = self.st
        a_raw = self.tracking.acceleration(t, q, v)
        planted = bool(feet[0] or feet[1])
        held = self.feet.held(feet)  # planted, or being released (feet.RELEASE_TIME)
        targets = self.feet.targets(body, held, t) if held.any() else None
        a_track = self.feet.constrain(body, q, v, a_raw, held, targets) if targets is not None else a_raw
        allow, criteria = self.allowance(t)
        sides, foot_bodies = body.contact_sets[bool(feet[0]), bool(feet[1])] if planted else (None, None)
        cs = control_state(body.model, body.data, q, v, feet, body.strength, f_ext=f_ext,
                           ground_height=self.ground, parts=body.parts, settings=criteria, allowance=allow,
                           constants=body.constants, soles=self.feet.soles(body, q), contact_sides=sides,
                           foot_bodies=foot_bodies)
        if st.tracking_only:
            if record:
                self._record_diagnostics(f, cs, a_track)
            return a_track, cs, None
        res = dynamic_control(cs, a_track, self.modes)
        scale = None
        if res.falling is not None:
            a_slower, res, scale = self._slower_return(body, cs, t, a_raw, a_track, res, held, targets)
        else:
            a_slower = a_track
        a = a_slower + _bounded(res.delta, st.max_dynamic_acceleration) if res.acted else a_slower
        self.modes.remember(res.log.actions)
        # blended across a change of a part's kind or of the return's scale (modes.ModeBlend); a
        # control that starts or stops acting starts from or ends at no change by itself
        if self.mode_blend.blend_time > 0.0:
            a = a_track + self.mode_blend.blend((self.modes.state(), scale), a - a_track, dt)
        if record:
            self._record_result(f, cs, res)
        fi = self.frame_index(t)
        if self.fall.falls(res.falling is not None, dt, cs, fi):
            return a + res.falling.base_acceleration, cs, res.falling
        return a, cs, None

    def _integrate(self, body, q, v, t, dt, a, cs, feet, planted, fall, f_ext):
        """Semi-implicit Euler on the manifold, v' = v + a dt, q' = q (+) v' dt, with the instant
        pushes, the contact impulses and the planted legs' projections; (q', v')."""
        st, m = self.st, body.model
        if self.fallen:
            v = ragdoll_velocity(body, q, v, dt, f_ext, st)
        else:
            v = v + dt * a
        servo = None if self.fallen else self.tracking.target_times(t)
        through = (lambda solve, dv: self.feet.through_feet(body, q, feet, solve, dv)) if planted else None
        v, pushed = apply_impulses(self.pushes, body, q, v, t, dt, servo, through)
        if pushed and planted and fall is None and not st.tracking_only \
                and self.fall.knocked_over(cs, self.frame_index(t), v):
            # knocked over: the impulse's momentum carries the capture point beyond where the feet
            # could stop it; planted feet would take that momentum back (their projection acts as
            # an unbounded ground) and spin the upper body instead
            fall = KNOCKED_OVER
        v = self.collisions.collide(body, q, v, t, dt, self.fallen or fall is KNOCKED_OVER, self.feet.planted)
        if fall is not None:
            self.fallen = True
            self.feet.release()
            feet[:] = False
            planted = False
        resolve = correction = targets = None
        held = self.feet.held(feet) if not self.fallen else feet
        if held.any():  # the held feet's velocity over the step: the targets' at its end
            targets = self.feet.targets(body, held, t + dt)
            v = self.feet.project_velocity(body, q, v, held, targets)
            # the positions' re-solve: predicted from the frames at q, or after the step (a violent
            # step, a foot lifting or being released, foot_iterations)
            if st.foot_iterations == 0:
                correction = self.feet.predicted_resolve(body, q, v, held, targets, dt)
            resolve = correction is None
        # semi-implicit Euler: with tracking.step_consistent's input velocities it steps onto the
        # input's frames and velocities exactly (test_motion_control_tracking)
        q = kinematics.integrate(m, q, v * dt if correction is None else v * dt + correction)
        self.t = t + dt
        if resolve:
            q = self.feet.project_position(body, q, held, targets, max(st.foot_iterations, 1))
        return q, v

    def _slower_return(self, body, cs, t, a_raw, a_track, res, feet, targets):
        """When balance control cannot keep the ZMP in the support polygon, return to the input
        more slowly before giving in to a fall: the tracking's feedback (its acceleration beyond the
        input's own) scaled by each of RETURN_SCALES until one balances; (a, result, that scale or
        None). Only while the figure can
        still stop on its feet (capture point within the support polygon, or no further out than
        the input's own): a figure pushed beyond that falls, as in the thesis."""
        if not self.fall.can_stop(cs, self.frame_index(t)):  # it cannot stop without a step: it falls
            return a_track, res, None
        a_d = self.tracking.desired_state(t)[2]
        for scale in RETURN_SCALES:
            a = a_d + scale * (a_raw - a_d)
            if targets is not None:
                a = self.feet.constrain(body, cs.q, cs.v, a, feet, targets)
            out = dynamic_control(cs, a, self.modes)
            if out.falling is None:
                return a, out, scale
        return a_track, res, None

    # ---- the record ----

    def _record_state(self, f, body, q, feet, fall):
        rec = self.record
        rec.falling[f] = self.fallen or fall is not None
        if rec.falling[f]:  # no support to measure against: no balance error
            rec.err[f] = np.nan
        rec.support[f] = feet
        for s in range(2):
            if feet[s] and self.feet.planted[s] is not None:
                rec.slide[f, s] = self.feet.contact_drift(body, q, s, f)

    def _record_result(self, f, cs, res):
        rec, m = self.record, cs.model
        rec.stress[f].put(self._stress_index, res.stress_after[6:])  # stress_by_bone into the (zero) row
        rec.polygon[f] = res.polygon
        if res.zmp is not None:
            rec.zmp[f] = res.zmp
            rec.mmp[f] = res.mmp
            dx, dy = (res.zmp - res.mmp).tolist()
            rec.err[f] = self.excess(math.hypot(dx, dy), cs)
        if not res.acted:  # no mask is set: the row stays zero
            return
        code = np.zeros(m.nv, np.int8)
        code[res.log.passive] = PASSIVE
        code[res.log.comfort] = np.maximum(code[res.log.comfort], COMFORT)
        code[res.log.balance] = BALANCE
        per_bone = np.zeros(m.skeleton.joint_count, np.int8)
        np.maximum.at(per_bone, m.dof_joint[6:], code[6:])
        rec.control[f] = per_bone

    def _record_diagnostics(self, f, cs, a):
        rec = self.record
        tau, wrench = required_torques(cs, a)
        rec.stress[f] = stress_by_bone(cs.model, stress_of(cs, tau))
        poly = support_polygon(cs)
        rec.polygon[f] = poly
        p, mmp, dist = balance_error(cs, wrench, poly)
        if p is not None:
            rec.zmp[f], rec.mmp[f], rec.err[f] = p, mmp, self.excess(dist, cs)

    @staticmethod
    def excess(dist, cs):
        """The balance error beyond what the input itself has at this frame (its allowance)."""
        tol = cs.settings.zmp_tolerance
        return max(0.0, dist - tol) if tol > _BALANCED else dist

    def result(self):
        m, rec = self.body.model, self.record
        traj = _to_trajectories(m, self.sk, self.tr, rec.q)
        return ControlResult(trajectories=traj, stress=rec.stress, balance_error=rec.err, zmp=rec.zmp,
                             mmp=rec.mmp, support=rec.support, polygon=rec.polygon, control=rec.control,
                             falling=rec.falling, foot_slide=rec.slide, foot_skate=self.skate, model=m,
                             ground_height=self.ground)


def _window_max(x):
    """Max over each frame and its neighbours (along axis 0)."""
    out = x.copy()
    out[1:] = np.maximum(out[1:], x[:-1])
    out[:-1] = np.maximum(out[:-1], x[1:])
    return out


def _bounded(delta, top):
    """delta scaled down so that no component exceeds `top`."""
    size = np.abs(delta).max() if len(delta) else 0.0
    return delta * (top / size) if size > top else delta
