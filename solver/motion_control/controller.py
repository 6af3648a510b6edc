"""Oshita's dynamic motion control loop (2003, ch. 2, in 3-D): per step the tracking acceleration
(sec. 2.4.1), the constrained legs (sec. 2.4.2), comfort and balance control (sec. 2.5), Euler
integration and the falling criterion (sec. 2.3.3); loads, impulses, pushes and colliders are the
environmental input.

One step (dt = frame time / substeps):

  1. tracking acceleration of every DOF towards the input (TrackingController);
  2. constrained legs: a foot that supports the body (support_intervals of the input, with the
     animator's overrides) is planted where it was when it landed and follows the input foot's own
     motion from there (a heel that rises in the input rises), rolling about its contact point
     without sliding (_rolling_anchor; the capture's foot skate is first removed from the whole
     input, _foot_skate). The supported leg's joint accelerations are the tracking ones corrected
     by the least change that gives the foot its target acceleration for the pelvis's acceleration
     (the acceleration form of the limb's inverse kinematics); the velocities are projected onto
     the foot's target velocity at the step's end and, after the Euler step, the positions
     re-solved (a Gauss-Newton pass of the leg's IK on its own DOFs), so the foot cannot drift
     however balance control moves the pelvis. The legs' least squares are damped, more so near a
     straight knee (_damping: a straight leg cannot move its foot along itself);
  3. dynamic control (dynamic_control: passive, comfort then balance of arms, back and legs),
     unless tracking_only, against the strength and support widened by what the input itself
     needs at that frame (input_allowance); external forces (Impulse with a duration, collider
     contact forces of the previous step) enter its inverse dynamics as known wrenches; when
     balance can't be kept the tracking's return is slowed first (_slower_return);
  4. semi-implicit Euler on the manifold, v' = v + a dt, q' = q (+) v' dt, which with the input's
     step-consistent velocities (tracking.step_consistent) reproduces an undisturbed input
     exactly; instant impulses change the velocities through the inertia matrix, dv = H^-1 J' p,
     the joints' servo resisting it over the step (_servoed_inertia) and the planted feet held
     (_through_feet: the ground takes its share), before the legs' projection;
  5. colliders: each collider sphere's path over the step swept against the body's capsules (a
     bone's two contact spheres, default_contacts, and the segment between them), so a fast fist
     cannot pass through between two steps; at the first contact an approaching pair gets the
     impulse that leaves it separating at restitution times its approach speed (all pairs at
     once, projected Gauss-Seidel on J H^-1 J' + B B'/M), friction included; the collider is
     kinematic (infinite mass, it keeps pushing) unless Collider.mass is finite (one impulse per
     contact). A swing foot (not planted) is kept above the ground by impulses on its leg's DOFs.

Falling (choice: contact impulses, not a hand-over to closed_loop.iter_simulate): when balance
control has reported for `fall_time` (0.1 s) that the ZMP cannot be brought inside the support
polygon (one glitch of a captured motion does not fell the figure) and the capture point lies
beyond the feet (_can_stop: the figure could not stop without a step), that step's output
turns the body about the MMP (Falling.base_acceleration, sec. 2.3.3) and the figure is released;
an instant impulse whose momentum carries the capture point that far out releases it at once
(knocked over: the planted feet's projection would otherwise take the momentum back, as an
unbounded ground, and spin the upper body instead). Released,
from the next step it is a ragdoll (no joint torques but damping, the joint limits as stiff
springs, both implicit: (H + dt D + dt^2 K) dv = dt (tau - bias)) at `fall_rate` steps a
second, kept on the ground by inelastic contact impulses on every contact sphere with speculative
contacts (a sphere may not pass below the ground within the step, and one below it is pushed
out at `fall_correction` of its depth per step), with Coulomb friction. Falling is final for the
rest of the clip. Reasons: the impulse ground holds a lying body within millimetres where the
penalty ground sinks ~2 cm on impact, and the same impulse solver serves the colliders.

tracking_only: the tracking acceleration with the constrained legs, nothing else (no comfort,
balance or falling); stress, ZMP and balance error are still reported.
"""

from dataclasses import dataclass, field, replace

import math

import numpy as np
from scipy.linalg import cho_factor, cho_solve
from scipy.linalg.lapack import dpotrf, dpotrs, dsyevd
from scipy.ndimage import gaussian_filter1d

from ..body_roles import SIDES
from ..progress import run_to_end
from ..trajectories import Trajectories
from ..vectors import cross as cross_rows
from ..dynamics import kinematics, spatial
from ..dynamics.closed_loop import (SimulationError, _require_connected_body, _to_trajectories,
                                    weld_static_helpers)
from ..dynamics.ground_contact import default_contacts, point_jacobians
from ..dynamics.inertia_matrix import bias_forces, crba
from ..dynamics.inverse_dynamics import velocity_terms
from ..dynamics.model import build_model
from ..dynamics.strength import default_strength, limit_torques
from ..dynamics.balance import closest_boundary_point, inside
from .balance_control import balance_error, support_polygon
from .comfort_control import Settings as CriteriaSettings
from .comfort_control import body_parts, joint_stress, required_torques
from .contacts import contact_floor, support_intervals
from .dynamic_control import control_state, dynamic_control, stress_by_bone
from .tracking import TrackingController

NONE, PASSIVE, COMFORT, BALANCE = 0, 1, 2, 3


@dataclass
class Load:
    """`mass` kg carried at the centre of mass of bone `bone` (dynamics.model.build_model) from
    `start_time` (seconds from the clip's start)."""

    bone: str
    mass: float
    start_time: float = 0.0


@dataclass
class Impulse:
    """At `time` (s from the clip's start), on `bone` at `point` (bone frame, metres) along the
    world unit vector `direction`: `magnitude` N s at once when duration == 0 (changes the
    velocities), else `magnitude` newtons for `duration` seconds (an external force in inverse
    dynamics)."""

    time: float
    bone: str
    point: tuple
    direction: tuple
    magnitude: float
    duration: float = 0.0


@dataclass
class Collider:
    """Moving spheres (another character's bones, a fist): world centres (F, k, 3) per frame of
    the clip, radii (k,), velocities (F, k, 3); kinematic unless `mass` (kg) is finite."""

    positions: np.ndarray
    radii: np.ndarray
    velocities: np.ndarray
    mass: float = np.inf


@dataclass
class ControlSettings:
    gravity: tuple = (0.0, 0.0, -9.81)
    ground_height: float = None  # None: the input's floor (contacts.contact_floor)
    loads: tuple = ()  # Load
    impulses: tuple = ()  # Impulse
    colliders: tuple = ()  # Collider
    strength_scale: float = 1.0
    substeps: int = 1  # Euler steps per frame
    tracking_only: bool = False  # no comfort, balance or falling
    support_overrides: tuple = ()  # contacts.Contact
    # --- beyond the interface (documented defaults) ---
    restitution: float = 0.2  # colliders
    friction: float = 0.8  # Coulomb, colliders and the fallen body on the ground
    fall_time: float = 0.1  # s the falling criterion must hold before the figure falls
    fall_rate: float = 480.0  # Hz: steps per second once falling (at least `substeps` a frame): a
    # body knocked over hits the ground fast; at 120 Hz (4 a frame at 30 fps) a hand sank 4 cm
    fall_damping: float = 2.0  # 1/s, ragdoll joint damping as a rate on each DOF's H_ii
    fall_correction: float = 0.2  # share of a sphere's depth below the ground removed per step
    limit_stiffness: float = 300.0  # N m/rad, ragdoll joint limits
    limit_damping: float = 10.0
    contact_iterations: int = 30  # projected Gauss-Seidel sweeps
    # Gauss-Newton iterations of the planted legs' position re-solve after the step; 0 (default):
    # one, predicted from the step's own frames instead (_Loop._predicted_resolve: no forward
    # kinematics at the integrated configuration, ~9 % fewer instructions per CMU step; the feet
    # land within ~1e-6 m of the exact re-solve's, every thesis experiment gives the same outcome)
    foot_iterations: int = 0
    foot_damping: float = 1e-3  # damped least squares of the legs' IK (a straight knee is singular)
    # near a straight knee (the leg Jacobian's smallest singular value below singular_band, m) the
    # damping grows to singular_damping (_Loop._damping)
    singular_band: float = 0.1
    singular_damping: float = 0.1
    kinematic_fraction: float = 0.0015  # as closed_loop.Settings: fingers follow the input
    # joint armature as a share of each DOF's own inertia H_ii in the first frame (closed_loop's
    # armature_ratio): regularises DOF pairs that turn the same mass about nearly the same axis
    # (CMU's massless lower neck twisting with the neck: passive control asked 1e4 rad/s^2 of them)
    armature_ratio: float = 0.02
    # rad/s^2 (m/s^2 on the root): the largest change dynamic control may make to any DOF in a
    # step (the whole change is scaled down). Passive control makes a stressed joint give way at
    # (excess torque) / H_ii, which a glitch of a captured motion (CMU 131_01's first frames ask
    # 2.4 kN of the ground) turns into 1e4 rad/s^2 of a light neck
    max_dynamic_acceleration: float = 200.0
    weld_static_helpers: bool = True
    min_horizon: float = None  # tracking (TrackingController)
    max_horizon: float = 0.5
    # the input is taken as feasible for the performer (Oshita: "our method assumes that input
    # motion is already realistic"): the stress and ZMP excursion the input motion itself has, with
    # this body model and the detected support, are allowed at its frames (+-1), so control acts on
    # what loads, pushes and collisions add, not on the capture's and the model's errors
    input_allowance: bool = True
    # a captured supporting foot often slides (CMU 131_01: up to 10 cm while planted): the whole
    # input is moved with it (root offset, ControlResult.foot_skate) so planted feet stay put
    remove_foot_skate: bool = True
    criteria: CriteriaSettings = field(default_factory=CriteriaSettings)  # comfort/balance tolerances


@dataclass
class ControlResult:
    trajectories: Trajectories  # at the input's frames
    stress: np.ndarray  # (F, J, 3) N m per bone axis at the output acceleration
    # (F,) m, ZMP outside the support polygon, beyond the input's own excursion at that frame (0
    # inside or without support, NaN falling)
    balance_error: np.ndarray
    zmp: np.ndarray  # (F, 2) NaN without support
    mmp: np.ndarray  # (F, 2) NaN without support
    support: np.ndarray  # (F, 2) bool (left, right) feet planted
    polygon: list  # per frame (k, 2) support polygon
    control: np.ndarray  # (F, J) int8: 0 none, 1 passive, 2 comfort, 3 balance
    falling: np.ndarray  # (F,) bool
    foot_slide: np.ndarray  # (F, 2) m, horizontal travel of each planted foot's contact point since landing
    foot_skate: np.ndarray = None  # (F, 2) m, the root offset that removed the input's foot skate
    model: object = None
    ground_height: float = None  # m, the ground the body stood and fell on


def control(skeleton, trajectories, settings=None, on_frame=None):
    """Dynamic motion control of a skeleton following `trajectories` (see the module notes)."""
    return run_to_end(iter_control(skeleton, trajectories, settings, on_frame))


def iter_control(skeleton, trajectories, settings=None, on_frame=None):
    """control() as steps: yields the fraction of frames done, returns the ControlResult.

    on_frame(f, q, v), optional, is called at the start of each frame with copies of the body's
    state (the model's generalised positions and velocities); when it returns a (q, v) pair the
    body continues from that state (a caller replays a state it recorded, e.g. to switch inputs)."""
    loop = _Loop(skeleton, trajectories, settings or ControlSettings())
    nf = loop.tr.frame_count
    for f in range(nf):
        if on_frame is not None:
            state = on_frame(f, loop.q.copy(), loop.v.copy())
            if state is not None:
                loop.q, loop.v = (np.array(x, float) for x in state)
        loop.frame(f)
        yield (f + 1) / nf
    return loop.result()


# ---- the loop ---------------------------------------------------------------------------------

class _Body:
    """A model (one set of active loads) and what the steps need of it."""

    def __init__(self, model, strength):
        self.model = model
        self.data = model.create_data()
        self.contacts = default_contacts(model)
        self.parts = body_parts(model, self.contacts)
        self.strength = strength
        self.spheres = self.contacts.on(model)  # bodies (k,), body-frame centres (k, 3)
        self.sphere_hom = np.c_[self.spheres[1], np.ones(len(self.spheres[1]))]
        # per side, once per model: the foot's body and frame offset, the DOFs of the foot's
        # ancestors (its Jacobian's columns), and where the leg's own DOFs lie among them
        p = self.parts
        self.foot_body = [int(model.joint_body[f]) for f in p.feet]
        # the feet's bodies, and the root's and theirs, as index arrays (take converts a list per call)
        self.feet_rows = np.array(self.foot_body, np.intp)
        self.root_feet_rows = np.array([0] + self.foot_body, np.intp)
        self.foot_offset = [model.joint_offset[f] for f in p.feet]
        self.leg_cols = [np.asarray(c, int) for c in p.legs]
        self.leg_dofs = [np.flatnonzero(model.ancestors[b][model.dof_body] != 0) for b in self.foot_body]
        self.leg_pos = [np.searchsorted(dofs, cols) for dofs, cols in zip(self.leg_dofs, self.leg_cols)]
        # per foot (2, nb) its ancestors and (2, nv) their DOFs (as 0 / 1)
        self.feet_ancestors = np.ascontiguousarray(model.ancestors[self.foot_body], float)
        self.feet_dof_mask = (self.feet_ancestors[:, model.dof_body] != 0.0).astype(float)
        # per contact set: the rotations that swing the planted feet, the root's and their legs'
        # joints (_Loop._predicted_resolve)
        self.landing_dofs = {(a, b): np.concatenate([np.arange(3)] + [c for c, on in zip(self.leg_cols, (a, b)) if on])
                             for a in (False, True) for b in (False, True)}
        # both legs batched when they have the same layout (a symmetric rig): Jacobian columns
        # (2, k) and the leg's own columns among them (l,)
        same = (len(self.leg_dofs[0]) == len(self.leg_dofs[1])
                and np.array_equal(self.leg_pos[0], self.leg_pos[1]))
        self.legs_batched = (np.array(self.foot_body), np.array(self.foot_offset), np.array(self.leg_dofs),
                             self.leg_pos[0]) if same else None
        # both feet's sole points on their bodies (_Loop._soles)
        self.sole_bodies, self.sole_local = kinematics.points_on_bodies(
            model, np.concatenate(p.sole_joints), np.concatenate(p.sole_points))
        self.sole_split = len(p.sole_joints[0])
        # the sole points as (x, y, z, 1) on their bodies (_Loop._soles: one product with the
        # bodies' frames)
        self.sole_hom = np.c_[self.sole_local, np.ones(len(self.sole_local))]
        # per contact set (left, right on the ground): the sides' indices and their feet's bodies
        self.contact_sets = {}
        for contact in ((True, True), (True, False), (False, True)):
            sides = np.flatnonzero(contact)
            self.contact_sets[contact] = (sides, model.joint_body[np.asarray(p.feet)[sides]])
        self.feet_chain = _FeetChain(model, self.foot_body, self.foot_offset, self.leg_cols)


class _FeetChain:
    """The feet's frames and their legs' own Jacobian columns (_Loop._leg_jacobians' `frame` and
    `jac`) at a configuration, from the forward kinematics of the feet's ancestors alone: the
    position re-solve's needs, without the other bodies' frames, motion transforms and Jacobian
    columns. Bit for bit update_frames' and _leg_jacobians' values: the same products on the same
    rows (pointer doubling restricted to a set closed under taking parents stays in it)."""

    def __init__(self, model, foot_body, foot_offset, leg_cols):
        nb = model.nb
        chain = np.flatnonzero(model.ancestors[foot_body].any(axis=0))  # the feet and their ancestors
        n = len(chain)
        where = np.full(nb + 1, n)  # body -> row (nb, the identity above the base, -> n)
        where[chain] = np.arange(n)
        self.quat_index = (3 + 4 * chain[:, None] + np.arange(4)[None, :]).ravel()
        self.q2r = model.tree_q2r[chain]
        self.local = np.zeros((n + 1, 4, 4))
        self.local[:n] = model.tree[chain]
        self.local[n] = np.eye(4)
        self.doubling = [where[a[np.append(chain, nb)]] for a in model.doubling]
        self.feet = where[np.asarray(foot_body)]
        self.offsets = np.array(foot_offset)
        # per side, each leg DOF's motion subspace column (kinematics.motion_subspace's row) in the
        # flat (n, 19) rotations and levers (update_frames' parts)
        gather = model.motion_gather.reshape(6, 6)  # motion[b][i, j] = parts[b, gather[i, j]]
        self.cols = [np.asarray(c, int) for c in leg_cols]
        self.subspace = [19 * where[model.dof_body[c]][:, None] + gather[:, model.dof_slot[c]].T for c in self.cols]
        self.zero = np.zeros((n, 1))
        self.n = n

    def legs(self, q, feet):
        """Per side planted: (foot frame (4, 4), the leg's own Jacobian columns (6, l), its DOFs)."""
        n = self.n
        local = self.local
        quats = q.take(self.quat_index).reshape(n, 4)
        outer = (quats[:, :, None] * quats[:, None, :]).reshape(n, 1, 16)
        local[:n, :3, :3] = (outer @ self.q2r).reshape(n, 3, 3)
        local[0, :3, 3] = q[:3]
        frames = local
        for a in self.doubling:
            frames = frames.take(a, axis=0) @ frames
        frames = frames[:n]
        rot = frames[:, :3, :3]
        lever = (frames[:, :3, 3] @ spatial._SKEW_MAP).reshape(n, 3, 3) @ rot
        parts = np.concatenate((rot.reshape(n, 9), lever.reshape(n, 9), self.zero), axis=1).ravel()
        feet_frames = frames.take(self.feet, axis=0) @ self.offsets
        out = [None, None]
        for s in (0, 1):
            if not feet[s]:
                continue
            frame = feet_frames[s]
            x0, x1, x2 = frame[:3, 3].tolist()
            cols = parts.take(self.subspace[s])  # (l, 6)
            # column-major, as _leg_jacobians' fancy-indexed columns: the legs' damped least
            # squares (_dls) then take BLAS's same path, so the same arithmetic
            jac = np.empty((6, len(cols)), order="F")
            jac[:3] = cols[:, :3].T
            cross = np.array([[0.0, x2, -x1], [-x2, 0.0, x0], [x1, -x0, 0.0]])
            jac[3:] = (cols[:, 3:] - cols[:, :3] @ cross).T
            out[s] = (frame, jac, self.cols[s])
        return out


class _Loop:
    def __init__(self, skeleton, trajectories, st):
        tr = trajectories
        self.st, self.tr = st, tr
        sk = weld_static_helpers(skeleton, tr) if st.weld_static_helpers else skeleton
        _require_connected_body(sk)
        self.sk = sk
        self.basis0 = tr.basis()[0]
        total = sk.total_mass + sum(float(l.mass) for l in st.loads)
        self.kinematic_mass = st.kinematic_fraction * total
        self._bodies = {}
        self.body = self._body(self._active_loads(0.0))
        m = self.body.model
        self.desired_data = m.create_data()
        self.ground = float(contact_floor(sk, tr) if st.ground_height is None else st.ground_height)
        sup = support_intervals(sk, tr, st.support_overrides, floor=self.ground)
        self.support_in = np.stack([sup.get(s, np.zeros(tr.frame_count, bool)) for s in SIDES], axis=1)
        self._support_rows = self.support_in.tolist()  # (plain bools)
        self.skate = np.zeros((tr.frame_count, 2))
        self.dt_frame = 1.0 / tr.fps if tr.frame_count < 2 else float(np.mean(np.diff(tr.times)))
        if st.remove_foot_skate:
            self.skate = self._foot_skate(tr)
            pos, ori = tr.root_pose(sk)
            tr = self.tr = tr.with_root_pose(sk, pos + np.c_[self.skate, np.zeros(len(pos))], ori)
        self.tracking = TrackingController(m, sk, tr, min_horizon=st.min_horizon, max_horizon=st.max_horizon)
        self.dt_frame = self.tracking.dt
        self.impulses = [self._impulse(i) for i in st.impulses]
        # the input's sole points at every frame (unloaded body: one batched forward kinematics,
        # shared by the input allowance and the rolling anchor)
        rest = self._body(tuple(False for _ in self.st.loads))
        k = rest.sole_split
        pts = _sole_points(rest.model, self.tracking.q_d, rest.parts)
        self._input_soles = (pts[:, :k], pts[:, k:])
        self._criteria = {}
        self.allow_tau, self.allow_zmp = self._input_allowance() if st.input_allowance else (None, None)
        self.roll_weights, self.roll = self._rolling_anchor()
        self._grid_targets = [self._input_feet(self.body, f * self.dt_frame) for f in range(tr.frame_count)]
        self._soles_cache = None
        self._eye6 = st.foot_damping ** 2 * np.eye(6)
        self._singular = (st.singular_band ** 2, st.singular_damping ** 2)
        self._drift = [None, None]  # per side: (contact drift (2,), last sole points (k, 3))
        self.q = self.tracking.q_d[0].copy()
        self.v = self.tracking.v_d[0].copy()
        self.t = 0.0
        # per side: (world offset (3,), rolling-anchor offset at landing (3,), their difference: what
        # moves the input foot onto the planted one while it stays planted)
        self.planted = [None, None]
        self.fallen = False
        self._targets_cache = None
        self._legs_cache = None
        self._dls_factors = {}  # id(leg Jacobian): (Jacobian, Cholesky factor), the legs at one q
        self.unbalanced = 0.0  # s the ZMP has stayed outside what balance control can reach
        self.collider_wrench = None  # (nb, 6) contact forces of the last step's collisions
        nf, J = tr.frame_count, sk.joint_count
        self.out_q = np.zeros((nf, m.nq))
        self.stress = np.zeros((nf, J, 3))
        # stress_by_bone's entries (bone, axis) of the actuated DOFs in a frame's flat (J * 3) row
        # (every body of the loop has the same DOFs, _body)
        self._stress_index = 3 * m.dof_joint[6:] + m.dof_slot[6:]
        self.err = np.zeros(nf)
        self.zmp = np.full((nf, 2), np.nan)
        self.mmp = np.full((nf, 2), np.nan)
        self.support = np.zeros((nf, 2), bool)
        self.polygon = [np.zeros((0, 2))] * nf
        self.control = np.zeros((nf, J), np.int8)
        self.falling = np.zeros(nf, bool)
        self.slide = np.zeros((nf, 2))

    # ---- setup helpers ----

    def _active_loads(self, t):
        return tuple(t >= l.start_time - 1e-9 for l in self.st.loads)

    def _body(self, active):
        if active not in self._bodies:
            loads = {}
            for l, on in zip(self.st.loads, active):
                if on:
                    loads[l.bone] = loads.get(l.bone, 0.0) + float(l.mass)
            m = build_model(self.sk, reference_basis=self.basis0, loads=loads, gravity=self.st.gravity,
                            kinematic_mass=self.kinematic_mass)
            if self._bodies:
                ref = next(iter(self._bodies.values())).model
                if m.nv != ref.nv or not np.array_equal(m.body_joint, ref.body_joint):
                    raise SimulationError("a load changes which bones carry dynamics: put loads on bones "
                                          "with mass (hands, forearms, trunk)")
            if self.st.armature_ratio > 0.0:
                m.set_armature(self.st.armature_ratio * np.diag(crba(m, m.create_data(), self._q0(m))))
            strength = default_strength(m)
            strength = replace(strength, scale=strength.scale * self.st.strength_scale)
            self._bodies[active] = _Body(m, strength)
        return self._bodies[active]

    def _q0(self, m):
        pos, ori = self.tr.root_pose(self.sk)
        return m.configuration(pos[0], ori[0], self.tr.rotations[0])

    def _input_allowance(self):
        """Per input frame: (nv,) torque beyond strength and the ZMP's distance outside the support
        polygon of the input motion itself (unloaded body, no pushes), the max over frames f-1..f+1."""
        body = self._body(tuple(False for _ in self.st.loads))
        m, tk = body.model, self.tracking
        nf = self.tr.frame_count
        tau_x, zmp_x, self.allow_capture = np.zeros((nf, m.nv)), np.zeros(nf), np.zeros(nf)
        for f in range(nf):
            cs = control_state(m, body.data, tk.q_d[f], tk.v_d[f], self.support_in[f], body.strength,
                               ground_height=self.ground, parts=body.parts, settings=self.st.criteria)
            cs._cache["soles"] = [self._input_soles[0][f], self._input_soles[1][f]]
            tau, wrench = required_torques(cs, tk.a_d[f])
            tau_x[f] = np.abs(joint_stress(tau, cs.limits))
            zmp_x[f] = balance_error(cs, wrench)[2]
            self.allow_capture[f] = self._capture_error(cs)
        self.allow_capture = _window_max(self.allow_capture)
        return _window_max(tau_x), _window_max(zmp_x)

    def _frame_index(self, t):
        """The input frame a step at time t belongs to."""
        return min(int(math.floor(t / self.dt_frame + 1e-9)), self.tr.frame_count - 1)

    def _can_stop(self, cs, t):
        """Whether the figure can still stop over its feet: its capture point no further outside
        the support polygon than the input's own, plus _CAPTURE_TOLERANCE."""
        fi = self._frame_index(t)
        allowed = (self.allow_capture[fi] if self.allow_tau is not None else 0.0) + _CAPTURE_TOLERANCE
        return self._capture_error(cs) <= allowed

    def _capture_error(self, cs):
        """How far (m) the capture point (the centre of mass extrapolated by its velocity over
        sqrt(h / g), Hof 2005) lies outside the support polygon: where a standing figure can still
        stop without a step; 0 inside or without support."""
        return math.hypot(*self._capture_offset(cs))

    def _capture_offset(self, cs, v=None):
        """The capture point's offset (x, y) from the support polygon (from its nearest point; 0
        inside or without support), with velocities `v` (default the control state's)."""
        polygon = support_polygon(cs)
        if len(polygon) < 3:
            return 0.0, 0.0
        m, d = cs.model, cs.data
        com = kinematics.center_of_mass(m, d, cs.q)
        vel = kinematics.com_jacobian(m, d, cs.q) @ (cs.v if v is None else v)
        g = max(abs(float(self.st.gravity[2])), 1e-6)
        point = com[:2] + vel[:2] * np.sqrt(max(com[2] - self.ground, 1e-3) / g)
        if inside(polygon, point):
            return 0.0, 0.0
        near = closest_boundary_point(polygon, point)  # minimum_moment_point, point outside
        return float(point[0] - near[0]), float(point[1] - near[1])

    def _knocked_over(self, cs, t, v):
        """After an instant impulse (velocities `v`): whether its momentum carries the capture point
        further outside the support polygon than the figure could stop from: _CAPTURE_TOLERANCE,
        plus the input's own excursion when it stays on the side where the figure's capture point
        already was (a walk's runs ahead of its feet; a push the other way gets no such allowance)."""
        ax, ay = self._capture_offset(cs, v)
        bx, by = self._capture_offset(cs)
        fi = self._frame_index(t)
        own = self.allow_capture[fi] if self.allow_tau is not None and ax * bx + ay * by > 0.0 else 0.0
        return math.hypot(ax, ay) > own + _CAPTURE_TOLERANCE

    def _allowance(self, t):
        if self.allow_tau is None:
            return None, self.st.criteria
        fi = self._frame_index(t)
        zmp = float(self.allow_zmp[fi])
        if zmp <= self.st.criteria.zmp_tolerance:
            return self.allow_tau[fi], self.st.criteria
        crit = self._criteria.get(zmp)  # one Settings per tolerance (dataclasses.replace is slow)
        if crit is None:
            crit = self._criteria[zmp] = replace(self.st.criteria, zmp_tolerance=zmp)
        return self.allow_tau[fi], crit

    def _impulse(self, imp):
        d = np.asarray(imp.direction, float)
        d = d / max(np.linalg.norm(d), 1e-12)
        return (float(imp.time), float(imp.duration), self.sk.index(imp.bone), np.asarray(imp.point, float),
                float(imp.magnitude) * d)

    # ---- one frame ----

    def frame(self, f):
        """Record frame f's state and diagnostics, then step to the next frame (none after the last)."""
        last = f == self.tr.frame_count - 1
        self.out_q[f] = self.q
        n = self._fall_steps() if self.fallen else max(1, self.st.substeps)
        for k in range(1 if last else n):
            self.step(f, self.dt_frame / n, record=k == 0, integrate=not last)

    def step(self, f, dt, record, integrate):
        st = self.st
        body = self._body(self._active_loads(self.t))
        self.body = body
        m, d = body.model, body.data
        q, v, t = self.q, self.v, self.t
        f_ext = self._forces(body, t)
        if self.fallen:
            feet = np.zeros(2, bool)
        else:
            fi = self._frame_index(t)
            feet = self.support_in[fi].copy()
            self._update_plants(body, feet, t)
        planted = bool(feet[0] or feet[1])  # (a Python bool: feet.any() costs a numpy call)
        a_raw = None if self.fallen else self.tracking.acceleration(t, q, v)  # a ragdoll tracks nothing
        targets = self._foot_targets(body, feet, t) if planted else None
        a_track = self._constrain_legs(body, q, v, a_raw, feet, targets) if targets is not None else a_raw
        fall = None
        if self.fallen:
            a = None
        else:
            allow, criteria = self._allowance(t)
            cs = control_state(m, d, q, v, feet, body.strength, f_ext=f_ext, ground_height=self.ground,
                               parts=body.parts, settings=criteria, allowance=allow)
            cs._cache["soles"] = self._soles(body, q)
            if planted:  # the sides in contact and their foot bodies (ControlState.sides,
                # comfort_control._ground_wrenches), known here
                cs._cache["sides"], cs._cache["foot_bodies"] = body.contact_sets[bool(feet[0]), bool(feet[1])]
            if st.tracking_only:
                a = a_track
                if record:
                    self._record_diagnostics(f, cs, a, feet)
            else:
                res = dynamic_control(cs, a_track)
                if res.falling is not None:
                    a_track, res = self._slower_return(body, cs, t, a_raw, a_track, res, feet, targets)
                # no action: the change is exactly zero (DynamicResult.acted)
                a = a_track + _bounded(res.delta, st.max_dynamic_acceleration) if res.acted else a_track
                fall = res.falling
                if record:
                    self._record_result(f, cs, res, feet)
                self.unbalanced = self.unbalanced + dt if fall is not None else 0.0
                if (fall is not None and self.unbalanced >= st.fall_time - 1e-9
                        and not self._can_stop(cs, t)):
                    a = a + fall.base_acceleration
                else:
                    fall = None
        if record:
            self.falling[f] = self.fallen or fall is not None
            if self.falling[f]:  # no support to measure against: no balance error
                self.err[f] = np.nan
            self.support[f] = feet
            for s in range(2):
                if feet[s] and self.planted[s] is not None:
                    self.slide[f, s] = self._contact_drift(body, q, s, f)
        if not integrate:
            return
        try:
            with _raising():
                if self.fallen:
                    v = self._ragdoll_velocity(body, q, v, dt, f_ext)
                else:
                    v = v + dt * a
                v, pushed = self._apply_impulses(body, q, v, t, dt, feet if planted else None)
                if pushed and planted and fall is None and not st.tracking_only and self._knocked_over(cs, t, v):
                    # knocked over: the impulse's momentum carries the capture point beyond where the
                    # feet could stop it; planted feet would take that momentum back (their
                    # projection acts as an unbounded ground) and spin the upper body instead
                    fall = KNOCKED_OVER
                v = self._collide(body, q, v, t, dt, ground=self.fallen or fall is KNOCKED_OVER)
                if fall is not None:
                    self.fallen = True
                    self.planted = [None, None]
                    feet[:] = False
                planted = planted and fall is None  # a fall releases the feet (above)
                resolve = correction = None
                if planted:  # the feet's velocity over the step: the targets' at its end
                    targets = self._foot_targets(body, feet, t + dt)
                    v = self._project_velocity(body, q, v, feet, targets)
                    # the positions' re-solve: predicted from the frames at q (_predicted_resolve),
                    # or after the step (a violent step, a foot lifting, foot_iterations)
                    if st.foot_iterations == 0:
                        correction = self._predicted_resolve(body, q, v, feet, targets, dt)
                    resolve = correction is None
                # semi-implicit Euler: with tracking.step_consistent's input velocities it steps
                # onto the input's frames and velocities exactly (test_motion_control_tracking)
                q = kinematics.integrate(m, q, v * dt if correction is None else v * dt + correction)
                self.t = t + dt
                if resolve:
                    q = self._project_position(body, q, feet, targets, max(st.foot_iterations, 1))
        except (np.linalg.LinAlgError, FloatingPointError) as exc:
            raise SimulationError(f"the motion control diverged at frame {self.tr.frames[f]:g}: {exc}") from None
        # (a sum of q and v is finite when both are: one overflowing sum would take values of
        # 1e306, which no body reaches without diverging first)
        if not math.isfinite(float(np.add.reduce(q)) + float(np.add.reduce(v))):
            raise SimulationError(f"the motion control diverged at frame {self.tr.frames[f]:g}")
        self.q, self.v = q, v

    def _slower_return(self, body, cs, t, a_raw, a_track, res, feet, targets):
        """When balance control cannot keep the ZMP in the support polygon, return to the input
        more slowly before giving in to a fall: the tracking's feedback (its acceleration beyond the
        input's own) scaled by each of RETURN_SCALES until one balances. Only while the figure can
        still stop on its feet (capture point within the support polygon, or no further out than
        the input's own): a figure pushed beyond that falls, as in the thesis."""
        if not self._can_stop(cs, t):  # it cannot stop without a step: it falls
            return a_track, res
        a_d = self.tracking.desired_state(t)[2]
        for scale in RETURN_SCALES:
            a = a_d + scale * (a_raw - a_d)
            if targets is not None:
                a = self._constrain_legs(body, cs.q, cs.v, a, feet, targets)
            out = dynamic_control(cs, a)
            if out.falling is None:
                return a, out
        return a_track, res

    # ---- diagnostics ----

    def _record_result(self, f, cs, res, feet):
        m = cs.model
        # stress_by_bone into the frame's (zero) row
        self.stress[f].put(self._stress_index, res.stress_after[6:])
        self.polygon[f] = res.polygon
        if res.zmp is not None:
            self.zmp[f] = res.zmp
            self.mmp[f] = res.mmp
            dx, dy = float(res.zmp[0] - res.mmp[0]), float(res.zmp[1] - res.mmp[1])
            self.err[f] = self._excess(math.sqrt(dx * dx + dy * dy), cs)
        if not res.acted:  # no mask is set: the row stays zero
            return
        code = np.zeros(m.nv, np.int8)
        code[res.log.passive] = PASSIVE
        code[res.log.comfort] = np.maximum(code[res.log.comfort], COMFORT)
        code[res.log.balance] = BALANCE
        per_bone = np.zeros(m.skeleton.joint_count, np.int8)
        np.maximum.at(per_bone, m.dof_joint[6:], code[6:])
        self.control[f] = per_bone

    def _record_diagnostics(self, f, cs, a, feet):
        tau, wrench = required_torques(cs, a)
        self.stress[f] = stress_by_bone(cs.model, joint_stress(tau, cs.limits, cs.settings.torque_tolerance))
        poly = support_polygon(cs)
        self.polygon[f] = poly
        p, mmp, dist = balance_error(cs, wrench, poly)
        if p is not None:
            self.zmp[f], self.mmp[f], self.err[f] = p, mmp, self._excess(dist, cs)

    @staticmethod
    def _excess(dist, cs):
        """The balance error beyond what the input itself has at this frame (its allowance)."""
        tol = cs.settings.zmp_tolerance
        return max(0.0, dist - tol) if tol > _BALANCED else dist

    def result(self):
        m = self.body.model
        traj = _to_trajectories(m, self.sk, self.tr, self.out_q)
        return ControlResult(trajectories=traj, stress=self.stress, balance_error=self.err, zmp=self.zmp,
                             mmp=self.mmp, support=self.support, polygon=self.polygon, control=self.control,
                             falling=self.falling, foot_slide=self.slide, foot_skate=self.skate, model=m,
                             ground_height=self.ground)

    # ---- external input ----

    def _forces(self, body, t):
        """World wrenches (nb, 6) of the pushes active at t and the last step's collider forces."""
        m, d = body.model, body.data
        out = None
        for t0, dur, j, point, force in self.impulses:
            if dur > 0.0 and t0 <= t < t0 + dur:
                x = kinematics.point_positions(m, d, self.q, [j], [point])[0]
                w = np.zeros((m.nb, 6))
                w[m.joint_body[j]] = np.r_[_cross(x, force), force]
                out = w if out is None else out + w
        if self.collider_wrench is not None:
            out = self.collider_wrench if out is None else out + self.collider_wrench
        return out

    def _apply_impulses(self, body, q, v, t, dt, feet=None):
        """Instant impulses falling in [t, t + dt): dv = H^-1 J' p, with the tracking servo's damping
        over the step (_servoed_inertia) and the planted `feet` held (_through_feet; None: no foot
        planted). Returns (v, whether any)."""
        m, d = body.model, body.data
        pushed = False
        for t0, dur, j, point, p in self.impulses:
            if dur == 0.0 and t - 1e-9 <= t0 < t + dt - 1e-9:
                jac = kinematics.point_jacobian(m, d, q, j, point)
                inertia = cho_factor(self._servoed_inertia(body, q, t, dt))
                dv = cho_solve(inertia, jac.T @ p)
                if feet is not None:
                    dv = self._through_feet(body, q, feet, inertia, dv)
                v = v + dv
                pushed = True
        return v, pushed

    def _servoed_inertia(self, body, q, t, dt):
        """H with the tracking servo's damping over the step: H_ii (1 + 4 dt / h_i) on each actuated
        DOF, h_i its horizon. The Ferguson acceleration (eq. 2.6) falls by 4 / h per unit of
        velocity; within the step of an impulse it resists the velocity the impulse gives, taken
        implicitly as the step integrates it. Without it a push met free joints: 45 N s on the
        standing metarig's pelvis spun the light pelvis at 14 rad/s and its legs thrashed. A
        fallen body has no servo (its ragdoll damping is the step's own)."""
        m = body.model
        h = _inertia(m, body.data, q)
        if not self.fallen:
            gain = (4.0 * dt) / (self.tracking.target_times(t) - t)
            gain[:6] = 0.0  # the root is not actuated
            h.flat[::m.nv + 1] *= 1.0 + gain
        return h

    def _through_feet(self, body, q, feet, inertia, dv):
        """A push's velocity change on a body standing on planted feet: the feet are contacts that
        do not move during the impulse, so the ground takes its share (dv projected in the inertia
        metric onto Jc dv = 0). The floating body's response would carry the pelvis away from
        feet the legs then cannot reach: with straight legs they could only follow it by
        flexing a knee through its singularity."""
        rows = []
        for leg in self._leg_jacobians(body, q, feet):
            if leg is not None:
                full, _, dofs, _, _ = leg
                row = np.zeros((6, len(dv)))
                row[:, dofs] = full
                rows.append(row)
        jc = np.concatenate(rows)
        h_jc = cho_solve(inertia, jc.T)
        # (a straight leg cannot move its foot along itself: Jc H^-1 Jc' is then singular, and
        # Jc dv lies in its range)
        lam = np.linalg.lstsq(jc.dot(h_jc), jc.dot(dv), rcond=1e-10)[0]
        return dv - h_jc.dot(lam)

    # ---- planted feet (sec. 2.4.2) ----

    def _update_plants(self, body, feet, t):
        for s in range(2):
            if not feet[s]:
                self.planted[s] = None
            elif self.planted[s] is None:
                self.planted[s] = self._landing(body, s, t)
                self._drift[s] = None

    def _landing(self, body, s, t):
        """A landing foot's offset from the input's (head position, roll offset, their difference).
        The foot may land turned from the input's (a push changed its swing); its first target
        turns it to the input's rotation at once, so the offset makes that turn one about the
        contact point (the input's contact weights at t), not the ankle, which slid the contact
        2.4 mm (the demo's push)."""
        m, b, offset = body.model, body.foot_body[s], body.foot_offset[s]
        kinematics.update_frames(m, self.desired_data, self.tracking.desired_state(t)[0])
        want = self.desired_data.frames[b] @ offset
        contact = self.roll_weights[s][min(int(round(t / self.tracking.dt)), len(self.roll_weights[s]) - 1)] \
            @ self._soles(body, self.q)[s]  # (body.data now at q)
        now = body.data.frames[b] @ offset
        head = contact - want[:3, :3] @ (now[:3, :3].T @ (contact - now[:3, 3]))
        roll = self._roll_offset(s, t)[0]
        return (head - want[:3, 3], roll, head - want[:3, 3] - roll)

    def _foot_skate(self, tr):
        """The input's foot skate as a root offset (F, 2): what moves the whole motion so that the
        contact point of a supporting foot stays where it is (the mean over both feet in double
        support; held while no foot supports). The capture's own root travel is otherwise kept."""
        m = self.body.model
        pos, ori = tr.root_pose(self.sk)
        qs = m.configurations(pos, ori, tr.rotations)
        steps = [step for _, step in _contact_steps(m, qs, self.body.parts)]
        out = np.zeros((tr.frame_count, 2))
        for f in range(1, tr.frame_count):
            sides = [s for s in range(2) if self.support_in[f, s] and self.support_in[f - 1, s]]
            out[f] = out[f - 1] - (np.mean([steps[s][f - 1] for s in sides], axis=0) if sides else 0.0)
        # the offset's velocity jumps where the supporting feet change: smoothed over ~0.05 s so
        # the root gets no acceleration spike (the planted feet's rolling anchor takes the rest)
        return gaussian_filter1d(out, _SKATE_SMOOTHING / self.dt_frame, axis=0, mode="nearest")

    def _rolling_anchor(self):
        """A planted foot rolls (heel to toe) but its contact does not slide: per input frame and
        side, the weights of the sole points in contact (the lowest ones) and the horizontal offset
        (F, 2, 3) that cancels the input's own travel of that contact point over each support
        interval (capture's foot skate included)."""
        body = self._body(tuple(False for _ in self.st.loads))
        nf = self.tr.frame_count
        weights, roll = [], np.zeros((nf, 2, 3))
        for s, (w, step) in enumerate(_contact_steps(body.model, self.tracking.q_d, body.parts, self._input_soles)):
            weights.append(w)
            for f in range(1, nf):
                if self.support_in[f, s] and self.support_in[f - 1, s]:
                    roll[f, s, :2] = roll[f - 1, s, :2] - step[f - 1]
        return weights, roll

    def _roll_offset(self, s, t):
        """The rolling anchor's offset (3,), velocity and acceleration at time t (linear between
        frames; central differences)."""
        x = float(np.clip(t / self.dt_frame, 0.0, self.tr.frame_count - 1))
        f0 = min(int(np.floor(x)), self.tr.frame_count - 1)
        f1 = min(f0 + 1, self.tr.frame_count - 1)
        r = self.roll[:, s]
        pos = r[f0] + (x - f0) * (r[f1] - r[f0])
        fm, fp = max(f0 - 1, 0), f1
        vel = (r[fp] - r[fm]) / (max(fp - fm, 1) * self.dt_frame)
        acc = (r[fp] - 2.0 * r[f0] + r[fm]) / self.dt_frame ** 2 if fp - fm == 2 else np.zeros(3)
        supported = self.support_in[fm:fp + 1, s].all()
        return pos, (vel if supported else np.zeros(3)), (acc if supported else np.zeros(3))

    def _soles(self, body, q):
        """World sole points of both feet at q, [(k, 3), (k, 3)], one forward-kinematics pass
        (shared by the control state, the support polygon and the drift measure)."""
        key = (q.tobytes(), id(body))
        if self._soles_cache is None or self._soles_cache[0] != key:
            kinematics.update_frames(body.model, body.data, q)
            pts = kinematics.body_points(body.data, body.sole_bodies, body.sole_hom)
            k = body.sole_split
            self._soles_cache = (key, [pts[:k], pts[k:]])
        return self._soles_cache[1]

    def _contact_drift(self, body, q, s, f):
        """Horizontal travel (m) of the planted foot's contact point since landing: the sole points'
        steps weighted by the input's contact weights (a roll about the contact is no travel)."""
        pts = self._soles(body, q)[s]
        last = self._drift[s]
        if last is None:  # (plain floats: 0.0 + d is d)
            dx = dy = 0.0
        else:
            ex, ey = self.roll_weights[s][f].dot(pts[:, :2] - last[1][:, :2]).tolist()
            dx, dy = last[0][0] + ex, last[0][1] + ey
        self._drift[s] = ((dx, dy), pts)
        return math.sqrt(dx * dx + dy * dy)

    def _foot_targets(self, body, feet, t):
        # remembered for the same time, feet, plants and body (the plants are tuples made anew at
        # each landing, _update_plants, and the cache holds them: identity is their key)
        f0, f1 = bool(feet[0]), bool(feet[1])
        p0, p1 = self.planted
        c = self._targets_cache
        if c is not None and c[0] == t and c[1] == f0 and c[2] == f1 and c[3] is p0 and c[4] is p1 and c[5] is body:
            return c[6]
        out = self._foot_targets_at(body, feet, t)
        self._targets_cache = (t, f0, f1, p0, p1, body, out)
        return out

    def _foot_targets_at(self, body, feet, t):
        """Per planted side: the input foot's world rotation (3, 3), head position (3,), 6-D velocity
        and 6-D acceleration (angular; head point), moved by the landing offset."""
        f = self.tracking._on_frame(t)
        feet_in = self._grid_targets[f] if f is not None else self._input_feet(body, t)
        out = [None, None]
        for s in (0, 1):
            if not feet[s]:
                continue
            rot, pos, vel, acc = feet_in[s]
            out[s] = (rot, pos + self.planted[s][2], vel, acc)
        return out

    def _input_feet(self, body, t):
        """Both input feet at time t, without their skate (rolling anchor): world rotation, head
        position, 6-D velocity and acceleration (precomputed on the frame grid)."""
        m, dd = body.model, self.desired_data
        qd, vd, ad = self.tracking.desired_state(t)
        vel, acc = kinematics.body_accelerations(m, dd, qd, vd, ad)
        out = []
        for s in range(2):
            foot = body.parts.feet[s]
            b = m.joint_body[foot]
            frame = dd.frames[b] @ m.joint_offset[foot]
            x = frame[:3, 3]
            w, vo = vel[b, :3], vel[b, 3:]
            al, ao = acc[b, :3], acc[b, 3:]
            xd = vo + _cross(w, x)
            xdd = ao + _cross(al, x) + _cross(w, xd)
            roll, roll_v, roll_a = self._roll_offset(s, t)
            out.append((frame[:3, :3], x + roll, np.concatenate((w, xd + roll_v)),
                        np.concatenate((al, xdd + roll_a))))
        return out

    def _leg_jacobians(self, body, q, feet):
        """Per planted side: the (6, k) Jacobian of the foot's angular velocity and head velocity
        on the DOFs of the foot's ancestors (the rest of its (6, nv) Jacobian is zero), the foot's
        world frame, those DOFs (k,), and the Jacobian's columns of the leg's own DOFs (6, l) with
        those DOFs (l,); one forward-kinematics pass for both legs (cached for the same q: the
        legs' acceleration and velocity projections share it)."""
        key = (q.tobytes(), bool(feet[0]), bool(feet[1]), id(body))
        if self._legs_cache is not None and self._legs_cache[0] == key:
            return self._legs_cache[1]
        m, d = body.model, body.data
        self._dls_factors.clear()  # the factors of the previous configuration's legs
        kinematics.update_frames(m, d, q)
        sub = kinematics.motion_subspace(m, d, q)  # (nv, 6) world (omega, v at origin)
        out = [None, None]
        if feet[0] and feet[1] and body.legs_batched is not None:
            out = self._both_legs(body, d, sub)
            self._legs_cache = (key, out)
            return out
        for s in (0, 1):
            if not feet[s]:
                continue
            frame = d.frames[body.foot_body[s]].dot(body.foot_offset[s])
            x0, x1, x2 = frame[:3, 3].tolist()
            dofs = body.leg_dofs[s]
            cols = sub.take(dofs, axis=0)  # (k, 6)
            jac = np.empty((6, len(dofs)))
            jac[:3] = cols[:, :3].T
            # head velocity v_O + omega x x = v_O - x x omega; rows @ K = x x row
            cross = np.array([[0.0, x2, -x1], [-x2, 0.0, x0], [x1, -x0, 0.0]])
            jac[3:] = (cols[:, 3:] - cols[:, :3].dot(cross)).T
            out[s] = (jac, frame, dofs, jac[:, body.leg_pos[s]], body.leg_cols[s])
        self._legs_cache = (key, out)
        return out

    def _both_legs(self, body, d, sub):
        """_leg_jacobians of two planted legs of the same layout, in batched products."""
        bodies, offsets, dofs, pos = body.legs_batched
        frames = d.frames.take(bodies, axis=0) @ offsets  # (2, 4, 4); take: a third of [bodies]'s cost
        (a0, a1, a2), (b0, b1, b2) = frames[:, :3, 3].tolist()
        cross = np.array([[[0.0, a2, -a1], [-a2, 0.0, a0], [a1, -a0, 0.0]],
                          [[0.0, b2, -b1], [-b2, 0.0, b0], [b1, -b0, 0.0]]])
        cols = sub.take(dofs, axis=0)  # (2, k, 6)
        jac = np.empty((2, 6, dofs.shape[1]))
        jac[:, :3] = cols[:, :, :3].swapaxes(1, 2)
        jac[:, 3:] = (cols[:, :, 3:] - cols[:, :, :3] @ cross).swapaxes(1, 2)
        leg = jac[:, :, pos]  # (2, 6, l)
        return [(jac[i], frames[i], dofs[i], leg[i], body.leg_cols[i]) for i in (0, 1)]

    def _dls(self, jac, r):
        """Damped least squares J' (J J' + lambda^2)^-1 r of a (6, k) leg Jacobian (one right-hand
        side per solve: OpenBLAS wakes its thread pool for a matrix of right-hand sides, whose
        spinning then costs more CPU than the factorisations it would share). The Cholesky factor
        is remembered per Jacobian (the acceleration and velocity projections share the legs at
        q): dposv's own dpotrf and dpotrs, so the same arithmetic."""
        known = self._dls_factors.get(id(jac))
        if known is None or known[0] is not jac:
            jj = jac.dot(jac.T)
            c, info = dpotrf(jj + self._damping(jj))
            if info != 0:
                raise np.linalg.LinAlgError("a planted leg's Jacobian is singular")
            known = self._dls_factors[id(jac)] = (jac, c)
        x, info = dpotrs(known[1], r)
        if info != 0:
            raise np.linalg.LinAlgError("a planted leg's Jacobian is singular")
        return jac.T.dot(x)

    def _damping(self, jj):
        """lambda^2 I for the damped least squares of a leg with J J' = jj: foot_damping, growing
        to singular_damping as the smallest singular value of J falls through singular_band
        (adaptive damping, Nakamura and Hanafusa 1986). A leg near straight cannot move its foot
        along itself; undamped, each step's millimetres of error along it asked the knee for
        degrees, the next step's the other way, and a standing figure's knees thrashed after a
        10 N s push."""
        band2, extra = self._singular
        low = dsyevd(jj, compute_v=0)[0][0]  # the smallest eigenvalue of J J': sigma_min^2
        if low >= band2:
            return self._eye6
        return self._eye6 + (extra * (1.0 - max(low, 0.0) / band2)) * _EYE6

    def _constrain_legs(self, body, q, v, a, feet, targets):
        """Leg accelerations that give each planted foot its target acceleration: the tracking
        ones plus the least change (the acceleration form of the leg's IK for the pelvis's
        acceleration)."""
        m, d = body.model, body.data
        legs = self._leg_jacobians(body, q, feet)  # the frames at q
        # kinematics.body_accelerations, the accelerations only at the feet's bodies
        vel, _, product = velocity_terms(m, d, q, v)  # shared with the inverse dynamics
        # the joint accelerations' part as the motion subspace columns of the feet's ancestor
        # DOFs (2-D products, no per-body stack)
        sub = kinematics.motion_subspace(m, d, q)
        acc = ((body.feet_dof_mask * a).dot(sub) + body.feet_ancestors.dot(product)).tolist()
        vel = vel.take(body.feet_rows, axis=0).tolist()
        a = a.copy()
        for s, leg in enumerate(legs):
            if leg is None:
                continue
            _, frame, _, jac, cols = leg
            x = frame[:3, 3].tolist()
            w, vo, al, ao = vel[s][:3], vel[s][3:], acc[s][:3], acc[s][3:]
            now = al + _point_motion(w, vo, al, ao, x)[1]
            a[cols] += self._dls(jac, targets[s][3] - np.array(now))
        return a

    def _project_velocity(self, body, q, v, feet, targets):
        v = v.copy()
        for s, leg in enumerate(self._leg_jacobians(body, q, feet)):
            if leg is not None:  # the foot's velocity is linear in v: J v
                full, _, dofs, jac, cols = leg
                v[cols] += self._dls(jac, targets[s][2] - full.dot(v.take(dofs)))
        return v

    def _predicted_resolve(self, body, q, v, feet, targets, dt):
        """The planted legs' position re-solve (_project_position's Gauss-Newton step) without a
        forward kinematics at the integrated configuration: each foot's pose at q (+) v dt is
        predicted from the frames at q to second order, its head x + x' dt + x'' dt^2 / 2 and its
        rotation turned by omega dt + alpha dt^2 / 2, with the velocity-product acceleration of
        integrate's constant-velocity step (the rotating legs carry the foot on an arc), and the
        error to its target is corrected by the legs' damped least squares at q, added to the
        step (one integration). The residual is third order in the step (v dt). A (nv,) step,
        or None in a step this does not hold for: a planted leg's joint (or the root) turning
        more than LANDING_TURN, or a foot the input lifts at the step's end (the rolling anchor's
        offset ends with the support, _rolling_anchor, so its target pose jumps there)."""
        f0, f1 = bool(feet[0]), bool(feet[1])
        nxt = self._support_rows[self._frame_index(self.t + dt)]
        if (f0 and not nxt[0]) or (f1 and not nxt[1]):
            return None
        turns = v.take(body.landing_dofs[f0, f1])
        if np.maximum.reduce(np.abs(turns)) * dt > LANDING_TURN:  # (ndarray.max/min go through Python)
            return None
        m, d = body.model, body.data
        legs = self._leg_jacobians(body, q, feet)  # the frames at q
        vel, _, product = velocity_terms(m, d, q, v)  # the step's velocities
        acc = body.feet_ancestors.dot(product).tolist()
        vb = vel.take(body.root_feet_rows, axis=0).tolist()
        # integrate moves the root's origin along a straight line (its world velocity p' fixed over
        # the step), not on the screw of a constant spatial velocity: every body's spatial
        # acceleration then gets the root's (0, -omega x p')
        w0 = vb[0][:3]
        root = _cross3(w0, _add(vb[0][3:], _cross3(w0, q[:3].tolist())))
        h, h2 = dt, 0.5 * dt * dt
        step = np.zeros(m.nv)
        for s, leg in enumerate(legs):
            if leg is None:
                continue
            _, frame, _, jac, cols = leg
            x = frame[:3, 3].tolist()
            w, vo, al = vb[s + 1][:3], vb[s + 1][3:], acc[s][:3]
            ao = [acc[s][3] - root[0], acc[s][4] - root[1], acc[s][5] - root[2]]
            xd, xdd = _point_motion(w, vo, al, ao, x)  # the head point's velocity and acceleration
            p0, p1, p2 = targets[s][1].tolist()
            t0, t1, t2 = _rotation_log(targets[s][0].dot(frame[:3, :3].T), array=False)
            error = np.array([t0 - h * w[0] - h2 * al[0], t1 - h * w[1] - h2 * al[1], t2 - h * w[2] - h2 * al[2],
                              p0 - x[0] - h * xd[0] - h2 * xdd[0], p1 - x[1] - h * xd[1] - h2 * xdd[1],
                              p2 - x[2] - h * xd[2] - h2 * xdd[2]])
            step[cols] = self._dls(jac, error)
        return step

    def _project_position(self, body, q, feet, targets, iterations):
        m = body.model
        for _ in range(iterations):
            step = np.zeros(m.nv)
            # the feet's frames and their legs' own Jacobian columns at q: the step's own when q
            # has not moved (a figure at rest), else _FeetChain's (the forward kinematics of the
            # feet's ancestors alone, the same products as update_frames')
            key = (q.tobytes(), bool(feet[0]), bool(feet[1]), id(body))
            if self._legs_cache is not None and self._legs_cache[0] == key:
                legs = [None if leg is None else (leg[1], leg[3], leg[4]) for leg in self._legs_cache[1]]
            else:
                legs = body.feet_chain.legs(q, feet)
            for s, leg in enumerate(legs):
                if leg is None:
                    continue
                frame, jac, cols = leg
                rot, pos = targets[s][0], targets[s][1]
                error = np.concatenate((_rotation_log(rot @ frame[:3, :3].T), pos - frame[:3, 3]))
                step[cols] = self._dls(jac, error)
            q = kinematics.integrate(m, q, step)
        return q

    # ---- the fallen body ----

    def _fall_steps(self):
        """Steps in this frame of a fallen body: enough that no contact sphere travels more than
        FALL_STEP_TRAVEL in one (a body knocked over hits the ground fast: at 120 Hz, 4 steps a
        frame at 30 fps, a hand sank 4 cm), at most fall_rate a second, at least `substeps` a
        frame. A body lying on the ground, or coming to rest, needs no more steps than a standing
        one; a fixed fall_rate made every falling frame cost ~16 standing ones."""
        most = max(self.st.substeps, math.ceil(self.st.fall_rate * self.dt_frame - 1e-9))
        body = self.body
        m, d = body.model, body.data
        kinematics.update_frames(m, d, self.q)
        bodies = body.spheres[0]
        centres = kinematics.body_points(d, bodies, body.sphere_hom)
        vel = kinematics.body_velocities(m, d, self.q, self.v).take(bodies, axis=0)
        speed = float(np.sqrt(((vel[:, 3:] + _cross(vel[:, :3], centres)) ** 2).sum(axis=1).max()))
        return int(min(max(math.ceil(speed * self.dt_frame / FALL_STEP_TRAVEL), self.st.substeps, 1), most))

    def _ragdoll_velocity(self, body, q, v, dt, f_ext):
        st, m, d = self.st, body.model, body.data
        h = crba(m, d, q)
        hd = np.diag(h).copy()
        spring = limit_torques(m, q, np.zeros_like(v), st.limit_stiffness, 0.0)
        at_limit = spring != 0.0
        damp = st.fall_damping * hd + at_limit * (st.limit_damping + dt * st.limit_stiffness)
        damp[:6] = 0.0
        rhs = spring - bias_forces(m, d, q, v, f_ext=f_ext) - damp * v
        mat = h.copy()
        mat.flat[::m.nv + 1] += dt * damp
        out = v + dt * cho_solve(cho_factor(mat), rhs)
        # the velocity terms are explicit: a light segment spun fast (a toe, H_ii 2e-5 kg m^2)
        # feeds them quadratically and the fall diverged (numpy 2, a 40 N s push); no joint of a
        # body turns faster than RAGDOLL_JOINT_SPEED
        out[6:] = np.clip(out[6:], -RAGDOLL_JOINT_SPEED, RAGDOLL_JOINT_SPEED)
        return out

    # ---- contact impulses: colliders and the fallen body on the ground ----

    def _collide(self, body, q, v, t, dt, ground):
        """Impulses of the ground (when `ground`) and of the colliders on the velocities v (after the
        step's acceleration, before its position update); remembers the collider forces.

        Colliders are continuous (swept): each collider sphere's path over the step, relative to each
        body capsule (a bone's two contact spheres and the segment between them) moving at its
        velocity, is tested for the first instant it touches the capsule, so a fast fist cannot pass
        through the body between two steps. The impulse acts at that first contact with the relative
        velocity there (the collider's over the step: its displacement / dt). A collider of finite
        mass is one rigid body (its spheres share its mass) that gives one impulse per contact: it
        is spent until it has left the body (a thrown fist hits once; only a kinematic collider
        keeps pushing while it moves into the body)."""
        m, d = body.model, body.data
        self.collider_wrench = None
        swing = None if ground else _swing_spheres(body, self.planted)
        if not (ground or self.st.colliders or swing is not None):
            return v  # standing on both planted feet, nothing to collide with: no sphere is asked
        kinematics.update_frames(m, d, q)
        bodies = body.spheres[0]
        radii = body.contacts.radii
        centres = kinematics.body_points(d, bodies, body.sphere_hom)
        rows = []  # (sphere, point (3,), normal (3,), target normal speed, other velocity (3,), kind)
        vel = kinematics.body_velocities(m, d, q, v).take(bodies, axis=0)
        if ground or self.st.colliders:
            sphere_vel = vel[:, 3:] + _cross(vel[:, :3], centres)
            vz = sphere_vel[:, 2]
        else:  # a swing foot alone asks the spheres' vertical speed: v_z + (omega x centre)_z
            vz = vel[:, 5] + (vel[:, 0] * centres[:, 1] - vel[:, 1] * centres[:, 0])
        if ground:
            gap = centres[:, 2] - radii - self.ground
            # speculative: every sphere that could reach the ground within the step
            near = gap < np.maximum(-vz, 0.0) * dt + 0.01
            for k in np.flatnonzero(near):
                g = gap[k]
                target = -g / dt if g > 0 else -self.st.fall_correction * g / dt
                point = centres[k] - np.array([0.0, 0.0, radii[k]])
                rows.append((k, point, np.array([0.0, 0.0, 1.0]), target, np.zeros(3), None))
        elif swing is not None:  # standing: a foot that is not planted (a swing foot) may not pass below the ground
            gap = centres[:, 2] - radii - self.ground
            near = swing & (gap < np.maximum(-vz, 0.0) * dt)
            if near.any():
                v = self._swing_ground(body, q, v, dt, np.flatnonzero(near), centres, gap)
        # finite-mass colliders that gave their impulse and are still touching (kept across steps)
        spent = getattr(self, "_spent_colliders", set())
        self._spent_colliders = spent
        owners = [None] * len(rows)  # collider index per row (None: the ground)
        if self.st.colliders:
            ia, ib = _capsules(body.contacts)
        for ci, col in enumerate(self.st.colliders):
            p0, p1 = self._collider_at(col, t)[0], self._collider_at(col, t + dt)[0]
            rc = np.asarray(col.radii, float)
            hits = _swept_contacts(centres[ia], centres[ib], radii[ia], 0.5 * (sphere_vel[ia] + sphere_vel[ib]) * dt,
                                   p0, p1, rc)
            if not hits:
                spent.discard(ci)
                continue
            if np.isfinite(col.mass) and ci in spent:  # a thrown body gave its impulse: it stays spent while in contact
                continue
            vel_c = (p1 - p0) / dt
            for cap, c, axis_point, n in hits:
                k = ia[cap]
                point = axis_point - radii[k] * n
                rows.append((k, point, n, None, vel_c[c], col.mass))
                owners.append(ci)
        if not rows:
            return v
        ks = np.array([r[0] for r in rows])
        points = np.array([r[1] for r in rows])
        jac = point_jacobians(m, d, q, bodies[ks], points)  # (c, 3, nv)
        normals = np.array([r[2] for r in rows])
        t1 = _cross(normals, [1.0, 0.0, 0.0])
        t1[np.linalg.norm(t1, axis=1) < 1e-6] = _cross(normals, [0.0, 1.0, 0.0])[np.linalg.norm(t1, axis=1) < 1e-6]
        t1 /= np.linalg.norm(t1, axis=1)[:, None]
        t2 = _cross(normals, t1)
        basis = np.stack((normals, t1, t2), axis=1)  # (c, 3, 3) rows n, t1, t2
        jr = np.einsum("cij,cjn->cin", basis, jac).reshape(-1, m.nv)  # (3c, nv)
        other = np.array([r[4] for r in rows])
        rel0 = jr @ v - np.einsum("cij,cj->ci", basis, other).ravel()
        targets = np.empty(len(rows))
        for i, r in enumerate(rows):
            if r[3] is not None:
                targets[i] = r[3]
            else:  # a collider: bounce at restitution when approaching
                vn = rel0[3 * i]
                targets[i] = -self.st.restitution * vn if vn < 0 else -np.inf
        active = targets > -np.inf
        if not active.any():
            return v
        idx = np.flatnonzero(active)
        sel = np.flatnonzero(np.repeat(active, 3))
        jr, rel0 = jr[sel], rel0[sel]
        targets = targets[active]
        chol = cho_factor(_inertia(m, d, q))
        hij = cho_solve(chol, jr.T)  # (nv, 3c)
        w = jr @ hij
        # a collider of finite mass M is one translating body: its rows couple through B B' / M
        rows_basis = basis[idx].reshape(-1, 3)  # (3c, 3)
        row_owner = np.repeat([-1 if owners[i] is None else owners[i] for i in idx], 3)
        for ci in set(row_owner[row_owner >= 0].tolist()):
            mass = float(self.st.colliders[ci].mass)
            if np.isfinite(mass) and mass > 0.0:
                rs = np.flatnonzero(row_owner == ci)
                w[np.ix_(rs, rs)] += rows_basis[rs] @ rows_basis[rs].T / mass
        p = _pgs(w, rel0, targets, self.st.friction, self.st.contact_iterations)
        v = v + hij @ p
        # collider contact forces for the next step's inverse dynamics: a kinematic collider keeps
        # pushing; a finite-mass one gave its whole momentum here (like an instant Impulse)
        wrench = None
        for j, i in enumerate(idx):
            if owners[i] is None:
                continue
            if np.isfinite(self.st.colliders[owners[i]].mass):
                spent.add(owners[i])
                continue
            force = basis[i].T @ p[3 * j:3 * j + 3] / dt
            x = rows[i][1]
            wrench = np.zeros((m.nb, 6)) if wrench is None else wrench
            wrench[bodies[rows[i][0]]] += np.r_[_cross(x, force), force]
        self.collider_wrench = wrench
        return v

    def _swing_ground(self, body, q, v, dt, ks, centres, gap):
        """Ground impulses on a swing foot's spheres acting on its leg's DOFs only (the leg's own
        inertia block): like the planted legs' projection, the foot is kept out of the ground
        without jarring the rest of the body (a landing step would otherwise kick the pelvis)."""
        m, d = body.model, body.data
        bodies = body.spheres[0]
        h = None
        for s, foot in enumerate(body.parts.feet):
            fb = m.joint_body[foot]
            mine = ks[m.ancestors[bodies[ks]][:, fb] != 0]
            if not len(mine):
                continue
            cols = np.asarray(body.parts.legs[s])
            points = centres[mine].copy()
            points[:, 2] -= body.contacts.radii[mine]
            jac = point_jacobians(m, d, q, bodies[mine], points)[:, :, cols]  # (c, 3, leg)
            jr = jac.reshape(-1, len(cols))  # rows x, y, z: z the normal
            jr = jr[np.r_[[[3 * i + 2, 3 * i, 3 * i + 1] for i in range(len(mine))]].ravel()]
            h = _inertia(m, d, q) if h is None else h
            hl = h[np.ix_(cols, cols)]
            hij = cho_solve(cho_factor(hl), jr.T)
            w = jr @ hij
            g = gap[mine]
            targets = np.where(g > 0, -g / dt, -self.st.fall_correction * g / dt)
            p = _pgs(w, jr @ v[cols], targets, self.st.friction, self.st.contact_iterations)
            v = v.copy()
            v[cols] += hij @ p
        return v

    def _collider_at(self, col, t):
        pos = np.asarray(col.positions, float)
        vel = np.asarray(col.velocities, float)
        x = np.clip(t / self.dt_frame, 0.0, len(pos) - 1)
        f0 = min(int(np.floor(x)), len(pos) - 1)
        f1 = min(f0 + 1, len(pos) - 1)
        w = x - f0
        return (1 - w) * pos[f0] + w * pos[f1], (1 - w) * vel[f0] + w * vel[f1]




if hasattr(np, "seterrobj"):  # numpy 1: np.errstate's error mask set directly (np.errstate: ~10 us a step)
    from numpy.core import umath as _umath

    _RAISE_MASK = ((_umath.ERR_RAISE << _umath.SHIFT_OVERFLOW) | (_umath.ERR_RAISE << _umath.SHIFT_INVALID))
    _KEEP_MASK = ~((7 << _umath.SHIFT_OVERFLOW) | (7 << _umath.SHIFT_INVALID))

    class _raising:
        """np.errstate(over="raise", invalid="raise")."""

        __slots__ = ("old",)

        def __enter__(self):
            old = self.old = np.geterrobj()
            np.seterrobj([old[0], (old[1] & _KEEP_MASK) | _RAISE_MASK, old[2]])

        def __exit__(self, *exc):
            np.seterrobj(self.old)
else:
    def _raising():
        return np.errstate(over="raise", invalid="raise")




def _cross3(a, b):
    """Cross product of two 3-sequences of floats (a list)."""
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def _add(a, b):
    return [a[0] + b[0], a[1] + b[1], a[2] + b[2]]


def _point_motion(w, vo, al, ao, x):
    """Velocity and acceleration (lists) of the world point x (3 floats) of a body of spatial
    velocity (w, vo) and acceleration (al, ao) at the origin: vo + w x x and ao + al x x + w x x';
    _add and _cross3's arithmetic in one call (the legs' projection and re-solve, per step)."""
    (w0, w1, w2), (x0, x1, x2), (a0, a1, a2) = w, x, al
    d0, d1, d2 = vo[0] + (w1 * x2 - w2 * x1), vo[1] + (w2 * x0 - w0 * x2), vo[2] + (w0 * x1 - w1 * x0)
    return [d0, d1, d2], [ao[0] + (a1 * x2 - a2 * x1) + (w1 * d2 - w2 * d1),
                          ao[1] + (a2 * x0 - a0 * x2) + (w2 * d0 - w0 * d2),
                          ao[2] + (a0 * x1 - a1 * x0) + (w0 * d1 - w1 * d0)]


def _cross(a, b):
    """Cross products of 3-vectors or (k, 3) stacks (np.cross costs ~20 us per call)."""
    a = np.asarray(a, float)
    b = np.asarray(b, float)
    if a.shape == (3,) and b.shape == (3,):  # plain floats: a tenth of the numpy calls' cost
        return np.array(_cross3(a.tolist(), b.tolist()))
    return cross_rows(a, b)


def _swing_spheres(body, planted):
    """(k,) bool: the contact spheres on the foot (and toes, heel) of each side not planted, or
    None when there is none (remembered per body and planted sides)."""
    key = (planted[0] is None, planted[1] is None)
    cache = body.__dict__.setdefault("_swing", {})
    if key not in cache:
        m, (bodies, _) = body.model, body.spheres
        out = np.zeros(len(bodies), bool)
        for s, foot in enumerate(body.parts.feet):
            if key[s]:
                fb = m.joint_body[foot]
                out |= m.ancestors[bodies][:, fb] != 0
        cache[key] = out if out.any() else None
    return cache[key]


def _capsules(contacts):
    """Sphere index pairs (a, b) of the contact geometry as capsules: a bone's two spheres of one
    radius (default_contacts puts them at its head and tail) and the segment between them; any
    other sphere is a capsule of zero length (a == b). Cached on the geometry."""
    cached = getattr(contacts, "_capsule_pairs", None)
    if cached is not None:
        return cached
    ia, ib = [], []
    joints, radii = np.asarray(contacts.joints), np.asarray(contacts.radii)
    for j in dict.fromkeys(joints.tolist()):
        ks = np.flatnonzero(joints == j)
        if len(ks) == 2 and radii[ks[0]] == radii[ks[1]] and radii[ks[0]] > 0.0:
            ia.append(ks[0]), ib.append(ks[1])
        else:
            ia.extend(ks), ib.extend(ks)
    out = (np.array(ia, int), np.array(ib, int))
    contacts._capsule_pairs = out
    return out


def _point_segment(p, a, b):
    """Closest points on segments a-b to points p (broadcast (..., 3))."""
    e = b - a
    den = np.maximum(np.einsum("...i,...i->...", e, e), 1e-18)
    u = np.clip(np.einsum("...i,...i->...", p - a, e) / den, 0.0, 1.0)
    return a + u[..., None] * e


_SWEEP_ITERATIONS = 24  # golden-section and bisection steps of the first contact (2^-24 of a step)


def _swept_contacts(a, b, rb, move, p0, p1, rc):
    """First contacts of collider spheres moving p0 -> p1 (c, 3) (radii rc (c,)) with capsules a-b
    (n, 3) (radii rb (n,)) moving by `move` (n, 3) over the step: a list of (capsule, sphere,
    closest axis point (3,), unit normal (3,) from the collider to the body) at the earliest instant
    each collider sphere touches (pairs touching within 5 % of a step of it included).

    The distance of a point moving on a line to a segment is convex in time: golden-section search
    finds its minimum, then bisection the first instant it comes within the radii."""
    if len(p0) == 0 or len(a) == 0:
        return []
    reach = rb.max() + rc.max()
    lo = np.minimum(np.minimum(a, b).min(axis=0), np.minimum(a + move, b + move).min(axis=0)) - reach
    hi = np.maximum(np.maximum(a, b).max(axis=0), np.maximum(a + move, b + move).max(axis=0)) + reach
    near = np.flatnonzero(np.all((np.maximum(p0, p1) >= lo) & (np.minimum(p0, p1) <= hi), axis=1))
    if not len(near):
        return []
    # relative motion: the capsule held still, the collider sphere moving by its path minus the capsule's
    start = p0[near][None, :, :] - np.zeros((len(a), 1, 3))  # (n, c, 3)
    path = (p1 - p0)[near][None, :, :] - move[:, None, :]
    aa, bb = a[:, None, :], b[:, None, :]
    limit = rb[:, None] + rc[near][None, :]

    def dist(s):
        x = start + s[..., None] * path
        return np.linalg.norm(x - _point_segment(x, aa, bb), axis=-1)

    shape = limit.shape
    lo_s, hi_s = np.zeros(shape), np.ones(shape)
    g = 0.5 * (np.sqrt(5.0) - 1.0)
    for _ in range(_SWEEP_ITERATIONS):  # the closest approach over the step
        m1, m2 = hi_s - g * (hi_s - lo_s), lo_s + g * (hi_s - lo_s)
        left = dist(m1) < dist(m2)
        hi_s = np.where(left, m2, hi_s)
        lo_s = np.where(left, lo_s, m1)
    s_min = 0.5 * (lo_s + hi_s)
    d0, d_min, d1 = dist(np.zeros(shape)), dist(s_min), dist(np.ones(shape))
    touch = (d0 <= limit) | (d_min <= limit) | (d1 <= limit)
    if not touch.any():
        return []
    s_min = np.where(d1 <= d_min, 1.0, s_min)
    lo_s, hi_s = np.zeros(shape), s_min.copy()
    for _ in range(_SWEEP_ITERATIONS):  # the first instant within reach, between the start and the minimum
        mid = 0.5 * (lo_s + hi_s)
        inside_ = dist(mid) <= limit
        hi_s = np.where(inside_, mid, hi_s)
        lo_s = np.where(inside_, lo_s, mid)
    s_hit = np.where(d0 <= limit, 0.0, hi_s)
    s_hit = np.where(touch, s_hit, np.inf)
    out = []
    for c in range(len(near)):
        first = s_hit[:, c].min()
        if not np.isfinite(first):
            continue
        for cap in np.flatnonzero(s_hit[:, c] <= first + 0.05):
            x = start[cap, c] + s_hit[cap, c] * path[cap, c]
            axis_point = _point_segment(x, a[cap], b[cap])
            n = axis_point - x
            size = np.linalg.norm(n)
            n = n / size if size > 1e-9 else path[cap, c] / max(np.linalg.norm(path[cap, c]), 1e-12)
            out.append((cap, near[c], axis_point, n))
    return out


RETURN_SCALES = (0.5, 0.25, 0.0)
LANDING_TURN = 0.1  # rad: the most a planted leg's joint (or the root) may turn in a step _predicted_resolve serves
KNOCKED_OVER = "knocked over"  # a step's fall from an impulse (no base acceleration: released as it is)
FALL_STEP_TRAVEL = 0.01  # m a contact sphere may travel in one step of a fallen body (_Loop._fall_steps)
RAGDOLL_JOINT_SPEED = 40.0  # rad/s (_Loop._ragdoll_velocity; strength.py's fastest joints: 40)
_BALANCED = 1e-3  # m: a ZMP tolerance above this is an input allowance (_Loop._excess)
# _Loop._slower_return: m beyond the input's own capture-point excursion (arms swung by passive
# control move the centre of mass quickly without the body falling; a 150 N s push: 0.6 m)
_CAPTURE_TOLERANCE = 0.2
_EYE6 = np.eye(6)


def _sole_points(model, qs, parts):
    """Both feet's sole points (F, k, 3) at every configuration (one batched forward kinematics)."""
    return kinematics.batch_point_positions(model, qs, np.concatenate(parts.sole_joints),
                                            np.concatenate(parts.sole_points))


def _contact_steps(model, qs, parts, soles=None):
    """Per side: per frame the weights (F, k) of a foot's sole points in contact (the lowest ones,
    by exp(-height above the lowest / _CONTACT_SCALE)) and the horizontal step (F - 1, 2) of that
    contact point from each frame to the next; `soles`: the sides' sole points if known."""
    if soles is None:
        soles = np.split(_sole_points(model, qs, parts), [len(parts.sole_joints[0])], axis=1)
    out = []
    for pts in soles:
        z = pts[..., 2]
        w = np.exp(-(z - z.min(axis=1, keepdims=True)) / _CONTACT_SCALE)
        w /= w.sum(axis=1, keepdims=True)
        out.append((w, np.einsum("fk,fkc->fc", w[1:], pts[1:, :, :2] - pts[:-1, :, :2])))
    return out


_SKATE_SMOOTHING = 0.02  # s, standard deviation of _Loop._foot_skate's smoothing
_CONTACT_SCALE = 0.01  # m: sole points this much above the lowest share the contact by exp(-dz / scale)


def _window_max(x):
    """Max over each frame and its neighbours (along axis 0)."""
    out = x.copy()
    out[1:] = np.maximum(out[1:], x[:-1])
    out[:-1] = np.maximum(out[:-1], x[1:])
    return out


def _bounded(delta, top):
    size = np.abs(delta).max() if len(delta) else 0.0
    return delta * (top / size) if size > top else delta


def _inertia(model, data, q):
    """H (the model's armature included, ControlSettings.armature_ratio)."""
    h = crba(model, data, q)
    h.flat[::model.nv + 1] += 1e-12
    return h


def _pgs(w, rel, targets, mu, iterations):
    """Projected Gauss-Seidel on contacts of three rows (normal, two tangents): normal impulses
    >= 0 that bring each normal speed up to its target (complementary), friction impulses within
    mu times the normal one that stop the sliding.

    Contact by contact, its three relative speeds come afresh from the impulses (one 3 x 3c
    product) and its rows are updated on plain floats through its own 3 x 3 block, instead of
    every row's speed being updated after each row: the same sweeps in a third fewer numpy calls
    (a fallen body's 25-30 ground contacts make this most of a falling step)."""
    n = len(targets)
    p = np.zeros(3 * n)
    rows = [w[3 * c:3 * c + 3] for c in range(n)]
    blocks = [w[3 * c:3 * c + 3, 3 * c:3 * c + 3].tolist() for c in range(n)]
    rel_rows = [rel[3 * c:3 * c + 3] for c in range(n)]
    targets = np.asarray(targets, float).tolist()
    for _ in range(iterations):
        change = 0.0
        for c in range(n):
            i = 3 * c
            u0, u1, u2 = (rel_rows[c] + rows[c] @ p).tolist()
            pn, p1, p2 = old = p[i:i + 3].tolist()
            (d0, _, _), (w10, d1, _), (w20, w21, d2) = blocks[c]
            new = max(0.0, pn + (targets[c] - u0) / d0)
            dp = new - pn
            if dp:
                pn = new
                u1 += w10 * dp
                u2 += w20 * dp
                change = max(change, abs(dp))
            cap = mu * pn
            new = min(max(p1 - u1 / d1, -cap), cap)
            dp = new - p1
            if dp:
                p1 = new
                u2 += w21 * dp
                change = max(change, abs(dp))
            new = min(max(p2 - u2 / d2, -cap), cap)
            dp = new - p2
            if dp:
                p2 = new
                change = max(change, abs(dp))
            if [pn, p1, p2] != old:
                p[i:i + 3] = pn, p1, p2
        if change < 1e-7:
            break
    return p


def _quat(rot):
    from .. import rotations
    return rotations.from_matrix(rot)


def _rotation_log(rot, array=True):
    """Rotation vector (3,) of a rotation matrix (angle below pi; the legs' small corrections); a
    list of floats when not `array`."""
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = np.asarray(rot, float).tolist()
    w = [0.5 * (r21 - r12), 0.5 * (r02 - r20), 0.5 * (r10 - r01)]
    sin = math.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
    if sin >= 1e-12:
        scale = math.atan2(sin, 0.5 * (r00 + r11 + r22 - 1.0)) / sin
        w = [w[0] * scale, w[1] * scale, w[2] * scale]
    return np.array(w) if array else w
