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
from ..vectors import cross
from . import ik
from .body import Capsule, body_sensors, body_volumes, own_volume, sensor_points


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


def correct_frame(skeleton, basis, armature_to_world, side, target_pos, target_rot, volumes=None,
                  margin=0.01, max_steps=40, with_spine=False, method="SECONDARY", sensors=None, world=None,
                  _full=False, _corrector=None):
    """One frame of table 4-1 for one arm. `method` 'SECONDARY' (default) moves the colliding
    elbow and forearm sensors in the null space; 'GOAL' uses temporary end-effector goals for
    every sensor (sec. 4.6.3). `world` (the basis's world frames) saves computing them.
    Returns (basis, depth before, depth after, steps)."""
    world = skeleton.world_frames(basis, armature_to_world) if world is None else world
    chain = _arm_chain(skeleton, side, with_spine)
    if _corrector is None:
        _corrector = arm_corrector(skeleton, world, side, with_spine, method, sensors, volumes)
    out = _correct_chain(skeleton, basis, world, armature_to_world, chain, None, None, None, target_pos,
                         target_rot, margin, max_steps, method, corrector=_corrector)
    return out if _full else out[:4]  # _full: also the chain's angles and the wrist (for the motion pass)


def arm_corrector(skeleton, world, side, with_spine=False, method="SECONDARY", sensors=None, volumes=None):
    """The arm's sensors against the volumes (default the trunk and head) as one _ChainCorrector,
    to reuse over the frames of a motion."""
    hand = skeleton.role_index(sided("hand", side))
    chain = _arm_chain(skeleton, side, with_spine)
    sensors = [x for x in (sensors if sensors is not None else body_sensors(skeleton, world))
               if x.limb == "arm" and x.chain_side == side and x.joint in chain.joints]
    if volumes is None:
        volumes = [v for v in body_volumes(skeleton, world) if v.name in ("trunk", "head")]
    return _ChainCorrector(skeleton, chain, sensors, volumes, lambda x: x.joint == hand, method, ARM_GAIN)


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


class _Volumes:
    """The volumes as arrays, for every sensor against every volume in one product (capsules;
    any other volume through its own distance and normal)."""

    def __init__(self, sensors, volumes):
        self.volumes = list(volumes)
        self.radii = np.array([s.radius for s in sensors], float)
        own = np.array([[own_volume(s, v) for v in self.volumes] for s in sensors], bool)
        self.own = own.reshape(len(sensors), len(self.volumes))
        self.capsules = all(isinstance(v, Capsule) for v in self.volumes)
        if self.capsules and self.volumes:
            self.a = np.array([v.a for v in self.volumes], float)
            self.ab = np.array([v.b - v.a for v in self.volumes], float)
            self.inv = 1.0 / np.maximum(np.einsum("vi,vi->v", self.ab, self.ab), 1e-12)
            self.r = np.array([v.radius for v in self.volumes], float)

    def depths(self, pts):
        """(S, V) depths (radius minus distance; -inf for a sensor's own volume) and, for
        capsules, the (S, V, 3) offsets from each volume's axis (the response direction)."""
        if not self.volumes:
            return np.full(pts.shape[:-1] + (0,), -np.inf), None
        if not self.capsules:
            d = self.radii[:, None] - np.stack([v.distance(pts) for v in self.volumes], axis=-1)
            return np.where(self.own, -np.inf, d), None
        rel = pts[..., :, None, :] - self.a  # (..., S, V, 3)
        t = np.minimum(np.maximum(np.einsum("...vi,vi->...v", rel, self.ab) * self.inv, 0.0), 1.0)
        off = rel - t[..., None] * self.ab
        dist = np.sqrt(np.einsum("...i,...i->...", off, off))
        d = self.radii[:, None] - (dist - self.r)
        return np.where(self.own, -np.inf, d), off

    def normals(self, off, pts):
        """(..., S, V, 3) unit directions out of each volume at each sensor (pts (..., S, 3); `off`
        from depths)."""
        if off is None:
            flat = pts.reshape(-1, 3)
            out = np.array([[v.normal(p) for v in self.volumes] for p in flat]).reshape(flat.shape[:1] + (-1, 3))
            return out.reshape(pts.shape[:-1] + (len(self.volumes), 3))
        n = np.sqrt(np.einsum("...i,...i->...", off, off))[..., None]
        return np.where(n > 1e-9, off / np.maximum(n, 1e-300), (0.0, 0.0, 1.0))


class _ChainCorrector:
    """Table 4-1 on one chain for a fixed set of sensors and volumes: what does not change from
    frame to frame (the sensors' bones and offsets, the volumes as arrays) made once."""

    def __init__(self, skeleton, chain, sensors, volumes, on_end, method, gain=1.0):
        self.chain, self.sensors, self.gain = chain, sensors, gain
        self.pos = np.array([chain.joints.index(x.joint) for x in sensors], int)
        self.local = np.array([[0.0, x.along * skeleton.lengths[x.joint], 0.0] for x in sensors]).reshape(-1, 3)
        self.ends = np.array([bool(on_end(x)) or method == "GOAL" for x in sensors], bool)
        self.vols = _Volumes(sensors, volumes)
        # the sub-chain root..sensor of each sensor (eq. 4-2): the DOFs at or above its bone
        self.sub = (chain._k[None, :] <= self.pos[:, None]).astype(float)  # (S, n)

    def points(self, frames):
        """Sensor centres (..., S, 3) of the chain's frames (..., n, 4, 4)."""
        f = frames[..., self.pos, :, :]
        return (f[..., :3, :3] @ self.local[:, :, None])[..., 0] + f[..., :3, 3]

    def secondary(self, frames, axes, pts, hit, pushes, sub):
        """dz (B, n) = sum over each frame's hit sensors of J'+ dz' (eq. 4-2): every sensor's
        sub-chain Jacobian of every frame at once, a 3x3 solve (J' J'^T) where J' has full rank,
        the SVD pseudo-inverse where not. pts, pushes (B, S, 3); hit (B, S); sub: the sensors' rows of
        self.sub."""
        ch = self.chain
        w = axes[:, ch._k, ch._a]  # (B, n, 3)
        o = frames[:, ch._k][..., :3, 3]
        jac = cross(w[:, None], pts[:, :, None, :] - o[:, None]) * sub[:, :, None]  # (B, S, n, 3) = J'^T
        m = np.einsum("bsni,bsnj->bsij", jac, jac)  # J' J'^T (B, S, 3, 3)
        tr = np.trace(m, axis1=2, axis2=3)
        good = np.linalg.det(m) > 1e-9 * np.maximum(tr, 1e-30) ** 3
        # a sensor not hit, or short of rank 3, solves against I (its push is zero, or replaced below)
        y = np.linalg.solve(np.where(good[..., None, None], m, np.eye(3)),
                            np.where((hit & good)[..., None], pushes, 0.0)[..., None])[..., 0]
        dz = np.einsum("bsni,bsi->bn", jac, y)
        for b, h in zip(*np.nonzero(hit & ~good)):  # a sub-chain short of rank 3: the pseudo-inverse
            dz[b] += np.linalg.pinv(jac[b, h].T) @ pushes[b, h]
        return dz

    def run(self, basis, world, target_pos, target_rot, margin, max_steps, sticky_goal=False):
        """One frame: run_many on a batch of one."""
        out = self.run_many(basis[None], world[None], np.asarray(target_pos, float)[None],
                            None if target_rot is None else np.asarray(target_rot, float)[None],
                            margin, max_steps, sticky_goal)
        return tuple(x[0] for x in out)

    def run_many(self, bases, worlds, target_pos, target_rot, margin, max_steps, sticky_goal=False):
        """Table 4-1 on B frames at once (bases, worlds (B, J, 4, 4); targets (B, 3) and (B, 3, 3) or
        None): each frame iterates until it is done, then drops out of the batch. Returns the
        corrected bases, the deepest sensor before and after (B,), the steps taken (B,), the
        chain's angles (B, n) and the effector positions (B, 3)."""
        chain = self.chain
        count = len(bases)
        parent = chain.skeleton.parents[chain.joints[0]]
        base = np.broadcast_to(np.eye(4), (count, 4, 4)) if parent < 0 else worlds[:, parent]
        eul0 = ik.euler_xyz(bases[:, chain.joints][..., :3, :3])
        # each bone's head from its parent's frame: rest offset plus the pose's translation
        offsets = chain._rest_t + (chain._rest_r @ bases[:, chain.joints][..., :3, 3, None])[..., 0]
        theta = eul0[:, chain._k, chain._a]
        goal = np.array(target_pos, float)  # the legs' sticky goals
        before, after, steps = np.zeros(count), np.zeros(count), np.zeros(count, int)
        effector = np.zeros((count, 3))
        tested = np.zeros(count, bool)  # theta is the pose whose depth and effector are known
        live = np.arange(count)
        for step in range(1, max_steps + 1):
            if not len(live):
                break
            steps[live] = step
            eul = eul0[live]
            eul[:, chain._k, chain._a] = theta[live]
            frames, axes = ik.chain_frames(eul, chain._rest_r, offsets[live], base[live])
            pts = self.points(frames)
            depth, off = self.vols.depths(pts)  # (L, S, V)
            deepest = depth.max(axis=(1, 2), initial=-np.inf)
            if step == 1:
                before[:] = np.maximum(deepest, 0.0)
            after[live] = np.maximum(deepest, 0.0)
            tested[live] = True
            tip = frames[:, chain._tip_k]
            x = tip[:, :3, :3] @ chain.point + tip[:, :3, 3]
            effector[live] = x
            # the response of every sensor within the margin, summed over the volumes it is near
            hit = depth > -margin
            push = (self.vols.normals(off, pts) * np.where(hit, depth + margin, 0.0)[..., None]).sum(axis=2)
            ends = hit[:, self.ends].any(axis=(1, 2))
            end_push = push[:, self.ends].sum(axis=1)
            # temporary goal for the effector: pushed out along the response, else its own target
            if sticky_goal:
                goal[live] = np.where(ends[:, None], x + end_push, goal[live])
                ep = goal[live] - x
            else:
                ep = target_pos[live] + end_push - x
            er = np.zeros((len(live), 3)) if target_rot is None else \
                ik.rot_log_many(target_rot[live] @ np.swapaxes(tip[:, :3, :3], 1, 2))
            # done when every sensor keeps half the margin (the response aims at the whole margin,
            # which it only approaches geometrically) and the effector is on its goal
            done = (deepest <= -0.5 * margin) & (np.einsum("bi,bi->b", ep, ep) < 4e-8) & \
                (np.einsum("bi,bi->b", er, er) < 1e-6)
            go = ~done
            live = live[go]
            if not len(live):
                break
            frames, axes, pts, x, ep, er = frames[go], axes[go], pts[go], x[go], ep[go], er[go]
            inner = hit[go][:, ~self.ends].any(axis=2)
            dz = self.gain * self.secondary(frames, axes, pts[:, ~self.ends], inner, push[go][:, ~self.ends],
                                                 self.sub[~self.ends]) if inner.any() else np.zeros((len(live), chain.n))
            w = axes[:, chain._k, chain._a]
            lin = np.swapaxes(cross(w, x[:, None] - frames[:, chain._k][..., :3, 3]), 1, 2)
            ep = np.minimum(np.maximum(ep, -0.05), 0.05)
            if target_rot is not None:
                wt = 0.15
                jac = np.concatenate((wt * np.swapaxes(w, 1, 2), lin), axis=1)
                dx = np.concatenate((wt * er, ep), axis=1)
            else:
                jac, dx = lin, ep
            dq = ik.null_space_steps(jac, dx, dz)
            theta[live] = np.minimum(np.maximum(theta[live] + dq, chain.lower), chain.upper)
            tested[live] = False
            live = live[np.abs(dq).max(axis=1) >= CONVERGED]  # a fixed point: the response and goal balance
        eul = eul0.copy()
        eul[:, chain._k, chain._a] = theta
        moved = np.flatnonzero(~tested)
        if len(moved):
            frames, _ = ik.chain_frames(eul[moved], chain._rest_r, offsets[moved], base[moved])
            depth, _ = self.vols.depths(self.points(frames))
            after[moved] = np.maximum(depth.max(axis=(1, 2), initial=-np.inf), 0.0)
            tip = frames[:, chain._tip_k]
            effector[moved] = tip[:, :3, :3] @ chain.point + tip[:, :3, 3]
        out = np.array(bases, float)
        out[:, chain.joints, :3, :3] = ik.matrix_xyz(eul)
        return out, before, after, steps, theta, effector


def _correct_chain(skeleton, basis, world, armature_to_world, chain, sensors, volumes, on_end, target_pos,
                   target_rot, margin, max_steps, method, sticky_goal=False, corrector=None):
    """Table 4-1 on one chain; `on_end(sensor)` tells the sensors that ride on the end effector
    (they get temporary goals, the others the secondary task). The arm's temporary goal is its
    target pushed by the current response; with `sticky_goal` (the legs) it is the effector's
    place pushed out, and it stays there once clear, so a goal inside the body is left for good
    on that frame instead of being sought again. `corrector` (made by the caller once for many
    frames) saves building the per-chain arrays."""
    if corrector is None:
        corrector = _ChainCorrector(skeleton, chain, sensors, volumes, on_end, method)
    return corrector.run(basis, world, target_pos, target_rot, margin, max_steps, sticky_goal)


CONVERGED = 1e-6  # radians: a correction step this small ends the frame's iterations
# the arm's step takes eq. 4-2's dz twice: the main task's null space passes on a quarter to a half
# of the response each step (a deep elbow took 10-14 steps at 1); 2 halves that, 3 and more
# overshoot and leave the hand 0.1-0.2 mm off its goal. The legs keep 1: each leg's response also
# moves the volumes the other leg answers to, and more overshoots into them.
ARM_GAIN = 2.0


def remove_self_collisions(skeleton, frames, armature_to_world, sides=("L", "R"), targets=None, margin=0.01,
                           max_steps=40, with_spine=False, method="SECONDARY", legs=("L", "R"), leg_targets=None,
                           world=None):
    """Correct a motion (F, J, 4, 4) frame by frame: the arms of `sides`, then the legs of `legs`.
    The hand's target on each frame is its position and orientation in the input (or
    `targets[side]` = (positions (F, 3), rotations (F, 3, 3))); the foot's goal likewise (or
    `leg_targets[side]`, the ankle's positions and the foot's rotations). `world` (F, J, 4, 4),
    the input's world frames, saves computing them. Returns (corrected frames, CorrectionReport).

    On its own targets (no `targets`), an arm's frames near the body are corrected together, as one
    batch, each from its own pose; with `targets`, frame by frame, each warm started from the one
    before.
    """
    frames = np.array(frames, float)
    out = frames.copy()
    tally = _Tally()
    # `world`: the frames' world frames when the caller has them (F, J, 4, 4)
    world_in = skeleton.world_frames(frames, armature_to_world) if world is None else np.asarray(world, float)
    rest_world = world_in[0]
    volumes = [v for v in body_volumes(skeleton, rest_world) if v.name in ("trunk", "head")]
    sensors = body_sensors(skeleton, rest_world)  # sized once, on the first frame
    # each arm moves only its chain (the base, above it, is the input's): the arms one after the other
    for s in sides:
        hand = skeleton.role_index(sided("hand", s))
        if hand is None:
            continue
        arm = ArmPass(skeleton, s, world_in, sensors, volumes, margin, max_steps, with_spine, method,
                      None if targets is None else targets.get(s), tally)
        if targets is None:
            arm.together(out)
        else:
            arm.sequential(out)
    leg_corrected, foot_err, steps = 0, 0.0, 0
    worst_before, worst_after = tally.before, tally.after
    for t in range(len(frames)) if legs else ():
        cur, n, depths, err = _correct_legs(skeleton, out[t], out[t - 1] if t > 0 else None, world_in[t], t,
                                            armature_to_world, legs, leg_targets, sensors, margin, max_steps, method)
        steps += n
        leg_corrected += depths[0] > 0
        worst_before, worst_after = max(worst_before, depths[0]), max(worst_after, depths[1])
        foot_err = max(foot_err, err)
        out[t] = cur
    return out, CorrectionReport(int(tally.corrected), worst_before, worst_after, tally.goal_err,
                                 tally.steps + steps, foot_err, int(leg_corrected))


class _Tally:
    """The arms' share of the CorrectionReport."""

    def __init__(self):
        self.corrected, self.before, self.after, self.goal_err, self.steps = 0, 0.0, 0.0, 0.0, 0

    def add(self, before, after, goal_err, steps):
        self.corrected += before > 0
        self.before, self.after = max(self.before, before), max(self.after, after)
        if goal_err is not None:
            self.goal_err = max(self.goal_err, goal_err)
        self.steps += steps


class ArmPass:
    """One arm over the frames of a motion (table 4-1 per frame)."""

    def __init__(self, skeleton, side, world_in, sensors, volumes, margin, max_steps, with_spine, method, target,
                 tally):
        self.sk, self.world_in, self.margin, self.max_steps, self.tally = skeleton, world_in, margin, max_steps, tally
        hand = skeleton.role_index(sided("hand", side))
        self.chain = _arm_chain(skeleton, side, with_spine)
        self.cor = arm_corrector(skeleton, world_in[0], side, with_spine, method, sensors, volumes)
        if target is not None:
            self.tp = np.asarray(target[0], float)
            self.tr = None if target[1] is None else np.asarray(target[1], float)
        else:
            self.tp, self.tr = world_in[:, hand, :3, 3], world_in[:, hand, :3, :3]
        # per input frame: a sensor within the margin of a volume, and the deepest one's depth
        depth, _ = self.cor.vols.depths(self.cor.points(world_in[:, self.chain.joints]))
        deepest = depth.max(axis=(1, 2), initial=-np.inf)
        self.near, self.depth_in = deepest > -margin, np.maximum(deepest, 0.0)
        # the hand's goal error counts where its target is clear of the body
        radius = max(x.radius for x in sensors if x.joint == hand)
        dist = np.min([v.distance(self.tp) for v in volumes], axis=0) if volumes else np.full(len(self.tp), np.inf)
        self.target_clear = dist > radius + margin

    def solve(self, out, t, start):
        """Correct frame t from `start`; returns the chain's angles."""
        res = self.cor.run(start, self.world_in[t], self.tp[t], None if self.tr is None else self.tr[t],
                           self.margin, self.max_steps)
        out[t] = res[0]
        err = float(np.linalg.norm(res[5] - self.tp[t])) if self.target_clear[t] else None
        self.tally.add(self.depth_in[t], res[2], err, res[3])
        return res[4]

    def sequential(self, out):
        """Every frame (given targets): warm started from the previous corrected frame."""
        chain = self.chain
        for t in range(len(out)):
            start = chain.apply(chain.angles(out[t - 1]), out[t]) if t > 0 else out[t].copy()
            self.solve(out, t, start)

    def together(self, out):
        """The frames near the body (on the input) corrected in one batch, each from its own pose;
        the others left."""
        near = np.flatnonzero(self.near)
        if not len(near):
            return
        res = self.cor.run_many(out[near], self.world_in[near], self.tp[near], None if self.tr is None else self.tr[near],
                                self.margin, self.max_steps)
        out[near] = res[0]
        for k, t in enumerate(near):
            err = float(np.linalg.norm(res[5][k] - self.tp[t])) if self.target_clear[t] else None
            self.tally.add(self.depth_in[t], res[2][k], err, int(res[3][k]))


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
