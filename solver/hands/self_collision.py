"""Self-collision detection and response (Huang 1996 sec. 4.6, table 4-1).

Detection: sphere sensors at the elbows, hands, knees, ankles and feet, and paired sensors along
the forearms and shins (fig. 4-20), tested against the body's volumes.
Response, per frame (table 4-1):
  (1) test each sensor of the moving arm against the body volumes;
  (2) if one is inside, the response vector v points out of the volume (depth + margin);
  (3)-(4) the secondary task: the sub-chain from the chain's root to the sensor moves the sensor
      by v, dz = J'+ dz' (eq. 4-2);
  (5) dq = J+ dx + (I - J+ J) dz, the main task keeping the hand on its target;
  (6) repeat until no sensor is inside or the step limit.
A sensor on the hand itself cannot be moved in the main task's null space: the hand gets a
temporary goal moved along v instead (the alternative of sec. 4.6.3, after Zhao and Badler), and
its own target again once it is clear.

The legs are corrected the same way (table 4-1 on the chain thigh-shin-foot): the main task keeps
the foot on its goal (the ankle's position and the foot's orientation), the secondary task moves
the knee and shin sensors out of the other leg's thigh and shin and out of the trunk; the ankle
and foot sensors, which cannot move without moving the foot, get temporary goals (sec. 4.6.3).
"""

from dataclasses import dataclass

import numpy as np

from ..body_roles import sided
from ..errors import RigError
from . import ik
from .body import body_sensors, body_volumes, own_volume, sensor_points


@dataclass
class CorrectionReport:
    frames_corrected: int
    max_depth_before: float
    max_depth_after: float
    max_goal_error: float  # hand off its target on the frames where its target is clear of the body
    steps: int
    max_foot_error: float = 0.0  # foot off its goal on the frames where its goal is clear of the body
    leg_frames_corrected: int = 0


def _inside(skeleton, sensors, world, volumes, margin, pts=None):
    """(sensor index, volume, depth, point) of every sensor within `margin` of a volume it is not
    attached to; all sensors against one volume at once."""
    if not sensors:
        return []
    pts = sensor_points(skeleton, sensors, world) if pts is None else pts
    radii = np.array([s.radius for s in sensors])
    out = []
    for v in volumes:
        d = radii - v.distance(pts)
        for i in np.flatnonzero(d > -margin):
            if not own_volume(sensors[i], v):
                out.append((int(i), v, float(d[i]), pts[i]))
    out.sort(key=lambda h: h[0])  # sensor order, as the response sums them
    return out


def _near_frames(skeleton, sensors, worlds, volumes, margin):
    """Per frame of worlds (F, J, 4, 4): is a sensor within `margin` of a volume, and the depth of
    the deepest one inside (0 when none); every frame at once."""
    f = len(worlds)
    if not sensors or not volumes:
        return np.zeros(f, bool), np.zeros(f)
    joints = np.array([x.joint for x in sensors], int)
    local = np.array([[0.0, x.along * skeleton.lengths[x.joint], 0.0] for x in sensors])
    w = worlds[:, joints]
    pts = (w[..., :3, :3] @ local[:, :, None])[..., 0] + w[..., :3, 3]  # (F, S, 3)
    radii = np.array([x.radius for x in sensors])
    depth = np.full((f, len(sensors)), -np.inf)
    for v in volumes:
        own = np.array([own_volume(x, v) for x in sensors], bool)
        depth = np.maximum(depth, np.where(own, -np.inf, radii - v.distance(pts)))
    deepest = depth.max(axis=1)
    return deepest > -margin, np.maximum(deepest, 0.0)


def correct_frame(skeleton, basis, armature_to_world, side, target_pos, target_rot, volumes=None,
                  margin=0.01, max_steps=40, with_spine=False, method="SECONDARY", sensors=None, world=None,
                  _full=False):
    """One frame of table 4-1 for one arm. `method` 'SECONDARY' (default) moves the colliding
    elbow and forearm sensors in the null space; 'GOAL' uses temporary end-effector goals for
    every sensor (sec. 4.6.3). `world` (the basis's world frames) saves computing them.
    Returns (basis, depth before, depth after, steps)."""
    world = skeleton.world_frames(basis, armature_to_world) if world is None else world
    hand = skeleton.role_index(sided("hand", side))
    chain = _arm_chain(skeleton, side, with_spine)
    sensors = [x for x in (sensors if sensors is not None else body_sensors(skeleton, world))
               if x.limb == "arm" and x.chain_side == side and x.joint in chain.joints]
    if volumes is None:
        volumes = [v for v in body_volumes(skeleton, world) if v.name in ("trunk", "head")]
    out = _correct_chain(skeleton, basis, world, armature_to_world, chain, sensors, volumes,
                         lambda x: x.joint == hand, target_pos, target_rot, margin, max_steps, method)
    return out if _full else out[:4]  # _full: also the chain's angles and the wrist (for the motion pass)


def _arm_chain(skeleton, side, with_spine):
    """The arm chain (wrist as the effector), made once per skeleton."""
    cache = skeleton.__dict__.setdefault("_hands_chains", {})
    key = ("arm", side, with_spine)
    if key not in cache:
        cache[key] = ik.Chain.arm(skeleton, side, point=np.zeros(3), with_spine=with_spine)
    return cache[key]


def leg_chain_joints(skeleton, side):
    """Thigh down to the foot, parents first."""
    thigh, foot = skeleton.role_index(sided("thigh", side)), skeleton.role_index(sided("foot", side))
    if thigh is None or foot is None:
        raise RigError(f"the rig has no thigh.{side} or foot.{side} role")
    path, j = [], foot
    while j != thigh:
        if j < 0:
            raise RigError(f"foot.{side} is not below thigh.{side}")
        path.append(j)
        j = skeleton.parents[j]
    return [thigh] + path[::-1]


def leg_chain(skeleton, side):
    cache = skeleton.__dict__.setdefault("_hands_chains", {})
    if ("leg", side) not in cache:
        joints = leg_chain_joints(skeleton, side)
        cache["leg", side] = ik.Chain(skeleton, joints, joints[-1], np.zeros(3))
    return cache["leg", side]


LEG_END_SENSORS = ("ankle", "foot")
LEG_ROUNDS = 3  # on the foot's goal: moved by temporary goals


def correct_leg(skeleton, basis, armature_to_world, side, target_pos, target_rot, volumes=None, margin=0.01,
                max_steps=40, method="SECONDARY", sensors=None):
    """One frame of table 4-1 for one leg: the foot keeps its goal (ankle position `target_pos`,
    foot orientation `target_rot`) while the knee and shin sensors leave the other leg and the
    trunk through the secondary task; the ankle and foot sensors through temporary goals.
    Returns (basis, depth before, depth after, steps)."""
    world = skeleton.world_frames(basis, armature_to_world)
    chain = leg_chain(skeleton, side)
    sensors = [x for x in (sensors if sensors is not None else body_sensors(skeleton, world))
               if x.limb == "leg" and x.chain_side == side and x.joint in chain.joints]
    if volumes is None:
        volumes = [v for v in body_volumes(skeleton, world) if v.name != "head"]
    return _correct_chain(skeleton, basis, world, armature_to_world, chain, sensors, volumes,
                          lambda x: x.name.split(".")[0] in LEG_END_SENSORS, target_pos, target_rot, margin,
                          max_steps, method, sticky_goal=True)[:4]


def _correct_chain(skeleton, basis, world, armature_to_world, chain, sensors, volumes, on_end, target_pos,
                   target_rot, margin, max_steps, method, sticky_goal=False):
    """Table 4-1 on one chain; `on_end(sensor)` tells the sensors that ride on the end effector
    (they get temporary goals, the others the secondary task). The arm's temporary goal is its
    target pushed by the current response; with `sticky_goal` (the legs) it is the effector's
    place pushed out, and it stays there once clear, so a goal inside the body is left for good
    on that frame instead of being sought again."""
    base = ik.chain_base(chain, world)
    eul0 = ik.euler_xyz(basis[chain.joints, :3, :3])
    theta = eul0[chain._k, chain._a]
    # every sensor rides on a bone of the chain: its place from the chain's frames alone
    pos = np.array([chain.joints.index(x.joint) for x in sensors], int)
    local = np.array([[0.0, x.along * skeleton.lengths[x.joint], 0.0] for x in sensors]).reshape(-1, 3)
    ends = np.array([bool(on_end(x)) or method == "GOAL" for x in sensors], bool)
    dof_k = chain._k

    def points(frames):
        return (frames[pos, :3, :3] @ local[:, :, None])[:, :, 0] + frames[pos, :3, 3]

    before = None  # the depth at the start: from the first step's test (the same pose)
    goal = np.asarray(target_pos, float).copy()
    steps = 0
    for steps in range(1, max_steps + 1):
        eul = eul0.copy()
        eul[chain._k, chain._a] = theta
        frames, axes = chain.frames(eul, basis, base)
        hit = _inside(skeleton, sensors, None, volumes, margin, pts=points(frames))
        if before is None:
            before = max([d for _, _, d, _ in hit if d > 0], default=0.0)
        x, r = chain.effector(frames)
        # temporary goal for the hand: pushed out along the response, else its own target
        if not sticky_goal:
            goal = np.asarray(target_pos, float).copy()
        pushed = None
        dz = np.zeros(chain.n)
        for i, v, d, p in hit:
            push = v.normal(p) * (d + margin)
            if ends[i]:
                if sticky_goal:
                    pushed = (x if pushed is None else pushed) + push
                else:
                    goal = goal + push
                continue
            # secondary task on the sub-chain root..sensor (eq. 4-2)
            jac = chain.jacobian(frames, axes, target_point=p)[3:]
            jsub = jac * (dof_k <= pos[i])
            dz += np.linalg.pinv(jsub) @ push
        if pushed is not None:
            goal = pushed
        ep = goal - x
        er = ik.rot_log(target_rot @ r.T) if target_rot is not None else np.zeros(3)
        # done when every sensor keeps half the margin (the response aims at the whole margin,
        # which it only approaches geometrically) and the effector is on its goal
        clear = all(d <= -0.5 * margin for _, _, d, _ in hit)
        if clear and np.linalg.norm(ep) < 2e-4 and np.linalg.norm(er) < 1e-3:
            break
        w = 0.15
        jac = chain.jacobian(frames, axes)
        if target_rot is not None:
            jac[:3] *= w
            dx = np.concatenate((er * w, np.clip(ep, -0.05, 0.05)))
        else:
            jac, dx = jac[3:], np.clip(ep, -0.05, 0.05)
        dq = ik.null_space_step(jac, dx, dz)
        theta = np.clip(theta + dq, chain.lower, chain.upper)
        if np.abs(dq).max() < CONVERGED:  # a fixed point: the response and the goal balance
            break
    eul = eul0.copy()
    eul[chain._k, chain._a] = theta
    frames, _ = chain.frames(eul, basis, base)
    out = chain.apply(theta, basis)
    after = max([d for _, _, d, _ in _inside(skeleton, sensors, None, volumes, 0.0, pts=points(frames))],
                default=0.0)
    if before is None:  # no step was taken
        before = after
    return out, before, after, steps, theta, chain.effector(frames)[0]


CONVERGED = 1e-6  # radians: a correction step this small ends the frame's iterations


def remove_self_collisions(skeleton, frames, armature_to_world, sides=("L", "R"), targets=None, margin=0.01,
                           max_steps=40, with_spine=False, method="SECONDARY", legs=("L", "R"), leg_targets=None,
                           world=None):
    """Correct a motion (F, J, 4, 4) frame by frame: the arms of `sides`, then the legs of `legs`.
    The hand's target on each frame is its position and orientation in the input (or
    `targets[side]` = (positions (F, 3), rotations (F, 3, 3))); the foot's goal likewise (or
    `leg_targets[side]`, the ankle's positions and the foot's rotations). `world` (F, J, 4, 4),
    the input's world frames, saves computing them. Returns (corrected frames, CorrectionReport)."""
    frames = np.array(frames, float)
    out = frames.copy()
    corrected, worst_before, worst_after, goal_err, steps = 0, 0.0, 0.0, 0.0, 0
    leg_corrected, foot_err = 0, 0.0
    # `world`: the frames' world frames when the caller has them (F, J, 4, 4)
    world_in = skeleton.world_frames(frames, armature_to_world) if world is None else np.asarray(world, float)
    rest_world = world_in[0]
    volumes = [v for v in body_volumes(skeleton, rest_world) if v.name in ("trunk", "head")]
    sensors = body_sensors(skeleton, rest_world)  # sized once, on the first frame
    shift = {}  # per arm, the change the correction made on the previous frame
    arm_near = {s: _near_frames(skeleton, [x for x in sensors if x.limb == "arm" and x.chain_side == s], world_in,
                                volumes, margin) for s in sides}
    for t in range(len(frames)):
        w_in = world_in[t]
        cur = out[t]
        for s in sides:
            hand = skeleton.role_index(sided("hand", s))
            if hand is None:
                continue
            if targets is not None and s in targets:
                tp = targets[s][0][t]
                tr = None if targets[s][1] is None else targets[s][1][t]
            else:
                tp, tr = w_in[hand][:3, 3], w_in[hand][:3, :3]
            chain = _arm_chain(skeleton, s, with_spine)
            near, before = arm_near[s][0][t], arm_near[s][1][t]
            if not near and targets is None:  # clear of the body, on its own target: nothing to do
                shift[s] = None
                continue
            # warm start from the previous corrected frame keeps the motion continuous
            angles_in = chain.angles(cur)
            if t > 0 and targets is not None:
                start = chain.apply(chain.angles(out[t - 1]), cur)
            elif shift.get(s) is not None:  # the previous frame's correction, as a first guess
                start = chain.apply(angles_in + shift[s], cur)
            else:
                start = cur.copy()
            # the chain's base is not moved by either arm's correction: the input's world serves
            cur, _, after, n, theta, hw = correct_frame(skeleton, start, armature_to_world, s, tp, tr, volumes,
                                                        margin, max_steps, with_spine, method, sensors, world=w_in,
                                                        _full=True)
            shift[s] = theta - angles_in
            steps += n
            corrected += before > 0
            worst_before, worst_after = max(worst_before, before), max(worst_after, after)
            radius = max(x.radius for x in sensors if x.joint == hand)
            clear = min(v.distance(tp) for v in volumes) > radius + margin
            if clear:
                goal_err = max(goal_err, float(np.linalg.norm(hw - tp)))
        if legs:
            cur, n, depths, err = _correct_legs(skeleton, cur, out[t - 1] if t > 0 else None, w_in, t,
                                                armature_to_world, legs, leg_targets, sensors, margin, max_steps,
                                                method)
            steps += n
            leg_corrected += depths[0] > 0
            worst_before, worst_after = max(worst_before, depths[0]), max(worst_after, depths[1])
            foot_err = max(foot_err, err)
        out[t] = cur
    return out, CorrectionReport(int(corrected), worst_before, worst_after, goal_err, steps, foot_err,
                                 int(leg_corrected))


def _leg_depth(skeleton, sensors, world, margin=0.0):
    vols = [v for v in body_volumes(skeleton, world) if v.name != "head"]
    hit = _inside(skeleton, sensors, world, vols, margin)
    return max([d for *_, d, _ in hit], default=0.0), hit, vols


def _correct_legs(skeleton, cur, previous, w_in, t, armature_to_world, legs, leg_targets, sensors, margin, max_steps,
                  method):
    """One frame of the legs: each leg against the other as it is now and the trunk. A round
    corrects each leg in turn; the next round catches a leg the other's correction moved into.
    Returns (basis, steps, (depth before, depth after), foot error where its goal is clear)."""
    steps, done, goals = 0, {}, {}
    leg_sensors = [x for x in sensors if x.limb == "leg"]
    before = _leg_depth(skeleton, leg_sensors, skeleton.world_frames(cur, armature_to_world))[0]
    for s in [x for _ in range(LEG_ROUNDS) for x in legs]:
        foot = skeleton.role_index(sided("foot", s))
        if foot is None or skeleton.role_index(sided("thigh", s)) is None:
            continue
        if leg_targets is not None and s in leg_targets:
            tp = leg_targets[s][0][t]
            tr = None if leg_targets[s][1] is None else leg_targets[s][1][t]
        else:
            tp, tr = w_in[foot][:3, 3], w_in[foot][:3, :3]
        goals[s] = (foot, tp, tr)
        start = cur.copy()
        if previous is not None and leg_targets is not None and not done.get(s):
            chain = leg_chain(skeleton, s)  # warm start from the previous corrected frame
            start = chain.apply(chain.angles(previous), cur)
        leg = [x for x in leg_sensors if x.chain_side == s]
        w_start = skeleton.world_frames(start, armature_to_world)
        _, near, vols = _leg_depth(skeleton, leg, w_start, margin)
        if not near and (leg_targets is None or done.get(s)):
            continue
        done[s] = True
        cur, _, _, n = correct_leg(skeleton, start, armature_to_world, s, tp, tr, vols, margin, max_steps, method,
                                   sensors)
        steps += n
    w_out = skeleton.world_frames(cur, armature_to_world)
    after, _, vols = _leg_depth(skeleton, leg_sensors, w_out)
    err = 0.0
    for s, (foot, tp, tr) in goals.items():
        # the foot's goal counts where its own sensors would be clear of the body there
        ends = [x for x in leg_sensors if x.chain_side == s and x.name.split(".")[0] in LEG_END_SENSORS]
        goal_w = w_out.copy()
        goal_w[foot] = np.eye(4)
        goal_w[foot][:3, :3] = w_out[foot][:3, :3] if tr is None else tr
        goal_w[foot][:3, 3] = tp
        shin = skeleton.parents[foot]
        goal_w[shin][:3, 3] = tp - goal_w[shin][:3, :3] @ [0, skeleton.lengths[shin], 0]
        if not _inside(skeleton, ends, goal_w, vols, margin):
            err = max(err, float(np.linalg.norm(w_out[foot][:3, 3] - tp)))
    return cur, steps, (before, after), err
