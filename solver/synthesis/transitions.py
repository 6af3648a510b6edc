"""Transitions between two actions (Oshita 2003, sec. 3.4): blending (3.4.2), connection (3.4.3)
and, beyond the thesis, inertialization. Every mode ends with the same rule for supporting legs:
a foot that supports the body at the join stays where the previous action planted it until the
next action lifts it, then blends smoothly to the next action's trajectory (Fig. 3.3).

The next action is first placed on the floor plan (yaw about +Z and a horizontal shift) so that
its supporting feet at the join best match the current ones (its root when no foot supports).
Weights use the quintic smootherstep rather than the thesis's linear ramp: a linear weight has a
velocity jump at both ends of the window, i.e. an acceleration spike (see the README).
"""

from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import CubicHermiteSpline

from .. import rotations
from ..dynamics import spatial
from ..errors import HumanAnimError
from ..motion_control.contacts import runs
from ..motion_control.limb_ik import LimbIK
from ..skeleton import compose, decompose
from ..trajectories import Trajectories
from .action import (ANGULAR, CONSTRAINT_NAMES, LIMBS, SPATIAL, SUPPORT, blend_frames, rigid_2d,
                     slerp, transformed, yaw_of)

MODES = ("blend", "connect", "inertialize")
LEGS = ("foot.L", "foot.R")


class TransitionRejected(HumanAnimError):
    """A transition the constraints at the join do not allow; `reason` says why."""

    def __init__(self, reason):
        super().__init__(reason)
        self.reason = reason


@dataclass
class TransitionSettings:
    blend_duration: float = None  # s; None: min(terminal of the current, initial of the next)
    inertialization_duration: float = None  # s; None: as blend_duration
    release_duration: float = None  # s a lifted foot takes to rejoin its own trajectory; None: blend
    lift_height: float = 0.08  # m, flying foot at the connective action's middle keyframe
    angular_speed: float = 1.5  # rad/s, eq. 3.5's constant C_angular
    spatial_speed: float = 0.4  # m/s, eq. 3.5's constant C_spatial
    # m/s^2: beyond eq. 3.5, a connective phase is also long enough that the root and flying foot
    # accelerate no more than this or the next action's own 99th percentile, whichever is larger
    spatial_acceleration: float = 1.0
    min_phase: float = 0.1  # s, shortest phase of a connective action


@dataclass
class Transition:
    mode: str
    trajectories: Trajectories  # the joined motion, frames from the first action's first frame
    support: dict  # side -> (F,) bool, feet planted in the joined motion
    window: tuple  # (first, last) output frame index of the transition
    next_start: int  # output frame index where the next action's own frames begin
    held: dict = field(default_factory=dict)  # side -> (F,) bool, frames a foot is held in place
    info: dict = field(default_factory=dict)


def smootherstep(u):
    u = np.clip(u, 0.0, 1.0)
    return u * u * u * (u * (6.0 * u - 15.0) + 10.0)


# ---- acceptance (sec. 3.4.2 and 3.4.3) ---------------------------------------------------------

def blend_rejection(a1, end1, a2, start2):
    """Why blending a1 (ending at its frame end1) into a2 is not allowed, or None: the root's and
    every limb's constraints must agree at the join (C_l1(T_total1) = C_l2(T_init2))."""
    c1, c2 = a1.constraint_at(end1), a2.constraint_at(start2)
    for limb in ["root"] + [k for k in LIMBS if k in c1 or k in c2]:
        x, y = c1.get(limb), c2.get(limb)
        if x != y:
            return (f"blend rejected: {limb} is {CONSTRAINT_NAMES.get(x, 'missing')} at the end of "
                    f"{a1.name!r} but {CONSTRAINT_NAMES.get(y, 'missing')} at the start of {a2.name!r}")
    return None


def connect_rejection(a1, end1, a2):
    """Why connecting is not allowed, or None: the roots' constraints agree and are not
    supporting, and one leg supports the body at the end of a1 and the start of a2."""
    r1, r2 = int(a1.constraints["root"][end1]), int(a2.constraints["root"][0])
    if r1 != r2 or r1 == SUPPORT:
        return (f"connect rejected: the root is {CONSTRAINT_NAMES[r1]} at the end of {a1.name!r} and "
                f"{CONSTRAINT_NAMES[r2]} at the start of {a2.name!r}")
    shared = [k for k in LEGS if k in a1.constraints and a1.constraints[k][end1] == SUPPORT
              and a2.constraints.get(k, [ANGULAR])[0] == SUPPORT]
    if not shared:
        return (f"connect rejected: no foot supports the body both at the end of {a1.name!r} and at the "
                f"start of {a2.name!r}")
    return None


# ---- the three modes ---------------------------------------------------------------------------

def transition(a1, a2, mode="blend", settings=None, end1=None, base=None):
    """Join a1 (used up to its frame end1, default its last) and a2; raises TransitionRejected.
    `base` forces the connective action's base foot ("foot.L" or "foot.R")."""
    if mode not in MODES:
        raise HumanAnimError(f"unknown transition mode {mode!r} (one of {', '.join(MODES)})")
    s = settings or TransitionSettings()
    if a1.skeleton is not a2.skeleton and a1.skeleton.names != a2.skeleton.names:
        raise TransitionRejected("the two actions are not for the same armature")
    if abs(a1.fps - a2.fps) > 1e-6:
        raise TransitionRejected(f"{a1.name!r} runs at {a1.fps:g} fps and {a2.name!r} at {a2.fps:g}")
    end1 = a1.frame_count - 1 if end1 is None else int(end1)
    blend = s.blend_duration if s.blend_duration is not None else min(a1.terminal_duration, a2.initial_duration)
    nb = max(2, min(int(round(blend * a1.fps)) + 1, end1 + 1, a2.frame_count - 1))
    if mode == "blend":
        why = blend_rejection(a1, end1, a2, nb - 1)
        if why:
            raise TransitionRejected(why)
        out = _blend(a1, end1, a2, nb, s)
    elif mode == "connect":
        why = connect_rejection(a1, end1, a2)
        if why:
            raise TransitionRejected(why)
        out = _connect(a1, end1, a2, s, base)
    else:
        ni = s.inertialization_duration if s.inertialization_duration is not None else blend
        out = _inertialize(a1, end1, a2, max(2, int(round(ni * a1.fps)) + 1), s)
    return out


# a joined motion may turn a joint this much faster than the faster of its two inputs (blending
# two motions adds their speeds for a moment, an interruption turns a joint the inputs hold
# still) before it is a pop, and a held foot may drift this far
STEP_RATIO, STEP_SLACK_DEG, HELD_DRIFT = 1.5, 6.0, 0.01


def continuity_rejection(a1, end1, a2, out, mode):
    """Why the joined motion is not acceptable, or None: in the transition's window no joint turns
    more in one frame than STEP_RATIO times its own fastest step in either input plus
    STEP_SLACK_DEG, and no held foot drifts more than HELD_DRIFT (m) from where it was planted. The
    Motion Queue (Synthesizer.queue) refuses a request whose result pops or slides instead of
    reporting it accepted; reactions (reactions.py) join their own falls and steps unchecked."""
    sk = a1.skeleton

    def steps(rot):
        return np.degrees(rotations.angle_between(rot[1:], rot[:-1])) if len(rot) > 1 else np.zeros((0, len(sk.names)))

    own = np.maximum(steps(a1.trajectories.rotations[:end1 + 1]).max(axis=0, initial=0.0),
                     steps(a2.trajectories.rotations).max(axis=0, initial=0.0))
    w0, w1 = out.window
    window = steps(out.trajectories.rotations)[max(w0 - 1, 0):w1 + 1]
    if len(window):
        excess = window - (STEP_RATIO * own + STEP_SLACK_DEG)
        f, j = np.unravel_index(np.argmax(excess), excess.shape)
        if excess[f, j] > 0.0:
            frame = out.trajectories.frames[max(w0 - 1, 0) + f + 1]
            return (f"{mode} refused: {sk.names[j]} would turn {window[f, j]:.0f} deg in one frame at frame "
                    f"{frame:g} (the actions' own fastest: {own[j]:.0f} deg)")
    if out.held:
        world = out.trajectories.world_frames(sk)
        for side, held in out.held.items():
            foot = sk.role_index(f"foot.{side}")
            for on, a, b in runs(held):
                if not on or foot is None:
                    continue
                drift = np.linalg.norm(world[a:b, foot, :2, 3] - world[a, foot, :2, 3], axis=1).max()
                if drift > HELD_DRIFT:
                    return (f"{mode} refused: the planted {'left' if side == 'L' else 'right'} foot would slide "
                            f"{1000 * drift:.0f} mm from frame {out.trajectories.frames[a]:g}")
    return None


class _Pose:
    """Editable joined motion: local rotations and translations and the root's world pose."""

    def __init__(self, sk, frames, fps, armature_to_world):
        self.sk, self.fps, self.a2w = sk, fps, armature_to_world
        n, j = len(frames), sk.joint_count
        self.frames = np.asarray(frames, float)
        self.rot = np.zeros((n, j, 4))
        self.trans = np.zeros((n, j, 3))
        self.pos = np.zeros((n, 3))
        self.ori = np.zeros((n, 4))

    def put(self, dst, tr, src):
        p, q = tr.root_pose(self.sk)
        self.rot[dst], self.trans[dst] = tr.rotations[src], tr.translations[src]
        self.pos[dst], self.ori[dst] = p[src], q[src]

    def trajectories(self):
        tr = Trajectories(self.frames, self.fps, rotations.make_continuous(self.rot), self.trans, self.a2w)
        return tr.with_root_pose(self.sk, self.pos, rotations.make_continuous(self.ori))


def _align(a1, end1, a2, start2, base=None, fit="headings"):
    """a2's trajectories moved on the floor plan onto a1 at the join (feet that support in both,
    or only `base`; the root when none). Two feet are fitted by their headings and mean place, or
    with fit="line" by the line between them (which foot of a connection steps is chosen so)."""
    sk = a1.skeleton
    w1 = a1.trajectories.world_frames(sk)[end1]
    w2 = a2.trajectories.world_frames(sk)[start2]
    feet = [base] if base else [k for k in LEGS if k in a1.constraints and a1.constraints[k][end1] == SUPPORT
                                and a2.constraints.get(k, [ANGULAR])[start2] == SUPPORT]
    if len(feet) == 2 and fit == "line":
        idx = [sk.role_index(k) for k in feet]
        yaw, shift = rigid_2d(w2[idx][:, :2, 3], w1[idx][:, :2, 3])
    elif feet:
        # the feet's headings set the turn (their mean, on the circle) and their places the shift:
        # fitting the line between two feet instead turned a2 by 60-75 deg where its feet stand
        # staggered and a1's side by side, and the held feet's ankles twisted 18 deg a frame
        idx = [sk.role_index(k) for k in feet]
        turns = [float(yaw_of(decompose(w1[j])[1]) - yaw_of(decompose(w2[j])[1])) for j in idx]
        yaw = float(np.arctan2(np.mean(np.sin(turns)), np.mean(np.cos(turns))))
        c, s_ = np.cos(yaw), np.sin(yaw)
        shift = np.mean([w1[j][:2, 3] - np.array([[c, -s_], [s_, c]]) @ w2[j][:2, 3] for j in idx], axis=0)
    else:
        r = sk.root
        yaw = float(yaw_of(decompose(w1[r])[1]) - yaw_of(decompose(w2[r])[1]))
        c, s_ = np.cos(yaw), np.sin(yaw)
        shift = w1[r][:2, 3] - np.array([[c, -s_], [s_, c]]) @ w2[r][:2, 3]
    return transformed(sk, a2.trajectories, yaw, (shift[0], shift[1], 0.0))


def _support_mask(a, side_limb, a_range):
    return a.constraints[side_limb][a_range] == SUPPORT if side_limb in a.constraints else np.zeros(len(a_range), bool)


def _blend(a1, end1, a2, nb, s):
    sk, fps = a1.skeleton, a1.fps
    start = end1 + 1 - nb  # output frame where a2 begins
    t2 = _align(a1, start, a2, 0)  # a2's first frame meets a1 where the window opens
    n = start + a2.frame_count
    out = _Pose(sk, a1.trajectories.frames[0] + np.arange(n), fps, a1.trajectories.armature_to_world)
    out.put(np.arange(start), a1.trajectories, np.arange(start))
    out.put(np.arange(start, n), t2, np.arange(a2.frame_count))
    w = smootherstep(np.arange(nb) / (nb - 1))
    win = np.arange(start, start + nb)
    p1, q1 = a1.trajectories.root_pose(sk)
    rot1, tr1 = a1.trajectories.rotations[win], a1.trajectories.translations[win]
    out.rot[win] = slerp(rot1, out.rot[win], w[:, None, None])
    out.trans[win] = (1 - w[:, None, None]) * tr1 + w[:, None, None] * out.trans[win]
    out.pos[win] = (1 - w[:, None]) * p1[win] + w[:, None] * out.pos[win]
    out.ori[win] = slerp(q1[win], out.ori[win], w[:, None])
    raw = out.trajectories()
    # spatial limbs: blend the end effector's world frame, then the limb's IK
    targets = {}
    e1 = a1.end_effectors()
    e2 = t2.world_frames(sk)
    for limb in a1.limbs():
        c1, c2 = a1.constraints[limb][win], a2.constraints[limb][:nb]
        sel = (c1 == SPATIAL) & (c2 == SPATIAL)
        if sel.any():
            tgt = np.full((n, 4, 4), np.nan)
            j = sk.role_index(limb)
            tgt[win[sel]] = blend_frames(e1[limb][win[sel]], e2[np.arange(nb)[sel], j], w[sel])
            targets[limb] = tgt
    held = _hold_supporting_feet(a1, end1, a2, start, n, raw, targets, s, first_hold=start, join2=nb - 1)
    tr = _solve_limbs(sk, out, raw, targets)
    support = _joined_support(a1, a2, start, n, held)
    return Transition("blend", tr, support, (start, end1), start, held,
                      {"blend_frames": nb})


def _hold_supporting_feet(a1, end1, a2, start, n, raw, targets, s, first_hold, join2, only=None):
    """Fill `targets` for the legs that support the body at the join (a1's frame end1, a2's frame
    join2 at output frame start + join2): held at a1's planted pose from max(first_hold, the frame
    it landed) until a2 lifts it, then blended into a2's own trajectory over the release duration
    (and before a2 lands it again). Returns side -> held mask."""
    sk, fps = a1.skeleton, a1.fps
    w_raw = raw.world_frames(sk)
    w1 = a1.trajectories.world_frames(sk)
    rel = s.release_duration if s.release_duration is not None else \
        (s.blend_duration if s.blend_duration is not None else min(a1.terminal_duration, a2.initial_duration))
    held = {}
    for limb in (only or LEGS):
        if limb not in a1.constraints or a1.constraints[limb][end1] != SUPPORT:
            continue
        c2 = _support_mask(a2, limb, np.arange(a2.frame_count))
        if not c2[join2]:
            continue
        side, j = LIMBS[limb][0], sk.role_index(limb)
        landed = [r for r in runs(a1.constraints[limb][:end1 + 1] == SUPPORT) if r[0]][-1][1]
        h0 = max(first_hold, landed)
        lift2 = next(r[2] for r in runs(c2) if r[0] and r[1] <= join2 < r[2])
        h1 = min(start + lift2 - 1, n - 1)
        anchor = w1[h0, j]
        tgt = targets.setdefault(limb, np.full((n, 4, 4), np.nan))
        tgt[h0:h1 + 1] = anchor
        toe = sk.role_index(f"toe.{side}")
        toes = targets.setdefault("toes", {})
        if toe is not None:  # the toe bends with the source: held too, so the whole sole stays put
            trot = toes.setdefault(toe, np.full((n, 5), np.nan))  # quaternion, weight of the raw pose
            trot[h0:h1 + 1, :4] = a1.trajectories.rotations[h0, toe]
            trot[h0:h1 + 1, 4] = 0.0
        mask = np.zeros(n, bool)
        mask[h0:h1 + 1] = True
        held[side] = mask
        if h1 < n - 1:  # release: onto a2's own foot before its next landing
            nxt = [r[1] for r in runs(c2) if r[0] and start + r[1] > h1]
            land = start + nxt[0] if nxt else n
            m = max(1, min(int(round(rel * fps)), land - h1 - 1))
            fr = np.arange(h1 + 1, min(h1 + 1 + m, n))
            if len(fr):
                u = smootherstep((fr - h1) / (m + 1))
                tgt[fr] = blend_frames(np.broadcast_to(anchor, (len(fr), 4, 4)), w_raw[fr, j], u)
                if toe is not None:
                    trot[fr, :4] = a1.trajectories.rotations[h0, toe]
                    trot[fr, 4] = u
    return held


def _solve_limbs(sk, out, raw, targets):
    """Rotations of each limb with a target frame (NaN where none) by the analytic limb IK,
    keeping the raw motion's swivel.

    A target beyond the limb's reach is brought within it, short of straight by NEAR_STRAIGHT."""
    if not targets:
        return raw
    basis, world = raw.basis(), raw.world_frames(sk)
    rot = raw.rotations.copy()
    for toe, trot in targets.get("toes", {}).items():
        sel = np.isfinite(trot[:, 0])
        rot[sel, toe] = slerp(trot[sel, :4], rot[sel, toe], trot[sel, 4:5])
    for limb, tgt in targets.items():
        if limb == "toes":
            continue
        side, kind = LIMBS[limb]
        ik = LimbIK(sk, side, kind, basis=basis[0], hinge=_bend_axis(sk, side, kind, world, basis[0]))
        reach = np.linalg.norm(ik.ankle_in_upper(ik.knee_angle(np.inf)[0] + NEAR_STRAIGHT))
        for f in np.flatnonzero(np.isfinite(tgt[:, 0, 0])):
            parent = ik.parent_frame(world[f])
            q, _, _ = ik.solve(parent, _within(tgt[f], ik.upper_zero(parent)[:3, 3], reach), ik.swivel(world[f]))
            rot[f, [ik.upper, ik.lower, ik.end]] = q
    return Trajectories(raw.frames, raw.fps, rotations.make_continuous(rot), raw.translations,
                        raw.armature_to_world)


# the straightest a limb is solved: at dead straight the IK's bend plane comes from the knee's
# offset along the hinge (a captured knee is no perfect hinge; Bandai Namco's legs) and the thigh
# turned 90 deg about itself between a frame it reached and one it did not
NEAR_STRAIGHT = np.radians(1.0)


def _within(target, hip, reach):
    """The target frame moved along the line from the hip to within `reach` of it."""
    d = target[:3, 3] - hip
    r = np.linalg.norm(d)
    if r <= reach:
        return target
    out = np.array(target, float)
    out[:3, 3] = hip + d * (reach / r)
    return out


def _bend_axis(sk, side, kind, world, basis):
    """The axis (lower bone frame) the motion bends the knee (elbow) about, taken where it bends
    most; a rig whose rest pose is straight (CMU's BVH bones) has no other reliable hinge, and a
    wrong hinge makes the IK's ankle turn to make up for it (a joint-angle jump at the join)."""
    from ..motion_control.limb_ik import LIMBS as CHAIN
    up, lo = (sk.role_index(f"{r}.{side}") for r in CHAIN[kind][:2])
    ik = LimbIK(sk, side, kind, basis=basis)
    rel = np.linalg.solve(world[:, up] @ ik.upper_chain, world[:, lo])[:, :3, :3]
    vec = spatial.quat_log(rotations.from_matrix(rel))
    f = int(np.argmax(np.linalg.norm(vec, axis=-1)))
    if np.linalg.norm(vec[f]) < np.radians(15.0):
        return None
    return vec[f] / np.linalg.norm(vec[f])


def _joined_support(a1, a2, start, n, held, extra=None):
    out = {}
    for limb in LEGS:
        side = LIMBS[limb][0]
        m = np.zeros(n, bool)
        if limb in a1.constraints:
            k1 = min(start, a1.frame_count)
            m[:k1] = a1.constraints[limb][:k1] == SUPPORT
        if limb in a2.constraints:
            k = min(a2.frame_count, n - start)
            m[start:start + k] = a2.constraints[limb][:k] == SUPPORT
        if extra is not None and side in extra:
            m = np.where(extra[side][0], extra[side][1], m)
        if side in held:
            m |= held[side]
        out[side] = m
    return out


# ---- inertialization ---------------------------------------------------------------------------

def decay(x0, v0, duration):
    """Offsets (T, ...) decaying from x0 with velocity v0 to rest in `duration` seconds with a
    quintic (zero velocity and acceleration at the end; Bollo 2016), sampled at times (T,)."""
    def curve(t):
        x0_, v0_ = np.asarray(x0, float), np.asarray(v0, float)
        v0c = np.where(x0_ * v0_ > 0, 0.0, v0_)  # moving away from zero: do not overshoot
        with np.errstate(divide="ignore", invalid="ignore"):
            lim = np.where(np.abs(v0c) > 1e-12, -5.0 * x0_ / v0c, np.inf)
        T = np.clip(np.where(lim > 0, np.minimum(duration, lim), duration), 1e-6, None)
        a0 = (-8.0 * v0c * T - 20.0 * x0_) / T ** 2
        A = -(a0 * T ** 2 + 6.0 * v0c * T + 12.0 * x0_) / (2.0 * T ** 5)
        B = (3.0 * a0 * T ** 2 + 16.0 * v0c * T + 30.0 * x0_) / (2.0 * T ** 4)
        C = -(3.0 * a0 * T ** 2 + 12.0 * v0c * T + 20.0 * x0_) / (2.0 * T ** 3)
        tt = np.minimum(t, T)
        x = A * tt ** 5 + B * tt ** 4 + C * tt ** 3 + 0.5 * a0 * tt ** 2 + v0c * tt + x0_
        return np.where(t < T, x, 0.0)
    return curve


def _inertialize(a1, end1, a2, ni, s):
    sk, fps = a1.skeleton, a1.fps
    t2 = _align(a1, end1, a2, 0)
    start = end1 + 1
    n = start + a2.frame_count
    dur = (ni - 1) / fps
    out = _Pose(sk, a1.trajectories.frames[0] + np.arange(n), fps, a1.trajectories.armature_to_world)
    out.put(np.arange(start), a1.trajectories, np.arange(start))
    out.put(np.arange(start, n), t2, np.arange(a2.frame_count))
    k = np.arange(a2.frame_count) / fps
    i0, im = end1, max(end1 - 1, 0)
    p1, q1 = a1.trajectories.root_pose(sk)
    p2, q2 = t2.root_pose(sk)
    r1, r2 = a1.trajectories.rotations, t2.rotations
    # local rotations: q(t) = q2(t) exp(x(t)), x from the extrapolated outgoing pose
    w1 = spatial.quat_log(rotations.multiply(rotations.conjugate(r1[im]), r1[i0]))
    w2 = spatial.quat_log(rotations.multiply(rotations.conjugate(r2[0]), r2[1]))
    nxt = rotations.multiply(r1[i0], spatial.quat_exp(w1))
    x0 = spatial.quat_log(rotations.multiply(rotations.conjugate(r2[0]), nxt))
    off = decay(x0, (w1 - w2) * fps, dur)(k[:, None, None])
    sel = np.arange(start, n)
    out.rot[sel] = rotations.multiply(r2, spatial.quat_exp(off))
    tl1, tl2 = a1.trajectories.translations, t2.translations
    x0 = tl1[i0] + (tl1[i0] - tl1[im]) - tl2[0]
    out.trans[sel] = tl2 + decay(x0, ((tl1[i0] - tl1[im]) - (tl2[1] - tl2[0])) * fps, dur)(k[:, None, None])
    x0 = p1[i0] + (p1[i0] - p1[im]) - p2[0]
    out.pos[sel] = p2 + decay(x0, ((p1[i0] - p1[im]) - (p2[1] - p2[0])) * fps, dur)(k[:, None])
    w1 = spatial.quat_log(rotations.multiply(q1[i0], rotations.conjugate(q1[im])))
    w2 = spatial.quat_log(rotations.multiply(q2[1], rotations.conjugate(q2[0])))
    nxt = rotations.multiply(spatial.quat_exp(w1), q1[i0])
    x0 = spatial.quat_log(rotations.multiply(nxt, rotations.conjugate(q2[0])))
    out.ori[sel] = rotations.multiply(spatial.quat_exp(decay(x0, (w1 - w2) * fps, dur)(k[:, None])), q2)
    raw = out.trajectories()
    targets = {}
    held = _hold_supporting_feet(a1, end1, a2, start, n, raw, targets, s, first_hold=max(0, start - 1), join2=0)
    tr = _solve_limbs(sk, out, raw, targets)
    support = _joined_support(a1, a2, start, n, held)
    return Transition("inertialize", tr, support, (start, min(start + ni - 1, n - 1)), start, held,
                      {"inertialization_frames": ni})


# ---- connection (sec. 3.4.3) -------------------------------------------------------------------

def _hermite(times, values, slopes, t):
    return CubicHermiteSpline(times, values, slopes, axis=0)(t)


def _peak_speed(x, fps):
    return float(np.linalg.norm(np.diff(x, axis=0), axis=-1).max() * fps) if len(x) > 1 else 0.0


def _connect(a1, end1, a2, s, base=None):
    sk, fps = a1.skeleton, a1.fps
    shared = [k for k in LEGS if a1.constraints[k][end1] == SUPPORT and a2.constraints[k][0] == SUPPORT]
    if base is not None:
        if base not in shared:
            raise TransitionRejected(f"connect rejected: {base} does not support the body at the join")
        shared = [base]
    w1all = a1.trajectories.world_frames(sk)
    w1 = w1all[end1]
    if len(shared) == 2:  # base: the foot the next action has closest to where it is now
        t2 = _align(a1, end1, a2, 0, fit="line")
        w2 = t2.world_frames(sk)[0]
        d = [np.linalg.norm(w1[sk.role_index(k)][:2, 3] - w2[sk.role_index(k)][:2, 3]) for k in shared]
        base = shared[int(np.argmin(d))]
    else:
        base = shared[0]
    fly = [k for k in LEGS if k != base][0]
    t2 = _align(a1, end1, a2, 0, base=base)
    w2all = t2.world_frames(sk)
    w2 = w2all[0]
    jb, jf = sk.role_index(base), sk.role_index(fly)
    p1, q1 = a1.trajectories.root_pose(sk)
    p2, q2 = t2.root_pose(sk)
    r0, r3 = p1[end1], p2[0]
    f0, f3 = w1[jf][:3, 3], w2[jf][:3, 3]
    # keyframe 1: the root over the base foot's sole, at the point closest to the flying foot
    heel, toe = w1[jb][:3, 3], _toe_tip(sk, w1, base)
    r1 = r0.copy()
    r1[:2] = _closest_on_segment(heel[:2], toe[:2], f0[:2])
    r1[:2] += _clip_norm(f0[:2] - r1[:2], 0.03)  # inside the sole, towards the flying foot
    # keyframe 2: the flying foot half way, lifted
    fly_moves = np.linalg.norm(f3 - f0) > 0.01
    f2 = 0.5 * (f0 + f3) + np.array([0.0, 0.0, s.lift_height if fly_moves else 0.0])
    # eq. 3.5: no speed above the larger of the outgoing speed, the next action's peak and C
    v_root = max(np.linalg.norm(p1[end1] - p1[max(end1 - 1, 0)]) * fps, _peak_speed(p2, fps), s.spatial_speed)
    v_foot = max(np.linalg.norm(w1all[end1, jf, :3, 3] - w1all[max(end1 - 1, 0), jf, :3, 3]) * fps,
                 _peak_speed(w2all[:, jf, :3, 3], fps), s.spatial_speed)
    phases = np.array([1.5 * np.linalg.norm(r1 - r0) / v_root,
                       1.5 * np.linalg.norm(f2 - f0) / v_foot,
                       1.5 * max(np.linalg.norm(f3 - f2) / v_foot, np.linalg.norm(r3 - r1) / v_root)])
    a_max = max(s.spatial_acceleration, float(np.percentile(
        np.linalg.norm(np.diff(p2, 2, axis=0), axis=-1), 99)) * fps * fps if len(p2) > 2 else 0.0)
    dist = np.array([np.linalg.norm(r1 - r0), np.linalg.norm(f2 - f0),
                     max(np.linalg.norm(f3 - f2), np.linalg.norm(r3 - r1))])
    phases = np.maximum(phases, np.sqrt(6.0 * dist / a_max))  # a cubic's peak: 6 d / T^2
    phases = np.maximum(phases, s.min_phase)
    rot1, rot2 = a1.trajectories.rotations, t2.rotations
    d_ang = np.linalg.norm(spatial.quat_log(rotations.multiply(rotations.conjugate(rot1[end1]), rot2[0])), axis=-1)
    om1 = np.linalg.norm(spatial.quat_log(rotations.multiply(rotations.conjugate(rot1[max(end1 - 1, 0)]),
                                                             rot1[end1])), axis=-1) * fps
    om2 = np.linalg.norm(spatial.quat_log(rotations.multiply(rotations.conjugate(rot2[:-1]), rot2[1:])),
                         axis=-1).max(axis=0) * fps
    t_joint = float((1.5 * d_ang / np.maximum(np.maximum(om1, om2), s.angular_speed)).max())
    if t_joint > phases.sum():
        phases *= t_joint / phases.sum()
    total = float(phases.sum())
    nc = max(2, int(np.ceil(total * fps)))
    phases *= (nc / fps) / total
    total = nc / fps
    times = np.concatenate(([0.0], np.cumsum(phases)))
    start = end1 + nc  # output index of a2's first frame
    n = start + a2.frame_count
    out = _Pose(sk, a1.trajectories.frames[0] + np.arange(n), fps, a1.trajectories.armature_to_world)
    out.put(np.arange(end1 + 1), a1.trajectories, np.arange(end1 + 1))
    out.put(np.arange(start, n), t2, np.arange(a2.frame_count))
    tk = np.arange(1, nc) / fps
    mid = np.arange(end1 + 1, start)
    im = max(end1 - 1, 0)
    # joints and root orientation: Hermite on the rotation vector from the outgoing pose, with the
    # outgoing and incoming angular velocities at the ends
    d = spatial.quat_log(rotations.multiply(rotations.conjugate(rot1[end1]), rot2[0]))
    v0 = spatial.quat_log(rotations.multiply(rotations.conjugate(rot1[im]), rot1[end1])) * fps
    v3 = spatial.quat_log(rotations.multiply(rotations.conjugate(rot2[0]), rot2[1])) * fps
    x = _hermite([0.0, total], np.stack((np.zeros_like(d), d)), np.stack((v0, v3)), tk)
    out.rot[mid] = rotations.multiply(rot1[end1], spatial.quat_exp(x))
    tl1, tl2 = a1.trajectories.translations, t2.translations
    out.trans[mid] = _hermite([0.0, total], np.stack((tl1[end1], tl2[0])),
                              np.stack(((tl1[end1] - tl1[im]) * fps, (tl2[1] - tl2[0]) * fps)), tk)
    d = spatial.quat_log(rotations.multiply(rotations.conjugate(q1[end1]), q2[0]))
    v0 = spatial.quat_log(rotations.multiply(rotations.conjugate(q1[im]), q1[end1])) * fps
    v3 = spatial.quat_log(rotations.multiply(rotations.conjugate(q2[0]), q2[1])) * fps
    x = _hermite([0.0, total], np.stack((np.zeros(3), d)), np.stack((v0, v3)), tk)
    out.ori[mid] = rotations.multiply(q1[end1], spatial.quat_exp(x))
    # root through keyframes 0 (outgoing velocity), 1 and 2 (at rest over the base foot), 3
    out.pos[mid] = _hermite(times, np.stack((r0, r1, r1, r3)),
                            np.stack(((p1[end1] - p1[im]) * fps, np.zeros(3), np.zeros(3), (p2[1] - p2[0]) * fps)), tk)
    raw = out.trajectories()
    targets = {}
    # flying foot: planted until keyframe 1, through the lifted keyframe 2 onto the next action's foot
    ff = np.full((n, 4, 4), np.nan)
    fpos = _hermite(times, np.stack((f0, f0, f2, f3)), np.zeros((4, 3)), tk)
    _, fq0 = decompose(w1[jf])
    _, fq3 = decompose(w2[jf])
    u = smootherstep((tk - times[1]) / (times[3] - times[1]))
    ff[mid] = compose(fpos, slerp(np.broadcast_to(fq0, (len(tk), 4)), np.broadcast_to(fq3, (len(tk), 4)), u[:, None]))
    planted = mid[tk <= times[1]]
    ff[planted] = w1[jf]
    targets[fly] = ff
    toe = sk.role_index(f"toe.{LIMBS[fly][0]}")
    if toe is not None:  # the planted flying foot's toe keeps its angle until the foot leaves
        trot = targets.setdefault("toes", {}).setdefault(toe, np.full((n, 5), np.nan))
        trot[planted, :4] = rot1[end1, toe]
        trot[planted, 4] = 0.0
        lift = (tk > times[1]) & (tk <= times[2])  # and rejoins the interpolation as the foot lifts
        trot[mid[lift], :4] = rot1[end1, toe]
        trot[mid[lift], 4] = smootherstep((tk[lift] - times[1]) / (times[2] - times[1]))
    held = _hold_supporting_feet(a1, end1, a2, start, n, raw, targets, s, first_hold=end1, join2=0, only=[base])
    fly_side = LIMBS[fly][0]
    fly_on = np.zeros(n, bool)
    fly_on[mid[tk <= times[1]]] = True
    fly_sel = np.zeros(n, bool)
    fly_sel[mid] = True
    tr = _solve_limbs(sk, out, raw, targets)
    support = _joined_support(a1, a2, start, n, held, extra={fly_side: (fly_sel, fly_on)})
    support[fly_side][end1] = bool(a1.constraints[fly][end1] == SUPPORT)
    return Transition("connect", tr, support, (end1, start), start, held,
                      {"connect_frames": nc, "base": base, "flying": fly, "keyframe_times": times.tolist()})


def _toe_tip(sk, world, foot_limb):
    side = LIMBS[foot_limb][0]
    toe = sk.role_index(f"toe.{side}")
    j = toe if toe is not None else sk.role_index(foot_limb)
    return world[j][:3, 3] + world[j][:3, 1] * sk.lengths[j]


def _closest_on_segment(a, b, p):
    ab = b - a
    u = np.clip((p - a) @ ab / max(ab @ ab, 1e-12), 0.0, 1.0)
    return a + u * ab


def _clip_norm(v, r):
    n = np.linalg.norm(v)
    return v if n <= r else v * (r / n)
