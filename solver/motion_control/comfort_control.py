"""Comfort control (Oshita 2003, sec. 2.5.1 and 2.5.3): the joint torques a commanded acceleration
needs (eq. 2.8), the stress of every joint against its muscle strength (eq. 2.9), and the change
of acceleration that relieves it through the moment of inertia (eq. 2.10):

  1. passive control of the upper body (eq. 2.17-2.18): a stressed joint gives way, its
     acceleration follows from its torque limit;
  2. active control of the arms (two swing axes of each upper arm, 4 DOF), then of the back (the
     lowest spine bone, 3 DOF), through submatrices H' of H and pseudo-inverses (eq. 2.19-2.21);
     the passive change is then recomputed;
  3. the legs, through the spatial acceleration of the pelvis p'' mapped to every joint of the
     legs that stand on the ground by J_p (eq. 2.16, 2.22), feet held in place.

Coordinates are the dynamics model's (q, v, a); Z up. The base's acceleration (the pelvis) is held
while the upper body is controlled, as in the thesis where H relates joint torques to joint
accelerations of a figure whose pelvis is prescribed. The ground reaction is shared between the
feet in contact at the zero moment point ("an approximation [19][21] is used to determine the
forces applied from the upper body to each leg"), so that leg torques carry the body's weight.
bpy-free: numpy only.
"""

from dataclasses import dataclass, field

import numpy as np

from ..dynamics import spatial
from ..dynamics.ground_contact import default_contacts
from ..dynamics.inertia_matrix import inertia_block
from ..dynamics.inverse_dynamics import subtree_wrenches
from ..dynamics.kinematics import motion_subspace, point_positions, segment_jacobian, update_frames
from ..dynamics.strength import StrengthModel, torque_range

SIDES = ("L", "R")


@dataclass
class Settings:
    passive_rounds: int = 6  # rounds after eq. 2.17-2.18: passive joints held at their limits
    rcond: float = 1e-6  # pseudo-inverses (eq. 2.21)
    leg_rcond: float = 0.05  # legs' inverse kinematics in J_p: a straight knee is singular
    pelvis_step: float = 0.1  # m/s^2: finite difference of leg torques in p''
    max_pelvis_acceleration: float = 4.9  # m/s^2: beyond this the legs cannot recover balance
    max_part_acceleration: float = 20.0  # rad/s^2: most the arms or back turn for balance
    zmp_tolerance: float = 1e-4  # m: a ZMP this close to the support polygon is balanced
    torque_tolerance: float = 1e-6  # N m: stress below this is none
    # the strength's smooth saturation (saturated_stress): a joint's torque saturates over a knee
    # of +-saturation_band times its strength around the strength, so the stress (and with it
    # comfort and passive control) grows smoothly with the load instead of starting at a kink;
    # 0 (default): eq. 2.9's hard clip. 0.05 leaves the thesis's 15 kg box squat's back bent after
    # the squat (docs/physics.md, "Predictable results")
    saturation_band: float = 0.0
    # hysteresis of a part's mode (largest_with_kind): the other kind's candidate takes over only
    # when its demand is this share larger than the acting kind's (a tie does not flip per step)
    mode_margin: float = 0.1


# ---- the body's parts -------------------------------------------------------------------------

@dataclass
class BodyParts:
    """DOF indices of the controlled parts of a model (Oshita fig. 2.6)."""

    arms: np.ndarray  # two swing axes (local x, z) of each upper arm
    back: np.ndarray  # the three axes of the lowest spine bone
    upper: np.ndarray  # every joint DOF outside the legs (passive control)
    lower: np.ndarray  # every joint DOF of the legs
    legs: tuple  # per side: joint DOFs from the pelvis down to the foot (J_p's rows)
    feet: tuple  # foot bone per side
    sole_joints: tuple  # per side: bones of the sole points (foot and toes)
    sole_points: tuple  # per side: sole points in those bones' frames


def body_parts(model, contacts=None):
    """The parts of a model's body from its skeleton's roles."""
    sk = model.skeleton
    joint_dofs = np.arange(6, model.nv)
    arms = [d for s in SIDES for d in _bone_dofs(model, sk.role_index(f"upper_arm.{s}"), (0, 2))]
    spine = [sk.index(n) for n in sk.roles.chain("spine")]
    back = next((_bone_dofs(model, j) for j in spine if len(_bone_dofs(model, j))), [])
    lower, legs, feet = [], [], []
    for s in SIDES:
        foot = sk.role_index(f"foot.{s}")
        fb = model.joint_body[foot]
        top = _top_below_base(model, model.joint_body[sk.role_index(f"thigh.{s}")])
        lower += [d for d in joint_dofs if model.ancestors[model.dof_body[d], top] > 0]
        legs.append(np.array([d for d in joint_dofs if model.ancestors[fb, model.dof_body[d]] > 0]))
        feet.append(foot)
    lower = np.array(sorted(set(lower)), int)
    upper = np.setdiff1d(joint_dofs, lower)
    sj, sp = _soles(model, feet, contacts or default_contacts(model))
    return BodyParts(np.array(arms, int), np.array(back, int), upper, lower, tuple(legs),
                     tuple(feet), sj, sp)


def _bone_dofs(model, joint, slots=(0, 1, 2)):
    if joint is None or model.joint_kind[joint] not in ("joint",):
        return []
    b = model.joint_body[joint]
    return [int(model.v_index[b, s]) for s in slots if model.v_index[b, s] < model.nv]


def _top_below_base(model, body):
    while model.parent[body] > 0:
        body = model.parent[body]
    return body


def _soles(model, feet, contacts):
    """Sole points of each foot: the contact points on the foot bone and the bones below it."""
    sk = model.skeleton
    joints, points = [], []
    for foot in feet:
        below = {foot, *sk.descendants(foot)}
        keep = np.array([j in below and r == 0.0 for j, r in zip(contacts.joints, contacts.radii)])
        joints.append(contacts.joints[keep])
        points.append(contacts.points[keep])
    return tuple(joints), tuple(points)


# ---- the state of one control step ------------------------------------------------------------

@dataclass(frozen=True)
class StateConstants:
    """What every control state of one body (model, body parts, strength) shares: made once per
    body (state_constants) and handed to its states, so nothing is remembered on the model."""

    dof_strength: object  # strength.select of the actuated DOFs (a StrengthModel's rows)
    fused: tuple  # _dof_limits' constants of a StrengthModel, None for another strength model
    weight: float  # N, the body's weight (balance_control's MIN_SUPPORT)
    selections: dict  # part name -> (nv, k) selection matrix S of eq. 2.16 (read-only)
    # contact set (left, right) -> the last support polygon's points, hull vertices and monotone
    # chain path (balance_control._support_polygon: the hull is rebuilt only when the feet move)
    hulls: dict = field(default_factory=dict)


def state_constants(model, parts, strength):
    """The StateConstants of a body."""
    sel = strength.select(model.dof_joint[6:], model.dof_slot[6:])
    fused = None
    if type(strength) is StrengthModel:
        body = model.dof_body[6:]
        fused = (3 + 4 * body[:, None] + np.arange(4)[None, :],  # each DOF's body quaternion in q
                 4 * np.arange(model.nv - 6) + 1 + np.asarray(model.dof_slot[6:]),  # its component, flat
                 sel.scale * sel.peak, sel.max_velocity)
    selections = {}
    for part in ("arms", "back"):
        cols = getattr(parts, part)
        s = np.zeros((model.nv, len(cols)))
        s[cols, np.arange(len(cols))] = 1.0
        s.flags.writeable = False
        selections[part] = s
    weight = float(model.mass.sum() * np.linalg.norm(model.gravity))
    return StateConstants(sel, fused, weight, selections)


@dataclass(eq=False)
class ControlState:
    """Everything a control step needs about the figure at (q, v). What is derived from it is
    computed on first use and kept in the fields below the inputs (one state per step)."""

    model: object
    data: object
    q: np.ndarray
    v: np.ndarray
    feet: np.ndarray  # (2,) bool: left, right foot on the ground
    parts: BodyParts
    strength: object  # StrengthModel of the skeleton's bones (J, 3)
    f_ext: np.ndarray = None  # (nb, 6) world wrenches (pushes, hands on things)
    ground_height: float = 0.0
    settings: Settings = field(default_factory=Settings)
    allowance: np.ndarray = None  # (nv,) N m each DOF may exceed its strength (the input's own excess)
    constants: StateConstants = None  # the body's (state_constants; made here when not given)
    # ---- derived, on first use ----
    soles: list = None  # per side (k, 3) world sole points (a caller that knows them passes them)
    contact_sides: np.ndarray = None  # indices of the feet in contact
    foot_bodies: np.ndarray = None  # their feet's bodies
    sole_centres: list = None  # per side in contact: mean sole point [x, y, ground]
    polygon: np.ndarray = None  # the support polygon (balance_control.support_polygon)
    torque_memo: dict = field(default_factory=dict)  # acceleration bytes -> required_torques
    balance_memo: dict = field(default_factory=dict)  # (wrench bytes, id(polygon)) -> balance_error
    _limits: tuple = None
    _knees: tuple = None
    _pelvis_jacobian: np.ndarray = None
    momentum_rate: np.ndarray = None  # (6, nv) balance_control._momentum_rate
    subtree_mass_com: tuple = None  # balance_control._subtree_mc

    def __post_init__(self):
        self.q = np.asarray(self.q, float)
        self.v = np.asarray(self.v, float)
        self.feet = np.asarray(self.feet, bool)
        if self.constants is None:
            self.constants = state_constants(self.model, self.parts, self.strength)

    def sides(self):
        """Indices (array) of the feet in contact (np.flatnonzero(feet), once per state)."""
        if self.contact_sides is None:
            self.contact_sides = np.flatnonzero(self.feet)
        return self.contact_sides

    @property
    def limits(self):
        """(tau_min, tau_max) (nv,) of every DOF (eq. 2.2); the base is unbounded."""
        if self._limits is None:
            self._limits = self._make_limits()
        return self._limits

    @property
    def knees(self):
        """(low, high) (nv,) where each DOF's smooth saturation starts: its limits pulled in by
        Settings.saturation_band of themselves (saturated_stress)."""
        if self._knees is None:
            keep = 1.0 - self.settings.saturation_band
            low, high = self.limits
            self._knees = (low * keep, high * keep)
        return self._knees

    def _make_limits(self):
        m = self.model
        fused = self.constants.fused
        if fused is not None:
            low, high = _dof_limits(fused, self.q, self.v)
        else:
            # joint_angles(m, q)[dof_joint, dof_slot]: the rotation vector of each DOF's own body
            angles = spatial.quat_log(self.q[7:].reshape(-1, 4))[m.dof_body[6:] - 1, m.dof_slot[6:]]
            low, high = self.constants.dof_strength.limits(angles, self.v[6:])
            low, high = np.concatenate((_BASE_LOW, low)), np.concatenate((_BASE_HIGH, high))
        if self.allowance is not None:
            low, high = low - self.allowance, high + self.allowance
        return low, high

    def sole_world(self):
        """World sole points of each foot (list of (k, 3))."""
        if self.soles is None:
            self.soles = [point_positions(self.model, self.data, self.q, j, p)
                          for j, p in zip(self.parts.sole_joints, self.parts.sole_points)]
        return self.soles

    def inertia(self, rows, cols):
        """H[rows][:, cols] (eq. 2.10), from the composite inertias."""
        return inertia_block(self.model, self.data, self.q, rows, cols)

    def pelvis_jacobian(self):
        """J_p (nv, 3): the joint accelerations a unit world acceleration of the pelvis gives."""
        if self._pelvis_jacobian is None:
            self._pelvis_jacobian = pelvis_jacobian(self)
        return self._pelvis_jacobian


_BASE_LOW, _BASE_HIGH = np.full(6, -np.inf), np.full(6, np.inf)  # the base is unbounded


def _dof_limits(fused, q, v):
    """(tau_min, tau_max) (nv,) with the unbounded base: StrengthModel.limits of the selected DOFs
    at the rotation-vector component of each DOF's body (spatial.quat_log's, its sign left out:
    the limits' cos is even) in a few array operations. quat_log's components lie within
    [-pi, pi], so limits' clamp to it is omitted."""
    index, component, top0, vmax = fused
    quat = q.take(index)  # (n, 4)
    comp = quat.take(component)  # quat[k, 1 + slot], by its flat index
    xyz = quat[:, 1:]
    s = np.sqrt((xyz * xyz).sum(axis=1))
    angle = spatial.log_scale(s, np.abs(quat[:, 0])) * comp  # (+-: the strength curve is even)
    low, high = torque_range(top0 * np.maximum(0.3, np.cos(0.6 * angle)), v[6:] / vmax)
    return np.concatenate((_BASE_LOW, low)), np.concatenate((_BASE_HIGH, high))


# ---- eq. 2.8-2.9: required torques and stress --------------------------------------------------

def required_torques(state, a):
    """Joint torques (nv,) for the acceleration a (eq. 2.8), and the ground wrench the motion
    needs (6,) (world, about the origin: torque, force). The ground wrench is shared between the
    feet in contact, so tau[:6] is ~0 when a foot is down.

    Remembered per state and acceleration (the control sequence asks for the same one several
    times); the arrays are read-only."""
    a = np.asarray(a, float)
    memo = state.torque_memo
    key = a.tobytes()
    out = memo.get(key)
    if out is None:
        out = memo[key] = _required_torques(state, a)
    return out


def _required_torques(state, a):
    m, d = state.model, state.data
    total = subtree_wrenches(m, d, state.q, state.v, a, f_ext=state.f_ext)  # rnea's inward pass
    below = total[m.dof_body]
    ground = _ground_wrenches(state, total[0])
    if ground is not None:
        # -J' f of the foot wrenches: each DOF against the wrenches on its body's subtree
        bodies, wrenches = ground
        below = below - m.dof_subtree[bodies].T.dot(wrenches)
    # rnea's tau: each DOF's motion subspace against the wrench its body's subtree needs
    tau = (motion_subspace(m, d, state.q) * below).sum(axis=1) + m.armature_v * a
    wrench = total[0]
    tau.flags.writeable = False
    wrench.flags.writeable = False
    return tau, wrench


def _ground_wrenches(state, wrench):
    """World wrenches on the feet in contact that sum to `wrench`: the force at the ZMP, split between
    the feet by where the ZMP lies between their sole centres; as the foot bodies (k,) and their
    wrenches (k, 6), on plain floats. (Plain formula: ZMP p, points c + (p - w c), moment about the
    ZMP m = n - np.cross(p, f), rows (np.cross(x, w f) + w m, w f); the floats save 7-13 % of Dynamic
    Control's time, benchmarks/microopt.py.)"""
    sides = state.sides()
    if not len(sides):
        return None
    n0, n1, n2, f0, f1, f2 = wrench.tolist()
    if f2 <= 1e-9:
        return None
    h = float(state.ground_height)
    px, py = (h * f0 - n1) / f2, (n0 + h * f1) / f2
    c = state.sole_centres
    if c is None:
        c = state.sole_centres = _sole_centres(state, sides, h)
    # application points: the sole centres moved so that their weighted mean is the ZMP
    if len(c) == 1:
        w = [1.0]
        mx, my, mz = c[0]  # (1.0 times each)
    else:
        w = _split(c, px, py)
        (w0, w1), (c0, c1) = w, c
        mx, my, mz = w0 * c0[0] + w1 * c1[0], w0 * c0[1] + w1 * c1[1], w0 * c0[2] + w1 * c1[2]
    dx, dy, dz = px - mx, py - my, h - mz
    # the moment about the ZMP (vertical only): n - p x f
    m0 = n0 - (py * f2 - h * f1)
    m1 = n1 - (h * f0 - px * f2)
    m2 = n2 - (px * f1 - py * f0)
    rows = []
    for wi, (cx, cy, cz) in zip(w, c):
        x0, x1, x2 = cx + dx, cy + dy, cz + dz
        g0, g1, g2 = wi * f0, wi * f1, wi * f2
        rows.append((x1 * g2 - x2 * g1 + wi * m0, x2 * g0 - x0 * g2 + wi * m1, x0 * g1 - x1 * g0 + wi * m2,
                     g0, g1, g2))
    bodies = state.foot_bodies
    if bodies is None:
        bodies = state.foot_bodies = state.model.joint_body[np.asarray(state.parts.feet)[sides]]
    return bodies, np.array(rows)


def _sole_centres(state, sides, height):
    """Per side in contact: the mean of its sole points on the ground [x, y, height] (floats)."""
    soles = state.sole_world()
    h = float(height)
    return [soles[s][:, :2].mean(axis=0).tolist() + [h] for s in sides.tolist()]


def _split(centres, px, py):
    """Weights (2,) of two sole centres whose combination is the projection of p on their line."""
    (ax, ay, _), (bx, by, _) = centres[0], centres[1]
    dx, dy = bx - ax, by - ay
    t = ((px - ax) * dx + (py - ay) * dy) / max(dx * dx + dy * dy, 1e-12)
    t = min(max(t, 0.0), 1.0)
    return [1.0 - t, t]


def joint_stress(tau, limits, tolerance=0.0):
    """Eq. 2.9: tau - tau_max above the range, tau - tau_min below it, zero inside (nv,)."""
    low, high = limits
    s = tau - np.clip(tau, low, high)
    s[np.abs(s) <= tolerance] = 0.0
    return s


def saturated_stress(tau, limits, knees, tolerance=0.0):
    """Eq. 2.9 with a smooth saturation of the strength. A DOF with strength tau_max (tau_min
    alike) delivers sat(tau): tau up to the knee k = tau_max - w (w = band * |tau_max|, knees =
    the limits pulled in by w), then k + e - e^2 / (4 w) for an excess e = tau - k in [0, 2 w],
    tau_max beyond. The stress tau - sat(tau) is

        0 for e <= 0,   e^2 / (4 w) for 0 < e < 2 w,   tau - tau_max for e >= 2 w,

    continuous with its slope (C1): comfort and passive control start gently near the strength
    instead of at a kink, and never let a joint deliver more than its strength. band = 0 is
    joint_stress."""
    s = joint_stress(tau, knees)  # the excess over the knee, signed
    over = np.flatnonzero(s)
    if len(over):
        (low, high), (klow, khigh) = limits, knees
        e = np.abs(s[over])
        w = np.where(s[over] > 0.0, high[over] - khigh[over], klow[over] - low[over])  # (> 0)
        quadratic = e * e / (4.0 * np.where(w > 0.0, w, np.inf))  # (w = 0: the hard clip)
        s[over] = np.copysign(np.where(e < 2.0 * w, quadratic, e - w), s[over])
    if tolerance:
        s[np.abs(s) <= tolerance] = 0.0
    return s


def stress_of(state, tau):
    """The stress (nv,) of torques `tau` on a ControlState: saturated_stress with the state's
    saturation band (Settings.saturation_band), or eq. 2.9's hard clip (joint_stress) at 0."""
    tol = state.settings.torque_tolerance
    if state.settings.saturation_band <= 0.0:
        return joint_stress(tau, state.limits, tol)
    return saturated_stress(tau, state.limits, state.knees, tol)


def pinv(a, rcond):
    """np.linalg.pinv(a, rcond): singular values at or below rcond times the largest are cut; an
    empty matrix gives the zero matrix of the transposed shape."""
    a = np.asarray(a, float)
    if a.size == 0:
        return np.zeros(a.shape[::-1])
    return np.linalg.pinv(a, rcond=rcond)


# ---- eq. 2.17-2.18: passive control -------------------------------------------------------------

def passive_control(state, a, dofs=None):
    """Change of acceleration (nv,) of the stressed joints among `dofs` (the upper body by
    default) that brings each one's torque to its limit: eq. 2.17 (own inertia H_ii), eq. 2.18
    (the others' changes through H_ij), then rounds that hold every passive joint at its limit
    exactly (the fixed point of eq. 2.18) and add the joints the changes pushed over."""
    dofs = state.parts.upper if dofs is None else np.asarray(dofs, int)
    delta = np.zeros(state.model.nv)
    tol = state.settings.torque_tolerance
    stress = stress_of(state, required_torques(state, a)[0])[dofs]
    k = dofs[stress != 0.0]
    if not len(k):
        return delta
    h = state.inertia(k, k)
    first = -stress[stress != 0.0] / np.diag(h)  # eq. 2.17
    delta[k] = first - (h @ first - np.diag(h) * first) / np.diag(h)  # eq. 2.18
    passive = np.zeros(state.model.nv, bool)
    passive[k] = True
    target = np.clip(required_torques(state, a)[0], *state.limits)
    if state.settings.saturation_band > 0.0:  # held at what the joint delivers: sat(tau), not the clip
        tau0 = required_torques(state, a)[0]
        target = tau0 - stress_of(state, tau0)
    for _ in range(state.settings.passive_rounds):
        tau = required_torques(state, a + delta)[0]
        stress = stress_of(state, tau)
        new = np.zeros_like(passive)
        new[dofs] = stress[dofs] != 0.0
        target[new & ~passive] = (tau - stress)[new & ~passive]
        passive |= new
        c = np.flatnonzero(passive)
        gap = target[c] - tau[c]
        if np.abs(gap).max() <= tol:
            break
        delta[c] += np.linalg.lstsq(state.inertia(c, c), gap, rcond=None)[0]
    return delta


# ---- eq. 2.16, 2.19-2.22: active control of one part -------------------------------------------

def pelvis_jacobian(state):
    """J_p (nv, 3) of eq. 2.16: a world acceleration of the pelvis (no rotation) with every foot
    on the ground held still, by the legs' inverse kinematics (pseudo-inverse of each leg's
    Jacobian from the pelvis to the foot, singular values below leg_rcond of the largest cut:
    a straight knee cannot lengthen the leg); legs in the air ride along."""
    m, d, q = state.model, state.data, state.q
    update_frames(m, d, q)
    jp = np.zeros((m.nv, 3))
    jp[3:6] = d.frames[0, :3, :3].T  # root axes
    for side in np.flatnonzero(state.feet):
        cols = state.parts.legs[side]
        jf = segment_jacobian(m, d, q, state.parts.feet[side])
        jp[cols] = -pinv(jf[:, cols], rcond=state.settings.leg_rcond) @ (jf[:, 3:6] @ jp[3:6])
    return jp


def part_matrix(state, part):
    """(nv, k) map from a part's control acceleration to the change of all joint accelerations:
    the selection matrices S_a, S_b of eq. 2.16, or J_p for the legs."""
    if part == "legs":
        return state.pelvis_jacobian()
    return state.constants.selections[part]


def torque_sensitivity(state, part, rows, a):
    """d tau[rows] / d (part's control acceleration): H' (eq. 2.19) for the arms and back, H' J_p
    (eq. 2.22) for the legs, where the ground reaction's share between the feet also changes
    (evaluated by differences of the required torques, which are affine in a but for the share)."""
    if part != "legs":
        return state.inertia(rows, getattr(state.parts, part))
    jp, step = state.pelvis_jacobian(), state.settings.pelvis_step
    base = required_torques(state, a)[0][rows]
    return np.column_stack([(required_torques(state, a + step * jp[:, i])[0][rows] - base) / step
                            for i in range(3)])


def comfort_candidates(state, part, a):
    """Eq. 2.19-2.21: the part's acceleration of least norm that removes the stress of the
    stressed composite joints (bones) it can reach, all at once (least squares when they cannot
    all be relieved), uncapped (control_sequence caps the one that acts); an empty list when none
    is stressed."""
    if part == "legs" and not state.feet.all():
        # the legs are controlled through the pelvis for a figure "in a standing double-support
        # phase" (Oshita sec. 2.5.2); in single support "the motion needs to be controlled ... in
        # angular space. This is beyond the scope of this method" (sec. 2.5.4). Relieving the one
        # supporting leg by accelerating the pelvis down unloads it for a step but bends its knee
        # further, which needs more torque: CMU 131_01 with 6 kg per hand, knee collapsed 85 deg
        return []
    domain = state.parts.lower if part == "legs" else state.parts.upper
    stress = stress_of(state, required_torques(state, a)[0])
    rows = domain[stress[domain] != 0.0]
    if not len(rows):
        return []
    sens = torque_sensitivity(state, part, rows, a)
    reach = np.abs(sens).max(axis=1) > 1e-9
    if not reach.any():
        return []
    return [pinv(sens[reach], rcond=state.settings.rcond) @ -stress[rows[reach]]]


def bounded(state, part, x):
    """A part's control acceleration scaled down to Settings.max_part_acceleration (rad/s^2, arms
    and back) or max_pelvis_acceleration (m/s^2, legs): the rest is left to the next part."""
    top = state.settings.max_pelvis_acceleration if part == "legs" else state.settings.max_part_acceleration
    return x * min(1.0, top / max(np.linalg.norm(x), 1e-12))


# ---- the heuristic order ------------------------------------------------------------------------

ACTED = 1e-9  # rad/s^2 (m/s^2 on the root): ControlLog.record's least change that counts


@dataclass
class ControlLog:
    """What acted in one step: per DOF masks and the sequence of actions."""

    nv: int
    passive: np.ndarray = None
    comfort: np.ndarray = None
    balance: np.ndarray = None
    actions: list = field(default_factory=list)  # (part, "passive" | "comfort" | "balance")

    def __post_init__(self):
        self.passive, self.comfort, self.balance = (np.zeros(self.nv, bool) for _ in range(3))

    def record(self, part, kind, delta):
        # a change is a DOF's acceleration moved by more than rounding: a pseudo-inverse leaves
        # 1e-16..1e-15 rad/s^2 on DOFs it does not move, and a last-bit change of the inputs
        # then flipped the recorded control of a bone (CMU walk, 15 kg per hand)
        moved = np.abs(delta) > ACTED
        if np.count_nonzero(moved):
            getattr(self, kind)[moved] = True
            self.actions.append((part, kind))


def control_sequence(state, a0, criteria, passive=True, log=None, memory=None):
    """Oshita's steps 3-5: passive control of the upper body, active control of the arms then the
    back, recomputed passive control, then the legs through the pelvis. `criteria` maps a kind
    ("comfort", "balance") to f(state, part, a_active, a_current) -> list of candidate part
    accelerations; `memory` (modes.ModeMemory, optional): the kinds that acted on each part in the
    last step (hysteresis, largest_with_kind). Returns the output acceleration."""
    log = log or ControlLog(state.model.nv)
    active = np.array(a0, float)
    stress = passive_control(state, active) if passive else np.zeros_like(active)
    log.record("upper", "passive", stress)
    for part in ("arms", "back", "legs"):
        if part == "legs" and passive:  # step 4's recomputation of the passive change
            stress = passive_control(state, active)
            log.record("upper", "passive", stress)
        previous = memory.previous(part) if memory is not None else None
        best = largest_with_kind(state, part, criteria, active, active + stress, previous)
        if best is None:
            continue
        kind, x = best
        delta = part_matrix(state, part).dot(bounded(state, part, x))
        active = active + delta
        log.record(part, kind, delta)
    return active + stress, log


def largest_with_kind(state, part, criteria, active, current, previous=None):
    """The part's candidate of the largest demand, with its kind, or None. The demands are compared
    before the cap (bounded): capped first, two saturated candidates would tie at the cap and the
    last bit would choose (the 15 kg squat parted from itself under gravity x (1 + 1e-14)).
    Hysteresis: the candidate of the `previous` kind (the one that acted last step) stays unless
    another is larger by Settings.mode_margin of it."""
    if not len(getattr(state.parts, part, ())) and part != "legs":
        return None
    found = [(kind, c) for kind, f in criteria.items() for c in f(state, part, active, current)]
    found = [(k, c, np.linalg.norm(c)) for k, c in found if c is not None and np.count_nonzero(c)]
    if not found:
        return None
    kind, c, size = max(found, key=lambda kcn: kcn[2])
    if previous is not None and kind != previous:
        held = [(k, c1, n) for k, c1, n in found if k == previous]
        if held and size <= (1.0 + state.settings.mode_margin) * held[0][2]:
            kind, c = held[0][:2]
    return kind, c


def comfort_criterion(state, part, active, current):
    """Stress of the upper body is judged as the tracking would need it (the active acceleration,
    passive change excluded); the legs' on the current acceleration (passive included)."""
    return comfort_candidates(state, part, current if part == "legs" else active)


@dataclass
class ComfortResult:
    delta: np.ndarray  # (nv,) change of acceleration
    stress: np.ndarray  # (nv,) eq. 2.9 at the tracking acceleration
    stress_after: np.ndarray  # (nv,) at the output acceleration
    tau: np.ndarray  # (nv,) required torques at the output
    log: ControlLog


def comfort_control(state, a_tracking):
    """Comfort control alone: Δθ'' relieving joint stress in the thesis's order (exactly zero when
    nothing is stressed)."""
    a0 = np.asarray(a_tracking, float)
    stress = stress_of(state, required_torques(state, a0)[0])
    log = ControlLog(state.model.nv)
    if not stress.any():
        return ComfortResult(np.zeros_like(a0), stress, stress, None, log)
    out, log = control_sequence(state, a0, {"comfort": comfort_criterion}, log=log)
    tau = required_torques(state, out)[0]
    return ComfortResult(out - a0, stress, stress_of(state, tau), tau, log)
