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
"""

from dataclasses import dataclass

import numpy as np

from ..body_roles import sided
from . import ik
from .body import body_sensors, body_volumes, sensor_points


@dataclass
class CorrectionReport:
    frames_corrected: int
    max_depth_before: float
    max_depth_after: float
    max_goal_error: float  # hand off its target on the frames where its target is clear of the body
    steps: int


def _inside(skeleton, sensors, world, volumes, margin):
    pts = sensor_points(skeleton, sensors, world)
    out = []
    for i, s in enumerate(sensors):
        for v in volumes:
            d = s.radius - v.distance(pts[i])
            if d > -margin:
                out.append((i, v, float(d), pts[i]))
    return out


def correct_frame(skeleton, basis, armature_to_world, side, target_pos, target_rot, volumes=None,
                  margin=0.01, max_steps=40, with_spine=False, method="SECONDARY", sensors=None):
    """One frame of table 4-1 for one arm. `method` 'SECONDARY' (default) moves the colliding
    elbow and forearm sensors in the null space; 'GOAL' uses temporary end-effector goals for
    every sensor (sec. 4.6.3). Returns (basis, depth before, depth after, steps)."""
    world = skeleton.world_frames(basis, armature_to_world)
    hand = skeleton.role_index(sided("hand", side))
    chain = ik.Chain.arm(skeleton, side, point=np.zeros(3), with_spine=with_spine)
    sensors = [x for x in (sensors if sensors is not None else body_sensors(skeleton, world))
               if x.limb == "arm" and x.chain_side == side and x.joint in chain.joints]
    if volumes is None:
        volumes = [v for v in body_volumes(skeleton, world) if v.name in ("trunk", "head")]
    base = ik.chain_base(chain, world)
    theta = chain.angles(basis)
    hit = _inside(skeleton, sensors, world, volumes, 0.0)
    before = max([d for _, _, d, _ in hit], default=0.0)
    goal = np.asarray(target_pos, float).copy()
    steps = 0
    for steps in range(1, max_steps + 1):
        eul = chain.euler(theta, basis)
        frames, axes = chain.frames(eul, basis, base)
        full = world.copy()
        for k, j in enumerate(chain.joints):
            full[j] = frames[k]
        # descendants of the chain (fingers) follow the hand for the sensors on it
        hit = _inside(skeleton, sensors, full, volumes, margin)
        x, r = chain.effector(frames)
        # temporary goal for the hand: pushed out along the response, else its own target
        goal = np.asarray(target_pos, float).copy()
        dz = np.zeros(chain.n)
        for i, v, d, p in hit:
            s = sensors[i]
            push = v.normal(p) * (d + margin)
            if s.joint == hand or method == "GOAL":
                goal = goal + push
                continue
            # secondary task on the sub-chain root..sensor (eq. 4-2)
            k = chain.joints.index(s.joint)
            jac = chain.jacobian(frames, axes, target_point=p)[3:]
            cols = np.array([kk <= k for kk, _ in chain.dofs])
            jsub = jac * cols
            dz += np.linalg.pinv(jsub) @ push
        ep = goal - x
        er = ik.rot_log(target_rot @ r.T) if target_rot is not None else np.zeros(3)
        if not hit and np.linalg.norm(ep) < 2e-4 and np.linalg.norm(er) < 1e-3:
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
    out = chain.apply(theta, basis)
    after_world = skeleton.world_frames(out, armature_to_world)
    after = max([d for _, _, d, _ in _inside(skeleton, sensors, after_world, volumes, 0.0)], default=0.0)
    return out, before, after, steps


def remove_self_collisions(skeleton, frames, armature_to_world, sides=("L", "R"), targets=None, margin=0.01,
                           max_steps=40, with_spine=False, method="SECONDARY"):
    """Correct a motion (F, J, 4, 4) frame by frame. The hand's target on each frame is its
    position and orientation in the input (or `targets[side]` = (positions (F, 3), rotations
    (F, 3, 3))). Returns (corrected frames, CorrectionReport)."""
    frames = np.array(frames, float)
    out = frames.copy()
    corrected, worst_before, worst_after, goal_err, steps = 0, 0.0, 0.0, 0.0, 0
    rest_world = skeleton.world_frames(frames[0], armature_to_world)
    volumes = [v for v in body_volumes(skeleton, rest_world) if v.name in ("trunk", "head")]
    sensors = body_sensors(skeleton, rest_world)  # sized once, on the first frame
    for t in range(len(frames)):
        w_in = skeleton.world_frames(frames[t], armature_to_world)
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
            # warm start from the previous corrected frame keeps the motion continuous
            start = cur.copy()
            if t > 0 and targets is not None:
                chain = ik.Chain.arm(skeleton, s, with_spine=with_spine)
                start = chain.apply(chain.angles(out[t - 1]), cur)
            arm = [x for x in sensors if x.limb == "arm" and x.chain_side == s]
            near = _inside(skeleton, arm, w_in, volumes, margin)
            before = max([d for *_, d, _ in near if d > 0], default=0.0)
            if not near and targets is None:  # clear of the body, on its own target: nothing to do
                continue
            cur, _, after, n = correct_frame(skeleton, start, armature_to_world, s, tp, tr, volumes,
                                             margin, max_steps, with_spine, method, sensors)
            steps += n
            corrected += before > 0
            worst_before, worst_after = max(worst_before, before), max(worst_after, after)
            hw = skeleton.world_frames(cur, armature_to_world)[hand][:3, 3]
            radius = max(x.radius for x in sensors if x.joint == hand)
            clear = min(v.distance(tp) for v in volumes) > radius + margin
            if clear:
                goal_err = max(goal_err, float(np.linalg.norm(hw - tp)))
        out[t] = cur
    return out, CorrectionReport(int(corrected), worst_before, worst_after, goal_err, steps)
