"""Closed-loop forward/inverse dynamics simulation (Huang 1996, ch. 3.5 and fig. 3-4).

Forward dynamics advances the body at a small step; at a coarser control step (one frame by
default, about ten small steps as Huang recommends) inverse dynamics computes the joint torques
that realise the desired accelerations, corrected by the tracking error so that errors never
accumulate (the "closed loop"), and the strength model clamps them. A PD servo is the alternative
controller. `tracking` scales the controller from 0 (pure ragdoll) to 1.

The root has no actuator: the base wrench that inverse dynamics asks for is applied only in the
share `root_support` (a "hand of God" on the pelvis: 1 reproduces motions that the simplified
contact cannot carry exactly, 0 is fully physical and the body keeps its balance only through the
ground). Ground contact forces measured at the start of a control step enter inverse dynamics as
known external forces; pushes do not (the body reacts to them through the feedback).
"""

from dataclasses import dataclass, field, replace

import numpy as np

from .. import rotations
from ..errors import HumanAnimError
from ..progress import run_to_end
from ..trajectories import Trajectories
from . import kinematics, spatial
from .balance import minimum_moment_point, support_polygon, zmp
from .forward_dynamics import aba, cholesky_solve, forward_dynamics_dense
from .ground_contact import ContactGeometry, GroundModel, default_contacts
from .inertia_matrix import bias_forces, crba
from .inverse_dynamics import external_wrenches, rnea
from .model import GRAVITY, build_model
from .strength import StrengthModel, default_strength, joint_angles, limit_torques


class SimulationError(HumanAnimError):
    """The simulation blew up: reported to the animator, with what to change."""


@dataclass
class Push:
    """A force of `magnitude` newtons along `direction` (world) at `point` (in the bone's frame)
    of bone `joint` (name or index), from `time` seconds after the start for `duration` seconds."""

    time: float
    joint: object
    point: tuple = (0.0, 0.0, 0.0)
    direction: tuple = (1.0, 0.0, 0.0)
    magnitude: float = 100.0
    duration: float = 0.1


@dataclass
class Settings:
    gravity: tuple = tuple(GRAVITY)
    ground: GroundModel = field(default_factory=GroundModel)
    loads: dict = field(default_factory=dict)  # bone -> kg carried (e.g. the hands)
    pushes: tuple = ()
    strength_scale: float = 1.0
    tracking: float = 1.0  # 0: ragdoll, 1: full controller torques
    controller: str = "inverse_dynamics"  # or "pd"
    root_support: float = 1.0
    max_step: float = 1e-3  # s, forward dynamics step (upper bound)
    control_step: float = None  # s, default: the largest whole fraction of a frame <= 1/120 s
    frequency: float = 20.0  # rad/s, natural frequency of the tracking feedback
    damping_ratio: float = 1.0
    joint_damping: float = 1.0  # 1/s: passive damping, as a rate on each DOF's own inertia H_ii
    limit_stiffness: float = 300.0  # N m/rad beyond the joint limits
    limit_damping: float = 10.0
    contacts: ContactGeometry = None  # default: default_contacts(model)
    strength: StrengthModel = None  # default: default_strength(model); scaled by strength_scale
    # "implicit": semi-implicit Euler with contact, joint and limit damping taken implicitly
    # (solves with H; stable at millisecond steps); "aba" or "dense": explicit forward dynamics,
    # which light segments in stiff contact require much smaller steps (max_step ~ 1e-4 s) for
    forward: str = "implicit"
    # kg m^2 of joint armature (rotor inertia) on every joint DOF, seen by the controller too:
    # keeps modes of tiny segments (helper bones, fingers, a short root bone) slow enough for the
    # millisecond step; 0 for exact rigid bodies
    armature: float = 1e-3
    # massless helper joints that the motion never turns (e.g. a BVH's LHipJoint) are welded:
    # a second free ball joint at the same point makes H nearly singular
    weld_static_helpers: bool = True


@dataclass
class Result:
    trajectories: Trajectories  # the simulated motion, at the input's frames
    torques: np.ndarray  # (F, n_dof) joint torques applied, N m, one column per actuated DOF
    usage: np.ndarray  # (F, n_dof) required torque / available torque (> 1: the clamp acted)
    available: np.ndarray  # (F, n_dof, 2) the strength model's (minimum, maximum) torque
    dof_names: tuple
    root_wrench: np.ndarray  # (F, 6) residual applied to the root (root axes: torque, force)
    contact_force: np.ndarray  # (F, 3) total ground reaction force, world
    zmp: np.ndarray  # (F, 2) zero moment point of the commanded motion
    mmp: np.ndarray  # (F, 2) minimum moment point (NaN in flight)
    model: object = None


def desired_motion(model, skeleton, trajectories):
    """Configurations (F, nq), velocities and accelerations (F, nv) of a motion, by central
    differences on the configuration manifold (one-sided at the ends)."""
    tr = trajectories
    pos, ori = tr.root_pose(skeleton)
    qs = np.array([model.configuration(pos[f], ori[f], tr.rotations[f]) for f in range(tr.frame_count)])
    dt = 1.0 / tr.fps if tr.frame_count < 2 else float(np.mean(np.diff(tr.times)))
    nf = len(qs)
    fwd = np.zeros((nf, model.nv))
    bwd = np.zeros((nf, model.nv))
    for f in range(nf):
        if f + 1 < nf:
            fwd[f] = kinematics.difference(model, qs[f], qs[f + 1])
        if f > 0:
            bwd[f] = kinematics.difference(model, qs[f], qs[f - 1])
    v = (fwd - bwd) / (2.0 * dt)
    a = (fwd + bwd) / dt ** 2
    if nf > 1:
        v[0], v[-1] = fwd[0] / dt, -bwd[-1] / dt
        a[0], a[-1] = (a[1], a[-2]) if nf > 2 else (0.0, 0.0)
    # the root's linear entries are velocities in its own turning axes: d/dt (R' p') = R' p'' - w x v
    a[:, 3:6] -= spatial.cross(v[:, :3], v[:, 3:6])
    return qs, v, a, dt


def simulate(skeleton, trajectories, settings=None):
    """Simulate a skeleton tracking `trajectories` under gravity, ground contact, loads and pushes."""
    return run_to_end(iter_simulate(skeleton, trajectories, settings))


def iter_simulate(skeleton, trajectories, settings=None):
    """simulate() as steps: yields the fraction of frames done, returns the Result."""
    st = settings or Settings()
    tr = trajectories
    if st.weld_static_helpers:
        skeleton = weld_static_helpers(skeleton, tr)
    model = build_model(skeleton, reference_basis=tr.basis()[0], loads=st.loads, gravity=st.gravity,
                        armature=st.armature)
    data = model.create_data()
    contacts = st.contacts if st.contacts is not None else default_contacts(model)
    strength = default_strength(model) if st.strength is None else st.strength
    strength = replace(strength, scale=strength.scale * st.strength_scale)
    forward = forward_dynamics_dense if st.forward == "dense" else aba
    qd, vd, ad, frame_dt = desired_motion(model, skeleton, tr)
    control_dt = st.control_step or frame_dt / np.ceil(frame_dt * 120.0 - 1e-9)
    substeps = max(1, int(np.ceil(control_dt / st.max_step - 1e-9)))
    dt = control_dt / substeps
    per_frame = max(1, int(round(frame_dt / control_dt)))
    pushes = _pushes(model, st.pushes)
    kp, kd = st.frequency ** 2, 2.0 * st.damping_ratio * st.frequency
    dof_j, dof_s = model.dof_joint[6:], model.dof_slot[6:]
    strength = strength.select(dof_j, dof_s)

    nf = tr.frame_count
    out_q = np.zeros((nf, model.nq))
    torques = np.zeros((nf, model.nv - 6))
    usage = np.zeros((nf, model.nv - 6))
    available = np.zeros((nf, model.nv - 6, 2))
    root_wrench = np.zeros((nf, 6))
    contact_force = np.zeros((nf, 3))
    zmps = np.full((nf, 2), np.nan)
    mmps = np.full((nf, 2), np.nan)
    q, v = qd[0].copy(), vd[0].copy()
    t = 0.0
    for f in range(nf):
        out_q[f] = q
        if f == nf - 1:
            w, x, force = st.ground.forces(model, data, q, v, contacts)
            contact_force[f] = force.sum(axis=0)
            break
        for k in range(per_frame):
            alpha = k / per_frame  # desired state between frames, linearly blended
            step = kinematics.difference(model, qd[f], qd[f + 1])
            target_q = kinematics.integrate(model, qd[f], step * alpha)
            target_v = (1 - alpha) * vd[f] + alpha * vd[f + 1]
            # torques are held over the step: aim at the mean desired acceleration over it, that
            # of its midpoint, or the motion lags half a control step behind
            mid = alpha + 0.5 / per_frame
            target_a = (1 - mid) * ad[f] + mid * ad[f + 1]
            w, x, force = st.ground.forces(model, data, q, v, contacts)
            err = kinematics.difference(model, q, target_q)
            hdiag = np.diag(crba(model, data, q))
            passive = st.joint_damping * hdiag  # scale-free: light segments are not overdamped
            passive[:6] = 0.0
            if st.controller == "pd":
                gains = st.tracking * hdiag
                gains[:6] *= st.root_support
                servo = _Servo(kp * gains, kd * gains, target_q, target_v, strength, dof_j, dof_s)
                control, _ = servo(model, q, v)
                command = target_a + kp * err + kd * (target_v - v)
                required = control / np.maximum(st.tracking, 1e-12)
            else:
                command = target_a + kp * err + kd * (target_v - v)
                required = rnea(model, data, q, v, command, f_ext=w) + passive * v  # the servo knows it
                angles = joint_angles(model, q)[dof_j, dof_s]
                applied, _ = strength.clamp(st.tracking * required[6:], angles, v[6:])
                control = np.concatenate((st.tracking * st.root_support * required[:6], applied))
                servo = _Constant(control)
            if k == 0:
                angles = joint_angles(model, q)[dof_j, dof_s]
                torques[f] = control[6:]
                usage[f] = strength.clamp(required[6:], angles, v[6:])[1]
                available[f] = np.stack(strength.limits(angles, v[6:]), axis=-1)
                root_wrench[f] = control[:6]
                contact_force[f] = force.sum(axis=0)
                zmps[f], mmps[f] = _balance(model, data, q, v, command, x, st.ground.height)
            for _ in range(substeps):
                push = _push_wrench(model, data, q, pushes, t) if pushes else None
                if st.forward == "implicit":
                    q, v = step_implicit(model, data, q, v, servo, dt, st, contacts, push, passive)
                else:
                    q, v = step_explicit(model, data, q, v, servo, dt, st, contacts, push, passive, forward)
                t += dt
            if not np.all(np.isfinite(q)):
                raise SimulationError(f"the simulation diverged at frame {tr.frames[f]:g}: "
                                      "try a smaller step, more damping or a lower tracking gain")
        yield (f + 1) / nf
    return Result(trajectories=_to_trajectories(model, skeleton, tr, out_q), torques=torques,
                  usage=usage, available=available, dof_names=model.dof_names[6:], root_wrench=root_wrench,
                  contact_force=contact_force, zmp=zmps, mmp=mmps, model=model)


def weld_static_helpers(skeleton, trajectories, tolerance=1e-3):
    """The skeleton with no free axis on massless joints whose rotation stays within
    `tolerance` radians of its first frame (they keep that rotation, welded)."""
    turn = rotations.angle_between(trajectories.rotations[:1], trajectories.rotations).max(axis=0)
    static = (turn < tolerance) & (skeleton.mass <= 0.0)
    static[skeleton.root] = False
    if not static.any():
        return skeleton
    dof = skeleton.dof.copy()
    dof[static] = False
    return replace(skeleton, dof=dof)


def step_explicit(model, data, q, v, servo, dt, st, contacts, push, passive, forward=aba):
    """One semi-implicit Euler step (velocity first) with explicit forward dynamics."""
    w, _, _ = st.ground.forces(model, data, q, v, contacts)
    if push is not None:
        w = w + push
    control, _ = servo(model, q, v)
    tau = control + limit_torques(model, q, v, st.limit_stiffness, st.limit_damping)
    tau -= passive * v
    v = v + dt * forward(model, data, q, v, tau, f_ext=w)
    return kinematics.integrate(model, q, v * dt), v


def step_implicit(model, data, q, v, servo, dt, st, contacts, push, passive):
    """One semi-implicit Euler step with linear damping taken at the new velocity:
    (H + dt K) (v+ - v) = dt (tau - bias(q, v) - K v), K = Jc' D Jc + joint damping."""
    w, jac, gain = st.ground.split_forces(model, data, q, v, contacts)
    if push is not None:
        w = w + push
    spring = limit_torques(model, q, np.zeros_like(v), st.limit_stiffness, 0.0)
    damp = passive + st.limit_damping * (spring != 0.0)
    control, servo_damping = servo(model, q, v)
    control = control + servo_damping * v  # the servo's damping, taken at the new velocity below
    damp += servo_damping
    h = crba(model, data, q)
    k = (jac.T * gain) @ jac
    k.flat[::model.nv + 1] += damp
    rhs = control + spring - bias_forces(model, data, q, v, f_ext=w) - k @ v
    v = v + dt * cholesky_solve(h + dt * k, rhs)
    return kinematics.integrate(model, q, v * dt), v


class _Constant:
    """Torques held over a control step (Huang's inverse dynamics controller)."""

    def __init__(self, tau):
        self.tau = tau

    def __call__(self, model, q, v):
        return self.tau, 0.0


class _Servo:
    """PD servo evaluated at every forward-dynamics step: tau = kp e + kd (v_target - v), gains
    scaled by the diagonal of H; clamped by the strength model (a clamped DOF loses its damping)."""

    def __init__(self, kp, kd, target_q, target_v, strength, dof_j, dof_s):
        self.kp, self.kd, self.target_q, self.target_v = kp, kd, target_q, target_v
        self.strength, self.dof_j, self.dof_s = strength, dof_j, dof_s

    def __call__(self, model, q, v):
        tau = self.kp * kinematics.difference(model, q, self.target_q) + self.kd * (self.target_v - v)
        angles = joint_angles(model, q)[self.dof_j, self.dof_s]
        clamped, _ = self.strength.clamp(tau[6:], angles, v[6:])
        free = np.ones(model.nv, bool)
        free[6:] = clamped == tau[6:]
        tau[6:] = clamped
        return tau, np.where(free, self.kd, 0.0)


def _balance(model, data, q, v, command, contact_points, ground_height):
    """ZMP of the commanded motion and its MMP on the current support polygon."""
    p = zmp(model, data, q, v, command, ground_height=ground_height)
    poly = support_polygon(contact_points, ground_height, tolerance=0.005)
    return p, (minimum_moment_point(poly, p) if len(poly) else np.full(2, np.nan))


def _pushes(model, pushes):
    sk = model.skeleton
    out = []
    for p in pushes:
        j = sk.index(p.joint) if isinstance(p.joint, str) else int(p.joint)
        d = np.asarray(p.direction, float)
        out.append((p.time, p.time + p.duration, j, np.asarray(p.point, float),
                    p.magnitude * d / np.linalg.norm(d)))
    return out


def _push_wrench(model, data, q, pushes, t):
    active = [p for p in pushes if p[0] <= t < p[1]]
    if not active:
        return 0.0
    return external_wrenches(model, data, q, [p[2] for p in active], [p[3] for p in active],
                             [p[4] for p in active])


def _to_trajectories(model, skeleton, trajectories, qs):
    """Trajectories of simulated configurations; bones without dynamics keep the input's pose."""
    tr = trajectories
    rot = tr.rotations.copy()
    moving = model.body_joint[1:]
    rot[:, moving] = qs[:, 7:].reshape(len(qs), -1, 4)[:, :]
    out = Trajectories(tr.frames, tr.fps, rot, tr.translations.copy(), tr.armature_to_world)
    return out.with_root_pose(skeleton, qs[:, :3], qs[:, 3:7])
