"""Planted feet (Oshita 2003, sec. 2.4.2): where a supporting foot is held, and the legs' inverse
kinematics that hold it there.

A foot that supports the body (the input's support intervals, with the animator's overrides) is
planted where it was when it landed and follows the input foot's own motion from there (a heel
that rises in the input rises), rolling about its contact point without sliding (rolling_anchor;
the capture's foot skate is first removed from the whole input, foot_skate). Per step:

- constrain: the supported leg's joint accelerations are the tracking ones corrected by the
  least change that gives the foot its target acceleration for the pelvis's acceleration (the
  acceleration form of the limb's inverse kinematics);
- project_velocity: the velocities projected onto the foot's target velocity at the step's end;
- predicted_resolve / project_position: the positions re-solved (a Gauss-Newton step of the leg's
  IK on its own DOFs), predicted from the step's start or after the Euler step, so the foot
  cannot drift however balance control moves the pelvis.

The legs' least squares are damped, more so near a straight knee (damping: a straight leg cannot
move its foot along itself). The Jacobians come from kinematics.motion_subspace, which carries a
two-axis (universal) joint's parent-side axis as Data.joint_motion gives it.
"""

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.ndimage import gaussian_filter1d

from ..dynamics import kinematics
from ..dynamics.inverse_dynamics import velocity_terms
from .vector_math import cross, cross3, point_motion, rotation_log

# s: a foot the input lifts leaves its planted place for the input's over this time (release):
# its leg stays held by the inverse kinematics, on a target blended from the planted pose to the
# input's (smoothstep), instead of being handed to the tracking at once, which turned the CMU
# demo's left hip 5.6 deg in the frame its foot lifted
RELEASE_TIME = 0.15
LANDING_TURN = 0.1  # rad: the most a planted leg's joint (or the root) may turn in a step predicted_resolve serves
SKATE_SMOOTHING = 0.02  # s, standard deviation of foot_skate's smoothing
IDENTITY6 = np.eye(6)  # (made once: the damping asks for it at every step of a straight leg)
CONTACT_SCALE = 0.01  # m: sole points this much above the lowest share the contact by exp(-dz / scale)


def frame_index(t, dt_frame, frame_count):
    """The input frame a step at time t belongs to."""
    return min(int(math.floor(t / dt_frame + 1e-9)), frame_count - 1)


# ---- the input's feet ---------------------------------------------------------------------------

def sole_points(model, qs, parts):
    """Both feet's sole points (F, k, 3) at every configuration (one batched forward kinematics)."""
    return kinematics.batch_point_positions(model, qs, np.concatenate(parts.sole_joints),
                                            np.concatenate(parts.sole_points))


def contact_steps(model, qs, parts, soles=None):
    """Per side: per frame the weights (F, k) of a foot's sole points in contact (the lowest ones,
    by exp(-height above the lowest / CONTACT_SCALE)) and the horizontal step (F - 1, 2) of that
    contact point from each frame to the next; `soles`: the sides' sole points if known."""
    if soles is None:
        soles = np.split(sole_points(model, qs, parts), [len(parts.sole_joints[0])], axis=1)
    out = []
    for pts in soles:
        z = pts[..., 2]
        w = np.exp(-(z - z.min(axis=1, keepdims=True)) / CONTACT_SCALE)
        w /= w.sum(axis=1, keepdims=True)
        out.append((w, np.einsum("fk,fkc->fc", w[1:], pts[1:, :, :2] - pts[:-1, :, :2])))
    return out


def foot_skate(model, parts, skeleton, tr, support_in, dt_frame):
    """The input's foot skate as a root offset (F, 2): what moves the whole motion so that the
    contact point of a supporting foot stays where it is (the mean over both feet in double
    support; held while no foot supports). The capture's own root travel is otherwise kept."""
    pos, ori = tr.root_pose(skeleton)
    qs = model.configurations(pos, ori, tr.rotations)
    steps = [step for _, step in contact_steps(model, qs, parts)]
    out = np.zeros((tr.frame_count, 2))
    for f in range(1, tr.frame_count):
        sides = [s for s in range(2) if support_in[f, s] and support_in[f - 1, s]]
        out[f] = out[f - 1] - (np.mean([steps[s][f - 1] for s in sides], axis=0) if sides else 0.0)
    # the offset's velocity jumps where the supporting feet change: smoothed over ~0.05 s so
    # the root gets no acceleration spike (the planted feet's rolling anchor takes the rest)
    return gaussian_filter1d(out, SKATE_SMOOTHING / dt_frame, axis=0, mode="nearest")


def rolling_anchor(model, qs, parts, soles, support_in):
    """A planted foot rolls (heel to toe) but its contact does not slide: per input frame and
    side, the weights of the sole points in contact (the lowest ones) and the horizontal offset
    (F, 2, 3) that cancels the input's own travel of that contact point over each support
    interval (capture's foot skate included). Between support intervals the offset holds its
    last value: a planted foot's target does not jump when the input lifts it (the jump turned
    the CMU demo's left hip 5.6 deg in one frame), and a released foot's offset is blended out
    (PlantedFeet._shift)."""
    nf = len(qs)
    weights, roll = [], np.zeros((nf, 2, 3))
    for s, (w, step) in enumerate(contact_steps(model, qs, parts, soles)):
        weights.append(w)
        for f in range(1, nf):
            roll[f, s, :2] = roll[f - 1, s, :2]
            if support_in[f, s] and support_in[f - 1, s]:
                roll[f, s, :2] -= step[f - 1]
    return weights, roll


@dataclass
class LegJacobian:
    """A planted leg at one configuration: the (6, k) Jacobian of the foot's angular velocity and
    head velocity on the DOFs of the foot's ancestors (the rest of its (6, nv) Jacobian is zero),
    the foot's world frame (4, 4), those DOFs (k,), and the columns of the leg's own DOFs (6, l)
    with those DOFs (l,)."""

    full: np.ndarray
    frame: np.ndarray
    dofs: np.ndarray
    leg: np.ndarray
    cols: np.ndarray


@dataclass
class Plant:
    """A planted foot: its world offset from the input foot (3,), the rolling anchor's offset at
    landing (3,), and their difference (what moves the input foot onto the planted one)."""

    head: np.ndarray
    roll: np.ndarray
    shift: np.ndarray


@dataclass
class PlantedFeet:
    """The planted feet of one control loop and the legs that hold them (see the module notes)."""

    settings: object  # ControlSettings
    tracking: object  # TrackingController
    desired_data: object  # a Data of the loop's model for the input's configurations
    support_in: np.ndarray  # (F, 2) bool, the input's support
    roll_weights: list  # per side (F, k): rolling_anchor's
    roll: np.ndarray  # (F, 2, 3): rolling_anchor's
    planted: list = field(default_factory=lambda: [None, None])  # per side a Plant or None
    # per side, a foot being released: (its offset from the input foot at lift-off, plant and rolling
    # anchor (3,), the rolling anchor's offset then (3,), lift time), or None
    releasing: list = field(default_factory=lambda: [None, None])
    drift: list = field(default_factory=lambda: [None, None])  # per side (contact drift (2,), last sole points)
    grid_targets: list = None  # per input frame: input_feet at that frame
    # memos of one configuration (the steps ask for the same ones several times)
    _soles_key: tuple = None
    _soles: list = None
    _legs_key: tuple = None
    _legs: list = None
    _dls_factors: dict = field(default_factory=dict)  # id(leg Jacobian): (Jacobian, damped pseudo-inverse)
    _targets_key: tuple = None
    _targets: list = None

    def __post_init__(self):
        self.dt_frame = self.tracking.dt
        self.frame_count = len(self.support_in)
        st = self.settings
        self.eye6 = st.foot_damping ** 2 * np.eye(6)
        self.singular = (st.singular_band ** 2, st.singular_damping ** 2)

    def precompute_targets(self, body):
        self.grid_targets = [self.input_feet(body, f * self.dt_frame) for f in range(self.frame_count)]

    # ---- landing and planted state ----

    def update(self, body, feet, t, q):
        """Plant the feet that landed at t, start releasing those that lifted."""
        for s in range(2):
            if not feet[s]:
                if self.planted[s] is not None:
                    roll = self.roll_offset(s, t)[0]
                    self.releasing[s] = (self.planted[s].shift + roll, roll, t)
                    self.planted[s] = None
                elif self.releasing[s] is not None and t - self.releasing[s][2] >= RELEASE_TIME - 1e-9:
                    self.releasing[s] = None
            else:
                self.releasing[s] = None
                if self.planted[s] is None:
                    self.planted[s] = self.landing(body, s, t, q)
                    self.drift[s] = None

    def held(self, feet):
        """(2,) bool: the feet whose legs the inverse kinematics hold, planted (`feet`) or being
        released."""
        return np.array([bool(feet[0]) or self.releasing[0] is not None,
                         bool(feet[1]) or self.releasing[1] is not None])

    def release(self):
        """Let go of every foot at once (a fall)."""
        self.planted = [None, None]
        self.releasing = [None, None]

    def _shift(self, s, t):
        """The offset (3,) moving the input foot (with its rolling anchor) onto the held one at t,
        and its velocity and acceleration: the plant's, or for a released foot its offset at
        lift-off blended out by a smoothstep (the rolling anchor holds its lift-off value then)."""
        if self.planted[s] is not None:
            return self.planted[s].shift, 0.0, 0.0
        shift, roll, t0 = self.releasing[s]
        u = min(max((t - t0) / RELEASE_TIME, 0.0), 1.0)
        w = 1.0 - u * u * (3.0 - 2.0 * u)
        dw = -6.0 * u * (1.0 - u) / RELEASE_TIME
        ddw = -(6.0 - 12.0 * u) / RELEASE_TIME ** 2 if u < 1.0 else 0.0
        return w * shift - roll, dw * shift, ddw * shift

    def landing(self, body, s, t, q):
        """A landing foot's offset from the input's. The foot may land turned from the input's (a
        push changed its swing); its first target turns it to the input's rotation at once, so the
        offset makes that turn one about the contact point (the input's contact weights at t), not
        the ankle, which slid the contact 2.4 mm (the demo's push)."""
        m, b, offset = body.model, body.foot_body[s], body.foot_offset[s]
        kinematics.update_frames(m, self.desired_data, self.tracking.desired_state(t)[0])
        want = self.desired_data.frames[b] @ offset
        weights = self.roll_weights[s]
        contact = weights[min(int(round(t / self.tracking.dt)), len(weights) - 1)] @ self.soles(body, q)[s]
        now = body.data.frames[b] @ offset  # (body.data is at q: soles)
        head = contact - want[:3, :3] @ (now[:3, :3].T @ (contact - now[:3, 3]))
        roll = self.roll_offset(s, t)[0]
        return Plant(head - want[:3, 3], roll, head - want[:3, 3] - roll)

    def roll_offset(self, s, t):
        """The rolling anchor's offset (3,), velocity and acceleration at time t (linear between
        frames; central differences)."""
        x = float(np.clip(t / self.dt_frame, 0.0, self.frame_count - 1))
        f0 = min(int(np.floor(x)), self.frame_count - 1)
        f1 = min(f0 + 1, self.frame_count - 1)
        r = self.roll[:, s]
        pos = r[f0] + (x - f0) * (r[f1] - r[f0])
        fm, fp = max(f0 - 1, 0), f1
        vel = (r[fp] - r[fm]) / (max(fp - fm, 1) * self.dt_frame)
        acc = (r[fp] - 2.0 * r[f0] + r[fm]) / self.dt_frame ** 2 if fp - fm == 2 else np.zeros(3)
        supported = self.support_in[fm:fp + 1, s].all()
        return pos, (vel if supported else np.zeros(3)), (acc if supported else np.zeros(3))

    def soles(self, body, q):
        """World sole points of both feet at q, [(k, 3), (k, 3)], one forward-kinematics pass
        (shared by the control state, the support polygon and the drift measure)."""
        key = (q.tobytes(), id(body))
        if self._soles_key != key:
            kinematics.update_frames(body.model, body.data, q)
            pts = kinematics.body_points(body.data, body.sole_bodies, body.sole_hom)
            k = body.sole_split
            self._soles_key, self._soles = key, [pts[:k], pts[k:]]
        return self._soles

    def contact_drift(self, body, q, s, f):
        """Horizontal travel (m) of the planted foot's contact point since landing: the sole points'
        steps weighted by the input's contact weights (a roll about the contact is no travel)."""
        pts = self.soles(body, q)[s]
        last = self.drift[s]
        if last is None:
            dx = dy = 0.0
        else:
            ex, ey = self.roll_weights[s][f].dot(pts[:, :2] - last[1][:, :2]).tolist()
            dx, dy = last[0][0] + ex, last[0][1] + ey
        self.drift[s] = ((dx, dy), pts)
        return math.sqrt(dx * dx + dy * dy)

    # ---- targets ----

    def targets(self, body, feet, t):
        """Per planted side: the input foot's world rotation (3, 3), head position (3,), 6-D velocity
        and 6-D acceleration (angular; head point), moved by the landing offset (remembered for the
        same time, feet, plants and body)."""
        p0, p1 = self.planted
        r0, r1 = self.releasing
        key = (t, bool(feet[0]), bool(feet[1]), id(p0), id(p1), id(r0), id(r1), id(body))
        if self._targets_key != key:
            self._targets_key, self._targets = key, self.targets_at(body, feet, t)
        return self._targets

    def targets_at(self, body, feet, t):
        f = self.tracking.on_frame(t)
        feet_in = self.grid_targets[f] if f is not None else self.input_feet(body, t)
        out = [None, None]
        for s in (0, 1):
            if feet[s]:
                rot, pos, vel, acc = feet_in[s]
                shift, dshift, ddshift = self._shift(s, t)
                if self.planted[s] is not None:
                    out[s] = (rot, pos + shift, vel, acc)
                else:
                    out[s] = (rot, pos + shift, np.concatenate((vel[:3], vel[3:] + dshift)),
                              np.concatenate((acc[:3], acc[3:] + ddshift)))
        return out

    def input_feet(self, body, t):
        """Both input feet at time t, without their skate (rolling anchor): world rotation, head
        position, 6-D velocity and acceleration."""
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
            xd = vo + cross(w, x)
            xdd = ao + cross(al, x) + cross(w, xd)
            roll, roll_v, roll_a = self.roll_offset(s, t)
            out.append((frame[:3, :3], x + roll, np.concatenate((w, xd + roll_v)),
                        np.concatenate((al, xdd + roll_a))))
        return out

    # ---- the legs' inverse kinematics ----

    def leg_jacobians(self, body, q, feet):
        """Per planted side a LegJacobian at q, one forward-kinematics pass for both legs
        (remembered for the same q: the acceleration and velocity projections share it)."""
        key = (q.tobytes(), bool(feet[0]), bool(feet[1]), id(body))
        if self._legs_key == key:
            return self._legs
        m, d = body.model, body.data
        self._dls_factors.clear()  # the factors of the previous configuration's legs
        sub = kinematics.motion_subspace(m, d, q)  # (nv, 6) world (omega, v at origin)
        if feet[0] and feet[1] and body.legs_batched is not None:
            out = self._both_legs(body, d, sub)
            self._legs_key, self._legs = key, out
            return out
        out = [None, None]
        for s in (0, 1):
            if not feet[s]:
                continue
            frame = d.frames[body.foot_body[s]].dot(body.foot_offset[s])
            dofs = body.leg_dofs[s]
            cols = sub.take(dofs, axis=0)  # (k, 6)
            jac = np.empty((6, len(dofs)))
            jac[:3] = cols[:, :3].T
            # head velocity v_O + omega x x = v_O - x x omega
            # head velocity v_O + omega x x: each column's omega x x as one product with x's skew
            x0, x1, x2 = frame[:3, 3].tolist()
            jac[3:] = (cols[:, 3:] - cols[:, :3].dot(np.array([[0.0, x2, -x1], [-x2, 0.0, x0], [x1, -x0, 0.0]]))).T
            out[s] = LegJacobian(jac, frame, dofs, jac[:, body.leg_pos[s]], body.leg_cols[s])
        self._legs_key, self._legs = key, out
        return out

    def _both_legs(self, body, d, sub):
        """leg_jacobians of two planted legs of the same layout, in batched products."""
        bodies, offsets, dofs, pos = body.legs_batched
        frames = d.frames.take(bodies, axis=0) @ offsets  # (2, 4, 4)
        (a0, a1, a2), (b0, b1, b2) = frames[:, :3, 3].tolist()
        skew = np.array([[[0.0, a2, -a1], [-a2, 0.0, a0], [a1, -a0, 0.0]],
                         [[0.0, b2, -b1], [-b2, 0.0, b0], [b1, -b0, 0.0]]])
        cols = sub.take(dofs, axis=0)  # (2, k, 6)
        jac = np.empty((2, 6, dofs.shape[1]))
        jac[:, :3] = cols[:, :, :3].swapaxes(1, 2)
        jac[:, 3:] = (cols[:, :, 3:] - cols[:, :, :3] @ skew).swapaxes(1, 2)
        leg = jac[:, :, pos]  # (2, 6, l)
        return [LegJacobian(jac[i], frames[i], dofs[i], leg[i], body.leg_cols[i]) for i in (0, 1)]

    def dls(self, jac, r):
        """Damped least squares J' (J J' + lambda^2)^-1 r of a (6, k) leg Jacobian. The damped
        pseudo-inverse J' (J J' + lambda^2)^-1 is made once per Jacobian, as (J J' + lambda^2)^-1 J
        transposed (the matrix is symmetric): the acceleration, velocity and position projections
        of a step share the legs at q, and each of their solves is then one product."""
        known = self._dls_factors.get(id(jac))
        if known is None or known[0] is not jac:
            jj = jac.dot(jac.T)
            try:
                pseudo_inverse = np.linalg.solve(jj + self.damping(jj), jac).T
            except np.linalg.LinAlgError:
                raise np.linalg.LinAlgError("a planted leg's Jacobian is singular") from None
            known = self._dls_factors[id(jac)] = (jac, pseudo_inverse)
        return known[1].dot(r)

    def damping(self, jj):
        """lambda^2 I for the damped least squares of a leg with J J' = jj: foot_damping, growing
        to singular_damping as the smallest singular value of J falls through singular_band
        (adaptive damping, Nakamura and Hanafusa 1986). A leg near straight cannot move its foot
        along itself; undamped, each step's millimetres of error along it asked the knee for
        degrees, the next step's the other way, and a standing figure's knees thrashed after a
        10 N s push."""
        band2, extra = self.singular
        low = np.linalg.eigvalsh(jj)[0]  # the smallest eigenvalue of J J': sigma_min^2
        if low >= band2:
            return self.eye6
        return self.eye6 + (extra * (1.0 - max(low, 0.0) / band2)) * IDENTITY6

    def constrain(self, body, q, v, a, feet, targets):
        """Leg accelerations that give each planted foot its target acceleration: the tracking
        ones plus the least change (the acceleration form of the leg's IK for the pelvis's
        acceleration)."""
        m, d = body.model, body.data
        legs = self.leg_jacobians(body, q, feet)  # the frames at q
        vel, _, product = velocity_terms(m, d, q, v)  # shared with the inverse dynamics
        # kinematics.body_accelerations at the feet's bodies: the joint accelerations' part as the
        # motion subspace columns of the feet's ancestor DOFs
        sub = kinematics.motion_subspace(m, d, q)
        acc = ((body.feet_dof_mask * a).dot(sub) + body.feet_ancestors.dot(product)).tolist()
        vel = vel.take(body.feet_rows, axis=0).tolist()
        a = a.copy()
        for s, leg in enumerate(legs):
            if leg is None:
                continue
            w, vo, al, ao = vel[s][:3], vel[s][3:], acc[s][:3], acc[s][3:]
            now = al + point_motion(w, vo, al, ao, leg.frame[:3, 3].tolist())[1]
            a[leg.cols] += self.dls(leg.leg, targets[s][3] - np.array(now))
        return a

    def project_velocity(self, body, q, v, feet, targets):
        """v with each planted foot at its target velocity (the foot's velocity is J v)."""
        v = v.copy()
        for s, leg in enumerate(self.leg_jacobians(body, q, feet)):
            if leg is not None:
                v[leg.cols] += self.dls(leg.leg, targets[s][2] - leg.full.dot(v.take(leg.dofs)))
        return v

    def predicted_resolve(self, body, q, v, feet, targets, dt):
        """The planted legs' position re-solve (project_position's Gauss-Newton step) without a
        forward kinematics at the integrated configuration: each foot's pose at q (+) v dt is
        predicted from the frames at q to second order, its head x + x' dt + x'' dt^2 / 2 and its
        rotation turned by omega dt + alpha dt^2 / 2, with the velocity-product acceleration of
        integrate's constant-velocity step (the rotating legs carry the foot on an arc), and the
        error to its target is corrected by the legs' damped least squares at q, added to the
        step (one integration). The residual is third order in the step (v dt). A (nv,) step,
        or None in a step this does not hold for: a held leg's joint (or the root) turning more
        than LANDING_TURN. (A foot the input lifts keeps a continuous target: the rolling anchor
        holds its offset and the release blends it out.)"""
        f0, f1 = bool(feet[0]), bool(feet[1])
        turns = v.take(body.landing_dofs[f0, f1])
        if np.abs(turns).max() * dt > LANDING_TURN:
            return None
        m, d = body.model, body.data
        legs = self.leg_jacobians(body, q, feet)  # the frames at q
        vel, _, product = velocity_terms(m, d, q, v)  # the step's velocities
        acc = body.feet_ancestors.dot(product).tolist()
        vb = vel.take(body.root_feet_rows, axis=0).tolist()
        # integrate moves the root's origin along a straight line (its world velocity p' fixed over
        # the step), not on the screw of a constant spatial velocity: every body's spatial
        # acceleration then gets the root's (0, -omega x p')
        w0 = vb[0][:3]
        p_dot = [a + b for a, b in zip(vb[0][3:], cross3(w0, q[:3].tolist()))]
        root = cross3(w0, p_dot)
        h, h2 = dt, 0.5 * dt * dt
        step = np.zeros(m.nv)
        for s, leg in enumerate(legs):
            if leg is None:
                continue
            x = leg.frame[:3, 3].tolist()
            w, vo, al = vb[s + 1][:3], vb[s + 1][3:], acc[s][:3]
            ao = [acc[s][3] - root[0], acc[s][4] - root[1], acc[s][5] - root[2]]
            xd, xdd = point_motion(w, vo, al, ao, x)  # the head point's velocity and acceleration
            t0, t1, t2 = rotation_log(targets[s][0].dot(leg.frame[:3, :3].T)).tolist()
            p0, p1, p2 = targets[s][1].tolist()
            # target - (pose + velocity h + acceleration h^2 / 2), the turn's pose being zero
            # (np.array of the floats, not np.r_: np.r_ parses its index syntax at every call, which
            # cost more than the rest of the prediction)
            target = np.array([t0, t1, t2, p0, p1, p2])
            pose = np.array([0.0, 0.0, 0.0, *x])
            error = target - (pose + h * np.array([*w, *xd]) + h2 * np.array([*al, *xdd]))
            step[leg.cols] = self.dls(leg.leg, error)
        return step

    def project_position(self, body, q, feet, targets, iterations):
        """Gauss-Newton iterations of the planted legs' IK on their own DOFs towards the targets'
        poses (the exact re-solve after the step)."""
        m = body.model
        for _ in range(iterations):
            step = np.zeros(m.nv)
            for s, leg in enumerate(self.leg_jacobians(body, q, feet)):
                if leg is None:
                    continue
                rot, pos = targets[s][0], targets[s][1]
                error = np.concatenate((rotation_log(rot @ leg.frame[:3, :3].T), pos - leg.frame[:3, 3]))
                step[leg.cols] = self.dls(leg.leg, error)
            q = kinematics.integrate(m, q, step)
        return q

    def through_feet(self, body, q, feet, solve_inertia, dv):
        """A push's velocity change on a body standing on planted feet: the feet are contacts that
        do not move during the impulse, so the ground takes its share (dv projected in the inertia
        metric onto Jc dv = 0; `solve_inertia(x)` is H^-1 x). The floating body's response would
        carry the pelvis away from feet the legs then cannot reach: with straight legs they could
        only follow it by flexing a knee through its singularity."""
        rows = []
        for leg in self.leg_jacobians(body, q, feet):
            if leg is not None:
                row = np.zeros((6, len(dv)))
                row[:, leg.dofs] = leg.full
                rows.append(row)
        jc = np.concatenate(rows)
        h_jc = solve_inertia(jc.T)
        # (a straight leg cannot move its foot along itself: Jc H^-1 Jc' is then singular, and
        # Jc dv lies in its range)
        lam = np.linalg.lstsq(jc.dot(h_jc), jc.dot(dv), rcond=1e-10)[0]
        return dv - h_jc.dot(lam)

