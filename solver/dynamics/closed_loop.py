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
from ..body_roles import REQUIRED_ROLES
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
    # joint armature (rotor inertia) on every joint DOF, seen by the controller too: kg m^2, and as
    # a share of each DOF's own inertia H_ii in the first frame (whichever is larger). The share
    # regularises DOF pairs that turn the same mass about nearly the same axis (a massless Neck
    # twisting with the Head: H is singular along their difference) at a cost of 2 % of the
    # inertia, on any scale of rig; 0 and 0 for exact rigid bodies
    armature: float = 0.0
    armature_ratio: float = 0.02
    # bones whose subtree weighs less than this share of the body (fingers: de Leva's fingers
    # together are 0.18 % of the body, 30 % of the 0.61 % hand; a toe is 0.27 %) carry no dynamics:
    # lumped into their parent in the first frame's pose, they follow the source exactly. Grams on
    # millimetre levers have modes far above any affordable step and change nothing visible
    kinematic_fraction: float = 0.0015
    # massless helper joints that the motion never turns (e.g. a BVH's LHipJoint) are welded:
    # a second free ball joint at the same point makes H nearly singular
    weld_static_helpers: bool = True
    # leaf bones whose tail the file does not define (an End Site at zero offset: Blender's
    # importer copies the parent's vector or leaves a millimetre) have no segment of their own:
    # their mass is lumped at their head into their parent (see lump_made_up_tails)
    lump_made_up_tails: bool = True


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
    qs = model.configurations(pos, ori, tr.rotations)
    dt = 1.0 / tr.fps if tr.frame_count < 2 else float(np.mean(np.diff(tr.times)))
    nf = len(qs)
    fwd = np.zeros((nf, model.nv))
    bwd = np.zeros((nf, model.nv))
    if nf > 1:  # every frame at once
        fwd[:-1] = kinematics.difference(model, qs[:-1], qs[1:])
        bwd[1:] = kinematics.difference(model, qs[1:], qs[:-1])
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
    skeleton = simulated_skeleton(skeleton, trajectories, st)
    run = _Run.prepare(skeleton, trajectories, st)
    rec = _Recording(trajectories.frame_count, run.model)
    q, v = run.qd[0].copy(), run.vd[0].copy()
    t = 0.0
    for f in range(rec.frames):
        rec.q[f] = q
        if f == rec.frames - 1:
            rec.contact_force[f] = st.ground.forces(run.model, run.data, q, v, run.contacts)[2].sum(axis=0)
            break
        for k in range(run.per_frame):
            target = run.target(f, k)
            servo, passive, record = run.servo(q, v, *target)
            if k == 0:
                rec.store(f, run, q, v, *record)
            q, v, t = run.advance(q, v, servo, passive, t, f)
        yield (f + 1) / rec.frames
    return rec.result(run, skeleton, trajectories)


class _Run:
    """What a simulation keeps from start to end: the model, the desired motion, the timing, the
    gains and the strength model."""

    @classmethod
    def prepare(cls, skeleton, tr, st):
        run = cls()
        run.st, run.tr = st, tr
        run.model = model = build_model(
            skeleton, reference_basis=tr.basis()[0], loads=st.loads, gravity=st.gravity, armature=st.armature,
            kinematic_mass=st.kinematic_fraction * (skeleton.total_mass + sum(st.loads.values())))
        run.data = model.create_data()
        run.qd, run.vd, run.ad, frame_dt = desired_motion(model, skeleton, tr)
        run.steps = kinematics.difference(model, run.qd[:-1], run.qd[1:])  # each frame's way to the next
        if st.armature_ratio > 0.0:
            model.set_armature(np.maximum(st.armature, st.armature_ratio * np.diag(crba(model, run.data, run.qd[0]))))
        run.contacts = st.contacts if st.contacts is not None else default_contacts(model)
        strength = default_strength(model) if st.strength is None else st.strength
        strength = replace(strength, scale=strength.scale * st.strength_scale)
        run.forward = forward_dynamics_dense if st.forward == "dense" else aba
        run.control_dt = st.control_step or frame_dt / np.ceil(frame_dt * 120.0 - 1e-9)
        run.substeps = max(1, int(np.ceil(run.control_dt / st.max_step - 1e-9)))
        run.dt = run.control_dt / run.substeps
        run.per_frame = max(1, int(round(frame_dt / run.control_dt)))
        run.pushes = _pushes(model, st.pushes)
        run.kp, run.kd = st.frequency ** 2, 2.0 * st.damping_ratio * st.frequency
        run.dof_j, run.dof_s = model.dof_joint[6:], model.dof_slot[6:]
        run.strength = strength.select(run.dof_j, run.dof_s)
        return run

    def target(self, f, k):
        """Desired position, velocity and acceleration at control step k of frame f."""
        qd, vd, ad = self.qd, self.vd, self.ad
        alpha = k / self.per_frame  # desired state between frames, linearly blended
        target_q = kinematics.integrate(self.model, qd[f], self.steps[f] * alpha)
        target_v = (1 - alpha) * vd[f] + alpha * vd[f + 1]
        # torques are held over the step: aim at the mean desired acceleration over it, that of
        # its midpoint, or the motion lags half a control step behind
        mid = alpha + 0.5 / self.per_frame
        return target_q, target_v, (1 - mid) * ad[f] + mid * ad[f + 1]

    def servo(self, q, v, target_q, target_v, target_a):
        """The controller held over one control step, the passive damping, and what the frame
        records: (control, required, command, contact points, contact forces)."""
        model, data, st = self.model, self.data, self.st
        w, x, force = st.ground.forces(model, data, q, v, self.contacts)
        err = kinematics.difference(model, q, target_q)
        h_now = crba(model, data, q)
        hdiag = np.diag(h_now)
        passive = st.joint_damping * hdiag  # scale-free: light segments are not overdamped
        passive[:6] = 0.0
        command = target_a + self.kp * err + self.kd * (target_v - v)
        if st.controller == "pd":
            gains = st.tracking * hdiag
            gains[:6] *= st.root_support
            servo = _Servo(self.kp * gains, self.kd * gains, target_q, target_v, self.strength, self.dof_j,
                           self.dof_s)
            control, _, _ = servo(model, q, v, None)
            required = control / np.maximum(st.tracking, 1e-12)
        else:
            # the contact forces are known to the controller (Huang) but change within a control
            # step far faster than it (a toe on the penalty ground: ~1e3 rad/s), so their
            # compensation is not held: the servo cancels its share of the current contact force
            # at every step (implicitly, see step_implicit)
            free = rnea(model, data, q, v, command) + passive * v  # the servo knows it
            contact = _generalized_forces(model, data, q, w)
            required = free - contact
            angles = joint_angles(model, q)[self.dof_j, self.dof_s]
            low, high = self.strength.limits(angles, v[6:])
            share = np.full(model.nv, st.tracking)
            share[:6] *= st.root_support
            control, clamped = _clamp_consistently(share * required, share, low, high, lambda: h_now)
            share[6:][clamped] = 0.0  # a clamped DOF feels the changes of the contact forces
            servo = _InverseDynamics(control + share * contact, share, low, high)
        return servo, passive, (control, required, command, x, force)

    def advance(self, q, v, servo, passive, t, f):
        """One control step of forward dynamics in `substeps` small steps, to (q, v, t); a
        blow-up is an error that names the frame."""
        model, data, st = self.model, self.data, self.st
        try:
            with np.errstate(over="raise", invalid="raise"):
                for _ in range(self.substeps):
                    push = _push_wrench(model, data, q, self.pushes, t) if self.pushes else None
                    if st.forward == "implicit":
                        q, v = step_implicit(model, data, q, v, servo, self.dt, st, self.contacts, push, passive)
                    else:
                        q, v = step_explicit(model, data, q, v, servo, self.dt, st, self.contacts, push, passive,
                                             self.forward)
                    t += self.dt
        except (np.linalg.LinAlgError, FloatingPointError) as exc:
            raise SimulationError(_diverged(model, self.tr, f, v, str(exc))) from None
        if not (np.all(np.isfinite(q)) and np.all(np.isfinite(v))) or np.abs(v).max() > MAX_SPEED:
            raise SimulationError(_diverged(model, self.tr, f, v))
        return q, v, t


class _Recording:
    """Per-frame outputs, filled at the first control step of each frame."""

    def __init__(self, frames, model):
        n = model.nv - 6
        self.frames = frames
        self.q = np.zeros((frames, model.nq))
        self.torques, self.usage = np.zeros((frames, n)), np.zeros((frames, n))
        self.available = np.zeros((frames, n, 2))
        self.root_wrench, self.contact_force = np.zeros((frames, 6)), np.zeros((frames, 3))
        self.zmps, self.mmps = np.full((frames, 2), np.nan), np.full((frames, 2), np.nan)

    def store(self, f, run, q, v, control, required, command, x, force):
        angles = joint_angles(run.model, q)[run.dof_j, run.dof_s]
        self.torques[f] = control[6:]
        self.usage[f] = run.strength.clamp(required[6:], angles, v[6:])[1]
        self.available[f] = np.stack(run.strength.limits(angles, v[6:]), axis=-1)
        self.root_wrench[f] = control[:6]
        self.contact_force[f] = force.sum(axis=0)
        self.zmps[f], self.mmps[f] = _balance(run.model, run.data, q, v, command, x, run.st.ground.height)

    def result(self, run, skeleton, tr):
        return Result(trajectories=_to_trajectories(run.model, skeleton, tr, self.q), torques=self.torques,
                      usage=self.usage, available=self.available, dof_names=run.model.dof_names[6:],
                      root_wrench=self.root_wrench, contact_force=self.contact_force, zmp=self.zmps,
                      mmp=self.mmps, model=run.model)


MAX_SPEED = 1e3  # rad/s or m/s: beyond this the simulation has blown up


def _diverged(model, tr, f, v, detail=""):
    """What to tell the animator when the simulation blew up at frame index f."""
    speed = np.where(np.isfinite(v), np.abs(v), np.inf)
    worst = model.dof_names[int(np.argmax(speed))]
    return (f"the simulation diverged at frame {tr.frames[f]:g} (fastest: {worst}"
            + (f"; {detail}" if detail else "") + "): try a smaller step (max_step), more joint "
            "damping, a lower tracking gain or check the source motion there for jumps")


def _require_connected_body(skeleton):
    """Every limb must hang below the pelvis in the bone hierarchy, or the simulation would
    silently leave it out (a generated Rigify rig parents its deform legs to control bones)."""
    pelvis = skeleton.root
    below = set(skeleton.descendants(pelvis)) | {pelvis}
    loose = [f"{role} ({bone})" for role in REQUIRED_ROLES + ("upper_arm.L", "upper_arm.R", "head")
             for bone in skeleton.roles.chain(role) if skeleton.index(bone) not in below]
    if loose:
        raise SimulationError(
            f"these body parts are not children of the pelvis '{skeleton.names[pelvis]}' in the bone "
            f"hierarchy, so they can't be simulated: {', '.join(loose)}. A rig whose deform bones follow "
            "control bones through constraints (e.g. a generated Rigify rig) isn't supported yet: "
            "simulate its metarig or a plain FK copy")


def motion_floor(skeleton, trajectories, contacts=None):
    """Height of the lowest point any contact sphere reaches in the motion: where its floor is.
    Capture floors are rarely at exactly zero; a ground above the feet makes them chatter."""
    model = build_model(skeleton, reference_basis=trajectories.basis()[0])
    contacts = contacts if contacts is not None else default_contacts(model)
    qs = desired_motion(model, skeleton, trajectories)[0]
    heights = kinematics.batch_point_positions(model, qs, contacts.joints, contacts.points)[..., 2]
    return float((heights - contacts.radii).min())


def simulated_skeleton(skeleton, trajectories, settings):
    """The skeleton a simulation or a dynamic control runs on (both build theirs here): static
    massless helpers welded and made-up tails lumped into their parent, as `settings` (closed_loop's
    Settings or motion_control's ControlSettings) ask; refused if its bodies don't connect. A
    made-up tail that carries a load keeps its segment: the load needs the hand's reach (the
    anthropometric model puts its centre in the palm whatever the bone's length)."""
    if settings.weld_static_helpers:
        skeleton = weld_static_helpers(skeleton, trajectories)
    if settings.lump_made_up_tails:
        loaded = [getattr(load, "bone", load) for load in settings.loads]  # Settings: {bone: kg}; ControlSettings: Loads
        skeleton = lump_made_up_tails(skeleton, keep=loaded)
    _require_connected_body(skeleton)
    return skeleton


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


def made_up_tails(skeleton, short=2e-3, tolerance=0.01):
    """Leaf bones (no children) whose tail is an importer's guess, not the file's: shorter than
    `short` metres (an End Site at zero offset kept a millimetre long), or the exact copy of the
    parent bone's vector, direction and length within `tolerance` of it (Blender's BVH importer
    gives a zero-length bone its parent's vector). (J,) bool."""
    sk = skeleton
    y = np.array([0.0, 1.0, 0.0])
    vec = sk.rest[:, :3, :3] @ y * np.asarray(sk.lengths, float)[:, None]
    out = np.zeros(sk.joint_count, bool)
    has_child = np.zeros(sk.joint_count, bool)
    has_child[sk.parents[sk.parents >= 0]] = True
    for j in np.flatnonzero(~has_child & (sk.parents >= 0)):
        p = sk.parents[j]
        copy = sk.lengths[p] > short and np.linalg.norm(vec[j] - vec[p]) <= tolerance * sk.lengths[p]
        out[j] = sk.lengths[j] < short or copy
    return out


def lump_made_up_tails(skeleton, keep=()):
    """The skeleton with every made-up-tail leaf (made_up_tails) lumped into its parent: its
    mass a point at its head added to the parent's segment (mass, centre of mass and inertia by
    the parallel axis theorem), its own mass and length zero. It then follows the source motion
    (a kinematic bone of build_model) and has no contact points of its own (the parent's carry
    the body), so that no segment, lever or sole point rests on a tail the file never gave.
    Bones in `keep` (names or indices) stay as they are."""
    lumped = made_up_tails(skeleton)
    lumped &= skeleton.mass > 0.0
    lumped[[skeleton.index(b) if isinstance(b, str) else int(b) for b in keep]] = False
    if not lumped.any():
        return skeleton
    sk = skeleton
    mass, com, inertia = sk.mass.copy(), sk.com.copy(), sk.inertia.copy()
    lengths = np.asarray(sk.lengths, float).copy()
    for j in np.flatnonzero(lumped):
        p = sk.parents[j]
        head = (np.linalg.inv(sk.rest[p]) @ sk.rest[j])[:3, 3]  # the leaf's head in the parent frame
        m_p, m_j = mass[p], mass[j]
        c = (m_p * com[p] + m_j * head) / (m_p + m_j)
        d_p, d_j = com[p] - c, head - c
        inertia[p] = (inertia[p] + m_p * (d_p @ d_p * np.eye(3) - np.outer(d_p, d_p))
                      + m_j * (d_j @ d_j * np.eye(3) - np.outer(d_j, d_j)))
        mass[p], com[p] = m_p + m_j, c
        mass[j], com[j], inertia[j], lengths[j] = 0.0, 0.0, 0.0, 0.0
    return replace(sk, mass=mass, com=com, inertia=inertia, lengths=lengths)


def step_explicit(model, data, q, v, servo, dt, st, contacts, push, passive, forward=aba):
    """One semi-implicit Euler step (velocity first) with explicit forward dynamics."""
    w, _, _ = st.ground.forces(model, data, q, v, contacts)
    contact = _generalized_forces(model, data, q, w)
    control, _, share = servo(model, q, v, contact)
    tau = control + (1.0 - np.asarray(share, float)) * contact + limit_torques(model, q, v, st.limit_stiffness, st.limit_damping)
    tau -= passive * v
    v = v + dt * forward(model, data, q, v, tau, f_ext=push if np.ndim(push) else None)
    return kinematics.integrate(model, q, v * dt), v


def step_implicit(model, data, q, v, servo, dt, st, contacts, push, passive):
    """One semi-implicit Euler step with the linear stiffness and damping taken at the new state:

        (H + dt D + dt^2 K) (v+ - v) = dt (tau - bias(q, v) - D v - dt K v)

    D: contact damping (J' c J over the touching points and sticking friction), joint, limit and
    servo damping; K: contact normal stiffness (J' k J) and joint-limit stiffness. Light segments
    (toes, fingers: 1e-5 kg m^2) in a penalty contact of 4e4 N/m have modes far above 1/dt; taken
    implicitly they are damped instead of exploding. The servo cancels a share s (per DOF) of the
    contact forces (the inverse-dynamics controller's compensation); the body feels the rest,
    (1 - s) J' f, the damping and stiffness of that part still implicit."""
    w, rows, damping, stiffness = st.ground.linearised_forces(model, data, q, v, contacts)
    elastic = _generalized_forces(model, data, q, w)
    rate = rows @ v
    contact = elastic - rows.T @ (damping * rate)
    control, servo_damping, share = servo(model, q, v, contact)
    keep = 1.0 - np.asarray(share, float)
    spring = limit_torques(model, q, np.zeros_like(v), st.limit_stiffness, 0.0)
    at_limit = spring != 0.0
    damp = passive + st.limit_damping * at_limit + servo_damping + dt * st.limit_stiffness * at_limit
    control = control + servo_damping * v  # the servo's damping, taken at the new velocity below
    h = crba(model, data, q)
    gains = damping + dt * stiffness
    k = (rows.T * gains) @ rows
    uniform = keep.ndim == 0 or np.all(keep == keep.flat[0])
    k *= keep.flat[0] if uniform else keep[:, None]
    k.flat[::model.nv + 1] += damp
    rhs = control + spring + keep * elastic - bias_forces(model, data, q, v, f_ext=push if np.ndim(push) else None) - k @ v
    a = h + dt * k
    v = v + dt * (cholesky_solve(a, rhs) if uniform else np.linalg.solve(a, rhs))
    return kinematics.integrate(model, q, v * dt), v


def _generalized_forces(model, data, q, wrenches):
    """J' f (nv,): the generalised forces of world wrenches (nb, 6) on the bodies (each DOF feels
    the wrenches on its body's subtree)."""
    if np.ndim(wrenches) == 0:
        return np.zeros(model.nv)
    cols = kinematics.motion_subspace(model, data, q)
    subtree = model.ancestors.T @ wrenches
    return np.einsum("ij,ij->i", cols, subtree[model.dof_body])


class _Constant:
    """Torques held over a control step."""

    def __init__(self, tau):
        self.tau = tau

    def __call__(self, model, q, v, contact=None):
        return self.tau, 0.0, 0.0


class _InverseDynamics:
    """Huang's inverse-dynamics torques: `held` (nv,) is held over the control step, and the
    servo also cancels the share `share` (nv,) of the current contact forces, so that the applied
    torques are held - share * J'f(t) (see step_implicit), as far as the strength model's range
    (low, high) on the joints allows: a joint DOF that would leave it applies its bound and
    feels the contact forces (a toe that the source pushes into the floor gives way)."""

    def __init__(self, held, share, low, high):
        self.held, self.share, self.low, self.high = held, share, low, high

    def __call__(self, model, q, v, contact):
        wanted = self.held[6:] - self.share[6:] * contact[6:]
        over = (wanted < self.low) | (wanted > self.high)
        if not over.any():
            return self.held, 0.0, self.share
        tau, share = self.held.copy(), self.share.copy()
        tau[6:] = np.where(over, np.clip(wanted, self.low, self.high), tau[6:])
        share[6:][over] = 0.0
        return tau, 0.0, share


def _clamp_consistently(tau, share, low, high, inertia, iterations=4):
    """Joint torques tau[6:] clamped to [low, high] so that the motion stays consistent (Oshita
    2003, sec. 2.5.1, eq. 2.10): a DOF c whose torque exceeds its strength gets the acceleration
    its bound allows, a_c + da_c, and every other DOF the torque change H[:, c] da_c that keeps its
    own acceleration as commanded. Clamping one DOF alone instead would throw the whole deficit
    into the motion of its neighbours: two DOFs that turn the same mass about nearly the same axis
    (a massless neck's twist and the head's) make H nearly singular along their difference, and a
    torque mismatch there spins them apart. The redistributed torques are scaled by `share` (the
    root gets its root_support share); returns the torques and the clamped joint DOFs (nv-6,)."""
    out = tau.copy()
    clamped = np.zeros(len(low), bool)
    h = None
    for _ in range(iterations):
        over = ((out[6:] < low - 1e-9) | (out[6:] > high + 1e-9)) & ~clamped
        if not over.any():
            break
        clamped |= over
        if h is None:
            h = inertia()
        c = np.flatnonzero(clamped) + 6
        target = np.clip(out[c], low[c - 6], high[c - 6])
        try:
            da = np.linalg.solve(h[np.ix_(c, c)], target - out[c])
        except np.linalg.LinAlgError:
            da = (target - out[c]) / np.diag(h)[c]
        out += share * (h[:, c] @ da)
        out[c] = target
    over = (out[6:] < low) | (out[6:] > high)
    if over.any():  # what the redistribution pushed over in the last round: plain clamp
        out[6:] = np.clip(out[6:], low, high)
        clamped |= over
    return out, clamped


class _Servo:
    """PD servo evaluated at every forward-dynamics step: tau = kp e + kd (v_target - v), gains
    scaled by the diagonal of H; clamped by the strength model (a clamped DOF loses its damping)."""

    def __init__(self, kp, kd, target_q, target_v, strength, dof_j, dof_s):
        self.kp, self.kd, self.target_q, self.target_v = kp, kd, target_q, target_v
        self.strength, self.dof_j, self.dof_s = strength, dof_j, dof_s

    def __call__(self, model, q, v, contact=None):
        tau = self.kp * kinematics.difference(model, q, self.target_q) + self.kd * (self.target_v - v)
        angles = joint_angles(model, q)[self.dof_j, self.dof_s]
        clamped, _ = self.strength.clamp(tau[6:], angles, v[6:])
        free = np.ones(model.nv, bool)
        free[6:] = clamped == tau[6:]
        tau[6:] = clamped
        return tau, np.where(free, self.kd, 0.0), 0.0


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
