"""Dynamic reactions (Oshita 2003, sec. 3.5) on top of the dynamic controller: after control, the
root's motion is checked frame by frame and, at the first frame a condition holds, the rest of the
motion is replaced by a generated reaction, joined to the controlled motion at that frame:

  * protective step (eq. 3.6): 0.5 < |v| < 1.0 m/s and |a| > 10 m/s^2 with both feet planted; the
    flying foot is the one nearer the ZMP, the terminal root p_root_term = k_root v + p_root_init
    (eq. 3.7) and flying foot p_fly = k_foot (p_root_term - p_base) + p_root_term (eq. 3.8); the
    step is generated as a connective action (sec. 3.4.3) into that stance;
  * fall (eq. 3.9): |v| > 1.0 m/s and |a| > 10 m/s^2 (or the controller's own falling criterion);
    backwards onto the hips and hands or forwards onto the knees and hands, with the animator's
    fall actions when given, else generated ones; no bone goes below the ground;
  * recovery (sec. 3.5.3): a joint stays farther than `recovery_angle` from its target for longer
    than `recovery_time`; a connective action back to the action's initial (stable) posture.

v and a are the root's velocity and acceleration minus those of the target motion at that frame
(what the interaction added), so a walking or running action does not count as a push.
"""

from dataclasses import dataclass, field, replace

import numpy as np
from scipy.interpolate import CubicHermiteSpline

from .. import rotations
from ..dynamics import spatial
from ..motion_control import ControlSettings, control
from ..motion_control.limb_ik import LimbIK
from ..trajectories import Trajectories
from .action import ANGULAR, SUPPORT, Action
from .keyframed import forward_of
from .transitions import LEGS, TransitionRejected, TransitionSettings, transition

KINDS = ("none", "step", "fall", "recovery")


@dataclass
class ReactionSettings:
    step_speed: tuple = (0.5, 1.0)  # m/s, eq. 3.6
    step_acceleration: float = 10.0  # m/s^2, eq. 3.6
    fall_speed: float = 1.0  # m/s, eq. 3.9
    fall_acceleration: float = 10.0  # m/s^2, eq. 3.9
    k_root: float = 0.4  # s, eq. 3.7
    k_foot: float = 1.0  # eq. 3.8 (1: the root half way between the feet)
    step_crouch: float = 0.04  # m the root of the step's terminal posture is lowered (bent knees)
    recovery_time: float = 0.5  # s, T_recovery
    recovery_angle: float = 0.5  # rad a joint may stay off its target before it counts
    fall_duration: float = 0.8  # s of a generated fall
    hold: float = 0.5  # s the terminal posture of a reaction is held at least
    # the reaction is the controller's new input from its first frame (False: spliced as generated)
    retrack: bool = True
    # the generated step and recovery: a protective step is quick (its speed bounds, eq. 3.5, start
    # from the push's own speed; these constants are the floor under them)
    transition: TransitionSettings = field(default_factory=lambda: TransitionSettings(
        angular_speed=4.0, spatial_speed=1.0, spatial_acceleration=8.0, lift_height=0.06, min_phase=0.08))


@dataclass
class ReactionResult:
    kind: str  # "none", "step", "fall" or "recovery"
    frame: int  # output frame index the reaction starts at (-1 for none)
    trajectories: Trajectories
    control: object  # the ControlResult before the reaction
    root_speed: np.ndarray  # (F,) m/s, added by the interaction
    root_acceleration: np.ndarray  # (F,) m/s^2
    support: dict = field(default_factory=dict)
    info: dict = field(default_factory=dict)
    target: object = None  # Trajectories: the generated reaction the controller tracked (None: none)
    reaction_control: object = None  # the ControlResult that tracked it (None: not re-tracked)


RATE_STEP = 1.0 / 30.0  # s: the thesis's frame time; rates over it make eq. 3.6's thresholds fps-free


def root_rates(skeleton, out, target, skate=None):
    """Root velocity (F, 3) and acceleration magnitude (F,) of `out` relative to `target` (moved by
    the controller's foot-skate offset `skate` (F, 2) when given), as backward differences over
    RATE_STEP (a push shows at the frame it acts; capture noise at 120 fps is not differentiated
    twice over 8 ms)."""
    fps = out.fps
    p = out.root_pose(skeleton)[0] - target.root_pose(skeleton)[0]
    if skate is not None:
        p[:, :2] -= skate
    k = max(1, int(round(RATE_STEP * fps)))
    h = k / fps
    v = np.zeros_like(p)
    v[k:] = (p[k:] - p[:-k]) / h
    a = np.zeros(len(p))
    a[k:] = np.linalg.norm(v[k:] - v[:-k], axis=-1) / h
    return v, a


def detect(skeleton, action, result, settings):
    """(kind, frame, root velocity (F, 3), root acceleration (F,)) of the first reaction the
    controlled motion calls for, with the root rates it was decided on (root_rates)."""
    s = settings
    out = result.trajectories
    v, a = root_rates(skeleton, out, action.trajectories, result.foot_skate)
    speed = np.linalg.norm(v, axis=-1)
    both = result.support.all(axis=1)
    falls = (speed > s.fall_speed) & (a > s.fall_acceleration)
    steps = (speed > s.step_speed[0]) & (speed < s.step_speed[1]) & (a > s.step_acceleration) & both
    # the reaction counts from the frame a push has shown in both speed and acceleration; a push
    # builds speed over a frame or two, so the decision looks one frame ahead for the larger class
    nf = len(speed)
    for f in range(1, nf):
        if falls[f] or (f + 1 < nf and falls[f + 1] and a[f] > s.fall_acceleration):
            return "fall", f, v, a
        if steps[f]:
            return "step", f, v, a
        if result.falling[f]:
            # the controller's own criterion: balance lost and the capture point beyond the feet,
            # so the body cannot stop without a step. Slower than eq. 3.9's fall speed, that step
            # is the protective step (from the frame balance was first lost); faster, it falls
            f0 = f
            while f0 > 1 and result.balance_error[f0 - 1] > 0.0 and not result.falling[f0 - 1]:
                f0 -= 1
            if speed[f] < s.fall_speed and both[f0]:
                return "step", f0, v, a
            return "fall", f0, v, a
    err = _tracking_error(out, action.trajectories, skeleton)
    run = int(round(s.recovery_time * out.fps))
    over = err > s.recovery_angle
    count = 0
    for f in range(nf):
        count = count + 1 if over[f] else 0
        if count > run:
            return "recovery", f, v, a
    return "none", -1, v, a


def _tracking_error(out, target, skeleton):
    """Per frame the largest angle (rad) between a massive joint's output and target rotation."""
    heavy = skeleton.mass > 0.002 * skeleton.total_mass
    return rotations.angle_between(out.rotations[:, heavy], target.rotations[:, heavy]).max(axis=1)


def react(action, control_settings=None, settings=None, fall_actions=None):
    """Dynamic control of `action` with the environment in `control_settings` (loads, impulses,
    colliders), then the reaction it calls for, re-tracked by the controller: from the reaction's
    first frame the generated step, fall or recovery is the controller's input (joined to the
    controlled motion like a connective action), and the body follows it with its dynamics, loads
    and contacts from the state the interaction left it in. fall_actions: {"back": Action,
    "forward": Action}."""
    sk = action.skeleton
    s = settings or ReactionSettings()
    cs = control_settings or ControlSettings()
    states = []
    res = control(sk, action.trajectories, cs, on_frame=lambda f, q, v: states.append((q, v)))
    kind, f, v, acc = detect(sk, action, res, s)
    speed = np.linalg.norm(v, axis=-1)
    floor = float(res.ground_height)
    support = {side: res.support[:, i] for i, side in enumerate("LR")}
    if kind == "none":
        return ReactionResult(kind, -1, res.trajectories, res, speed, acc, support)
    current = _as_action(action, res, f)
    n_total = action.frame_count
    if kind == "step":
        tr, sup, info = _protective_step(current, f, v[f], res, s, floor)
    elif kind == "fall":
        tr, sup, info = _fall(current, f, v[f], s, floor, fall_actions)
    else:
        tr, sup, info = _recovery(current, action, f, s)
    tr, sup = _hold_to(tr, sup, max(n_total, tr.frame_count + int(round(s.hold * action.fps))) if kind != "fall"
                       else max(n_total, tr.frame_count))
    info["trigger_speed"] = float(speed[f])
    info["trigger_acceleration"] = float(acc[f])
    target, tracked = tr, None
    info["retracked"] = False
    if s.retrack:
        # a fall is tracked without balance control: balance would hold the hips up over the feet
        tracked = retrack(sk, tr, replace(cs, tracking_only=True) if kind == "fall" else cs, floor, states, f)
        if tracked is not None:
            info["retracked"] = True
            info["fell_while_reacting"] = bool(tracked.falling[f + 1:].any())
            tr = _above_ground(sk, tracked.trajectories, floor, start=f) if kind == "fall" else tracked.trajectories
            sup = {side: tracked.support[:, i] for i, side in enumerate("LR")}
    return ReactionResult(kind, f, tr, res, speed, acc, sup, info, target=target, reaction_control=tracked)


def retrack(sk, target, cs, floor, states, f):
    """The controller following `target` (the reaction joined at frame f) with the body's recorded
    states (q, v) replayed up to frame f + 1: from there the reaction is the controller's input and the
    pushed body's own velocities carry on (the per-frame hook of motion_control.iter_control).
    None when the reaction's model differs from the recorded one (it cannot take its states)."""
    nq = len(states[0][0])

    def replay(frame, q, v):
        if len(q) != nq:
            raise _ModelChanged
        if frame <= f + 1:  # the reaction's frame f and the step out of it (the push acts in it)
            return states[frame]
        return None

    try:
        return control(sk, target, replace(cs, ground_height=floor), on_frame=replay)
    except _ModelChanged:
        return None


class _ModelChanged(Exception):
    pass


def _as_action(action, res, f):
    """The controlled motion up to frame f as an action (support from the controller)."""
    tr = res.trajectories
    cons = {k: v[:f + 1].copy() for k, v in action.constraints.items()}
    for i, limb in enumerate(LEGS):
        if limb in cons:
            cons[limb] = np.where(res.support[:f + 1, i], SUPPORT, ANGULAR).astype(np.int8)
    t = Trajectories(tr.frames[:f + 1], tr.fps, tr.rotations[:f + 1], tr.translations[:f + 1], tr.armature_to_world)
    return Action(action.name + " (controlled)", action.skeleton, t, cons, action.initial_duration, 0.1)


def _still_action(name, sk, pose_tr, seconds, support=("foot.L", "foot.R")):
    n = max(2, int(round(seconds * pose_tr.fps)) + 1)
    tr = Trajectories(np.arange(n, dtype=float) + pose_tr.frames[0], pose_tr.fps,
                      np.repeat(pose_tr.rotations[:1], n, axis=0), np.repeat(pose_tr.translations[:1], n, axis=0),
                      pose_tr.armature_to_world)
    cons = {"root": np.full(n, 1, np.int8)}
    for limb in ("foot.L", "foot.R", "hand.L", "hand.R"):
        if sk.role_index(limb) is not None:
            cons[limb] = np.full(n, SUPPORT if limb in support else ANGULAR, np.int8)
    return Action(name, sk, tr, cons, 0.2, 0.2)


def _frame_tr(tr, f):
    return Trajectories(tr.frames[f:f + 1], tr.fps, tr.rotations[f:f + 1], tr.translations[f:f + 1],
                        tr.armature_to_world)


# ---- protective step (sec. 3.5.1) ---------------------------------------------------------------

def _protective_step(current, f, vel, res, s, floor):
    sk = current.skeleton
    tr = current.trajectories
    world = tr.world_frames(sk)[f]
    zmp = res.zmp[f]
    feet = {k: world[sk.role_index(k)][:3, 3] for k in LEGS}
    if not np.all(np.isfinite(zmp)):
        zmp = tr.root_pose(sk)[0][f][:2]
    fly = min(LEGS, key=lambda k: np.linalg.norm(feet[k][:2] - zmp))  # the foot nearer the ZMP moves
    base = [k for k in LEGS if k != fly][0]
    p_root, q_root = tr.root_pose(sk)
    p0 = p_root[f]
    v = np.array([vel[0], vel[1], 0.0])
    root_term = p0 + s.k_root * v  # eq. 3.7 (horizontal)
    fly_term = s.k_foot * (root_term - feet[base]) + root_term  # eq. 3.8
    fly_term[2] = feet[fly][2]
    root_term[2] = p0[2] - s.step_crouch  # knees kept bent: the controller's legs need slack to absorb the push
    # terminal posture: the current posture with the root and flying foot moved, legs by IK
    for _ in range(40):  # the root lowered (1 cm at a time) until both legs reach their feet
        pose = _frame_tr(tr, f).with_root_pose(sk, root_term[None], q_root[f][None])
        pw = pose.world_frames(sk)[0]
        rot = pose.rotations.copy()
        basis = pose.basis()[0]
        reached = True
        for limb, target_pos in ((base, feet[base]), (fly, fly_term)):
            ik = LimbIK(sk, limb[-1], basis=basis)
            tgt = world[ik.end].copy()
            tgt[:3, 3] = target_pos
            q, _, ok = ik.solve(ik.parent_frame(pw), tgt, ik.swivel(world))
            rot[0, [ik.upper, ik.lower, ik.end]] = q
            reached &= ok
        if reached:
            break
        root_term[2] -= 0.01
    pose = Trajectories(pose.frames, pose.fps, rot, pose.translations, pose.armature_to_world)
    stance = _still_action("protective step stance", sk, pose, s.hold)
    # the step is a connective action with this base foot (the stance is placed where it stands)
    ts = TransitionSettings(**{**s.transition.__dict__})
    try:
        joined = transition(current, stance, "connect", ts, end1=f, base=base)
    except TransitionRejected as e:  # no planted foot to step from: the body falls
        tr2, sup, info = _fall(current, f, vel, s, floor, None)
        info["step_rejected"] = e.reason
        return tr2, sup, info
    info = {"flying": fly, "base": joined.info.get("base"), "root_terminal": root_term.tolist(),
            "flying_terminal": fly_term.tolist(), "step_frames": joined.info.get("connect_frames")}
    return joined.trajectories, joined.support, info


# ---- falling (sec. 3.5.2) -----------------------------------------------------------------------

def _fall(current, f, vel, s, floor, fall_actions):
    sk = current.skeleton
    tr = current.trajectories
    fwd = forward_of(sk, _frame_tr(tr, f))
    direction = "forward" if vel[:2] @ fwd[:2] > 0 else "back"
    if fall_actions and fall_actions.get(direction) is not None:
        fa = fall_actions[direction]
        mode = "inertialize"
        try:
            joined = transition(current, fa, mode, s.transition, end1=f)
        except TransitionRejected:
            joined = transition(current, fa, "inertialize", s.transition, end1=f)
        out = _above_ground(sk, joined.trajectories, floor, start=f)
        return out, joined.support, {"direction": direction, "fall_action": fa.name}
    terminal = fallen_pose(sk, _frame_tr(tr, f), direction, floor)
    n = max(2, int(round(s.fall_duration * tr.fps)))
    out = _interpolate(sk, tr, f, terminal, n)
    out = _above_ground(sk, out, floor, start=f)
    sup = {side: np.concatenate((current.constraints[f"foot.{side}"][:f + 1] == SUPPORT,
                                 np.zeros(out.frame_count - f - 1, bool))) for side in "LR"}
    return out, sup, {"direction": direction, "fall_action": "generated"}


def fallen_pose(sk, pose, direction, floor):
    """A generated terminal pose of a fall from `pose` (one frame): "back" sits on the hips with the
    hands behind, "forward" kneels with the hands in front; every bone kept above the floor."""
    w = pose.world_frames(sk)[0]
    p, q = pose.root_pose(sk)
    p, q = p[0].copy(), q[0]
    fwd = forward_of(sk, pose)
    up = np.array([0.0, 0.0, 1.0])
    lateral = np.cross(up, fwd)
    thigh = sk.role_index("thigh.L")
    shin = sk.role_index("shin.L")
    leg = sk.lengths[thigh] + sk.lengths[shin]
    hip_h = w[thigh][2, 3] - p[2]  # hip below (negative) or above the root
    if direction == "back":
        pitch = -np.radians(40.0)
        root = p - 0.35 * leg * fwd
        root[2] = floor + 0.12 - hip_h
        foot_pos = {side: root + 0.85 * leg * fwd + sign * 0.12 * lateral for side, sign in (("L", 1), ("R", -1))}
        hand_pos = {side: root - 0.25 * fwd + sign * 0.3 * lateral for side, sign in (("L", 1), ("R", -1))}
    else:
        pitch = np.radians(88.0)  # kneeling, thighs nearly upright, the trunk bent over the hands
        root = p + 0.3 * leg * fwd
        root[2] = floor + 0.06 + sk.lengths[thigh] * 0.9 - hip_h
        foot_pos = {side: root - sk.lengths[shin] * fwd + sign * 0.12 * lateral for side, sign in (("L", 1), ("R", -1))}
        hand_pos = {side: root + 0.55 * leg * fwd + sign * 0.25 * lateral for side, sign in (("L", 1), ("R", -1))}
    tilt = spatial.quat_exp(pitch * lateral)
    ori = rotations.multiply(tilt, q)
    pose2 = pose.with_root_pose(sk, root[None], ori[None])
    pw = pose2.world_frames(sk)[0]
    if direction == "forward":  # knees on the ground, hips back over the heels, shins flat behind
        root[2] += floor + 0.05 + 0.6 * sk.lengths[thigh] - pw[thigh][2, 3]
        pose2 = pose.with_root_pose(sk, root[None], ori[None])
        pw = pose2.world_frames(sk)[0]
        for side, sign in (("L", 1), ("R", -1)):
            hip = pw[sk.role_index(f"thigh.{side}")][:3, 3]
            foot_pos[side] = hip + (0.8 * sk.lengths[thigh] - sk.lengths[shin]) * fwd
    basis = pose2.basis()[0]
    rot = pose2.rotations.copy()
    for side in "LR":
        for kind, targets, lift in (("leg", foot_pos, 0.05), ("arm", hand_pos, 0.05)):
            try:
                ik = LimbIK(sk, side, kind, basis=basis)
            except ValueError:
                continue
            tgt = w[ik.end].copy()
            tgt[:3, 3] = targets[side]
            tgt[2, 3] = floor + lift
            if kind == "arm":  # a hand on the ground within reach of the shoulder, towards its target
                sh = pw[ik.upper][:3, 3]
                reach = 0.95 * (sk.lengths[ik.upper] + sk.lengths[ik.lower])
                flat = np.sqrt(max(reach ** 2 - (sh[2] - tgt[2, 3]) ** 2, 0.0))
                off = tgt[:2, 3] - sh[:2]
                tgt[:2, 3] = sh[:2] + off / max(np.linalg.norm(off), 1e-9) * min(flat, np.linalg.norm(off))
                y = np.r_[off / max(np.linalg.norm(off), 1e-9), 0.0]  # fingers flat, pointing away
                x = np.cross(y, up)
                tgt[:3, :3] = np.column_stack((x, y, np.cross(x, y)))
            qq, _, _ = ik.solve(ik.parent_frame(pw), tgt, ik.swivel(w))
            rot[0, [ik.upper, ik.lower, ik.end]] = qq
            pw = sk.world_frames(_with_rot(pose2, rot).basis()[0], pose2.armature_to_world)
    return _with_rot(pose2, rot)


def _with_rot(tr, rot):
    return Trajectories(tr.frames, tr.fps, rot, tr.translations, tr.armature_to_world)


def _interpolate(sk, tr, f, terminal, n):
    """tr up to frame f, then n frames moving to `terminal` (Hermite on rotation vectors and the
    root position, starting with frame f's velocities and ending at rest)."""
    fps = tr.fps
    fm = max(f - 1, 0)
    t = np.arange(1, n + 1) / fps
    T = n / fps
    rot0, rot1 = tr.rotations[f], terminal.rotations[0]
    d = spatial.quat_log(rotations.multiply(rotations.conjugate(rot0), rot1))
    w0 = spatial.quat_log(rotations.multiply(rotations.conjugate(tr.rotations[fm]), rot0)) * fps
    x = CubicHermiteSpline([0, T], np.stack((np.zeros_like(d), d)), np.stack((w0, np.zeros_like(d))), axis=0)(t)
    rot = rotations.multiply(rot0, spatial.quat_exp(x))
    trans = np.repeat(tr.translations[f:f + 1], n, axis=0)
    p, q = tr.root_pose(sk)
    pt, qt = terminal.root_pose(sk)
    pos = CubicHermiteSpline([0, T], np.stack((p[f], pt[0])), np.stack(((p[f] - p[fm]) * fps, np.zeros(3))),
                             axis=0)(t)
    dq = spatial.quat_log(rotations.multiply(rotations.conjugate(q[f]), qt[0]))
    wq = spatial.quat_log(rotations.multiply(rotations.conjugate(q[fm]), q[f])) * fps
    xq = CubicHermiteSpline([0, T], np.stack((np.zeros(3), dq)), np.stack((wq, np.zeros(3))), axis=0)(t)
    ori = rotations.multiply(q[f], spatial.quat_exp(xq))
    new = Trajectories(tr.frames[f] + np.arange(1, n + 1), fps, rot, trans, tr.armature_to_world)
    new = new.with_root_pose(sk, pos, ori)
    return Trajectories(np.concatenate((tr.frames[:f + 1], new.frames)), fps,
                        rotations.make_continuous(np.concatenate((tr.rotations[:f + 1], new.rotations))),
                        np.concatenate((tr.translations[:f + 1], new.translations)), tr.armature_to_world)


def segment_heights(sk, tr):
    """Per frame the lowest bone head or tail (world z, metres)."""
    w = tr.world_frames(sk)
    heads = w[..., :3, 3]
    tails = heads + w[..., :3, 1] * sk.lengths[None, :, None]
    return np.minimum(heads[..., 2], tails[..., 2]).min(axis=1)


def _above_ground(sk, tr, floor, start=0):
    """Lift the root from `start` on wherever a bone would come closer to the floor than the
    lowest bone does while standing at `start` (the sole's thickness: a fall lands on the skin)."""
    low = segment_heights(sk, tr)
    clearance = max(0.0, float(low[start]) - floor)
    depth = np.maximum(floor + clearance - low, 0.0)
    depth[:start] = 0.0
    if not depth.any():
        return tr
    p, q = tr.root_pose(sk)
    p = p.copy()
    p[:, 2] += depth
    return tr.with_root_pose(sk, p, q)


# ---- recovery (sec. 3.5.3) ----------------------------------------------------------------------

def _recovery(current, action, f, s):
    sk = current.skeleton
    stable = _still_action("stable posture", sk, _frame_tr(action.trajectories, 0), s.hold)
    for mode in ("connect", "inertialize"):
        try:
            joined = transition(current, stable, mode, s.transition, end1=f)
            return joined.trajectories, joined.support, {"mode": mode}
        except TransitionRejected:
            continue
    raise TransitionRejected("no transition to the stable posture")


def _hold_to(tr, support, n):
    """Hold the last frame until the motion has n frames."""
    k = n - tr.frame_count
    if k <= 0:
        return tr, support
    last = tr.frames[-1]
    out = Trajectories(np.concatenate((tr.frames, last + np.arange(1, k + 1))), tr.fps,
                       np.concatenate((tr.rotations, np.repeat(tr.rotations[-1:], k, axis=0))),
                       np.concatenate((tr.translations, np.repeat(tr.translations[-1:], k, axis=0))),
                       tr.armature_to_world)
    sup = {side: np.concatenate((m, np.repeat(m[-1:], k))) for side, m in support.items()}
    return out, sup
