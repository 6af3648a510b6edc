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
    return _ChainCorrector(skeleton, chain, sensors, volumes, lambda x: x.joint == hand, method)


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

    def normal(self, off, i, k, p):
        if off is None:
            return self.volumes[k].normal(p)
        o = off[i, k]
        n = np.sqrt(o @ o)
        return o / n if n > 1e-9 else np.array([0.0, 0.0, 1.0])


class _ChainCorrector:
    """Table 4-1 on one chain for a fixed set of sensors and volumes: what does not change from
    frame to frame (the sensors' bones and offsets, the volumes as arrays) made once."""

    def __init__(self, skeleton, chain, sensors, volumes, on_end, method):
        self.chain, self.sensors = chain, sensors
        self.pos = np.array([chain.joints.index(x.joint) for x in sensors], int)
        self.local = np.array([[0.0, x.along * skeleton.lengths[x.joint], 0.0] for x in sensors]).reshape(-1, 3)
        self.ends = np.array([bool(on_end(x)) or method == "GOAL" for x in sensors], bool)
        self.vols = _Volumes(sensors, volumes)
        # the sub-chain root..sensor of each sensor (eq. 4-2): the DOFs at or above its bone
        self.sub = (chain._k[None, :] <= self.pos[:, None]).astype(float)  # (S, n)

    def frames(self, eul, offsets, base):
        """Chain.frames with the bones' rest offsets and pose translations folded into `offsets`
        (n, 3) once per frame: the chain's world frames (rows 0-2) and the DOF axes in world."""
        local = ik.matrix_xyz(eul)
        rest_r = self.chain._rest_r
        n = len(rest_r)
        world = np.empty((n, 4, 4))
        world[:, 3] = (0.0, 0.0, 0.0, 1.0)
        pre = np.empty((n, 3, 3))  # each bone's rest orientation in world, before its own turn
        pr, pp = base[:3, :3], base[:3, 3]
        for k in range(n):
            pp = pp + pr @ offsets[k]
            pre[k] = r = pr @ rest_r[k]
            world[k, :3, :3] = pr = r @ local[k]
            world[k, :3, 3] = pp
        axes = np.empty((n, 3, 3))
        a = eul[:, 0, None]
        axes[:, 0] = pre[:, :, 0]
        axes[:, 1] = pre[:, :, 1] * np.cos(a) + pre[:, :, 2] * np.sin(a)
        axes[:, 2] = world[:, :3, 2]
        return world, axes

    def points(self, frames):
        return (frames[self.pos, :3, :3] @ self.local[:, :, None])[:, :, 0] + frames[self.pos, :3, 3]

    def secondary(self, frames, axes, idx, pts, pushes):
        """dz = sum over the hit sensors of J'+ dz' (eq. 4-2), every sensor's sub-chain Jacobian
        at once; a 3x3 solve (J' J'^T) where J' has full rank, the SVD pseudo-inverse where not."""
        ch = self.chain
        w = axes[ch._k, ch._a]  # (n, 3)
        o = frames[ch._k, :3, 3]  # (n, 3)
        jac = ik.cross(w[None], pts[:, None, :] - o[None]) * self.sub[idx][:, :, None]  # (H, n, 3) = J'^T
        m = np.einsum("hni,hnj->hij", jac, jac)  # J' J'^T (H, 3, 3)
        tr = np.trace(m, axis1=1, axis2=2)
        det = np.linalg.det(m)
        dz = np.zeros(ch.n)
        good = det > 1e-9 * np.maximum(tr, 1e-30) ** 3
        if good.any():
            y = np.linalg.solve(m[good], pushes[good][:, :, None])[:, :, 0]
            dz += np.einsum("hni,hi->n", jac[good], y)
        for h in np.flatnonzero(~good):  # a sub-chain short of rank 3: the pseudo-inverse
            dz += np.linalg.pinv(jac[h].T) @ pushes[h]
        return dz

    def run(self, basis, world, target_pos, target_rot, margin, max_steps, sticky_goal=False):
        chain = self.chain
        base = ik.chain_base(chain, world)
        eul0 = ik.euler_xyz(basis[chain.joints, :3, :3])
        # each bone's head from its parent's frame: rest offset plus the pose's translation
        offsets = chain._rest_t + (chain._rest_r @ basis[chain.joints][:, :3, 3, None])[:, :, 0]
        theta = eul0[chain._k, chain._a]
        target_pos = np.asarray(target_pos, float)
        before = None  # the depth at the start: from the first step's test (the same pose)
        goal = target_pos.copy()
        steps = 0
        depth = None
        frames = None
        for steps in range(1, max_steps + 1):
            eul = eul0.copy()
            eul[chain._k, chain._a] = theta
            frames, axes = self.frames(eul, offsets, base)
            pts = self.points(frames)
            depth, off = self.vols.depths(pts)
            if before is None:
                before = max(float(depth.max(initial=-np.inf)), 0.0)
            x, r = chain.effector(frames)
            # temporary goal for the hand: pushed out along the response, else its own target
            if not sticky_goal:
                goal = target_pos
            pushed = None
            dz = np.zeros(chain.n)
            hs, ks = np.nonzero(depth > -margin)  # sensor order, then volume order, as before
            sec_i, sec_push = [], []
            for i, k in zip(hs, ks):
                d = depth[i, k]
                push = self.vols.normal(off, i, k, pts[i]) * (d + margin)
                if self.ends[i]:
                    if sticky_goal:
                        pushed = (x if pushed is None else pushed) + push
                    else:
                        goal = goal + push
                    continue
                if sec_i and sec_i[-1] == i:  # one sensor, two volumes: the pushes add (dz is linear)
                    sec_push[-1] = sec_push[-1] + push
                else:
                    sec_i.append(i)
                    sec_push.append(push)
            if sec_i:
                dz = self.secondary(frames, axes, np.array(sec_i), pts[sec_i], np.array(sec_push))
            if pushed is not None:
                goal = pushed
            ep = goal - x
            er = ik.rot_log(target_rot @ r.T) if target_rot is not None else np.zeros(3)
            # done when every sensor keeps half the margin (the response aims at the whole margin,
            # which it only approaches geometrically) and the effector is on its goal
            clear = not len(hs) or bool((depth[hs, ks] <= -0.5 * margin).all())
            if clear and np.sqrt(ep @ ep) < 2e-4 and np.sqrt(er @ er) < 1e-3:
                break  # theta is the pose just tested: its frames and depths stand
            w = 0.15
            jac = chain.jacobian(frames, axes)
            if target_rot is not None:
                jac[:3] *= w
                dx = np.concatenate((er * w, np.minimum(np.maximum(ep, -0.05), 0.05)))
            else:
                jac, dx = jac[3:], np.minimum(np.maximum(ep, -0.05), 0.05)
            dq = ik.null_space_step(jac, dx, dz)
            theta = np.minimum(np.maximum(theta + dq, chain.lower), chain.upper)
            frames = None  # theta moved
            if np.abs(dq).max() < CONVERGED:  # a fixed point: the response and the goal balance
                break
        eul = eul0.copy()
        eul[chain._k, chain._a] = theta
        if frames is None:
            frames, _ = self.frames(eul, offsets, base)
            depth, _ = self.vols.depths(self.points(frames))
        out = np.array(basis, float)
        out[chain.joints, :3, :3] = ik.matrix_xyz(eul)
        after = max(float(depth.max(initial=-np.inf)), 0.0)
        if before is None:  # no step was taken
            before = after
        return out, before, after, steps, theta, chain.effector(frames)[0]


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


def remove_self_collisions(skeleton, frames, armature_to_world, sides=("L", "R"), targets=None, margin=0.01,
                           max_steps=40, with_spine=False, method="SECONDARY", legs=("L", "R"), leg_targets=None,
                           world=None):
    """Correct a motion (F, J, 4, 4) frame by frame: the arms of `sides`, then the legs of `legs`.
    The hand's target on each frame is its position and orientation in the input (or
    `targets[side]` = (positions (F, 3), rotations (F, 3, 3))); the foot's goal likewise (or
    `leg_targets[side]`, the ankle's positions and the foot's rotations). `world` (F, J, 4, 4),
    the input's world frames, saves computing them. Returns (corrected frames, CorrectionReport).

    On its own targets (no `targets`), an arm is corrected on every other frame of each stretch
    near the body; the frames between take the mean of their neighbours' corrections (the motion
    is smooth) and are kept only if they pass the same test a corrected frame ends on (every
    sensor half the margin clear, the hand on its target), all in one batched check; the others
    are corrected from that guess."""
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
            arm.skipping(out)
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


MAIN_STEPS = 1  # on a frame between: batched main-task steps before it is corrected on its own
STRIDE = 2  # an arm near the body: every STRIDE-th frame corrected, the ones between interpolated and checked


def _between(shift, solved, t):
    """The correction at frame t, linear between the corrected frames on either side."""
    k = np.searchsorted(solved, t)
    t0, t1 = solved[k - 1], solved[k]
    u = (t - t0) / (t1 - t0)
    return (1.0 - u) * shift[t0] + u * shift[t1]


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
        self.near, self.depth_in = _near_frames(skeleton, self.cor.sensors, world_in, volumes, margin)
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

    def skipping(self, out):
        """Each stretch of frames near the body (on the input) through _stretch; the others left."""
        f = len(out)
        t = 0
        while t < f:
            if not self.near[t]:  # clear of the body, on its own target: nothing to do
                t += 1
                continue
            b = t
            while b + 1 < f and self.near[b + 1]:
                b += 1
            self._stretch(out, t, b)
            t = b + 1

    def _stretch(self, out, a, b):
        """Frames a..b, all near the body: every other one corrected, the others checked."""
        chain = self.chain
        solved = list(range(a, b + 1, STRIDE))
        if solved[-1] != b:
            solved.append(b)
        shift = {}
        done = []  # the corrected frames so far: their changes, extrapolated, are the next one's first guess
        for t in solved:
            angles_in = chain.angles(out[t])
            if not done:
                start = out[t].copy()
            else:
                guess = shift[done[-1]]
                if len(done) > 1:  # the correction grows or shrinks smoothly over the reach
                    t0, t1 = done[-2], done[-1]
                    guess = guess + (shift[t1] - shift[t0]) * ((t - t1) / (t1 - t0))
                start = chain.apply(angles_in + guess, out[t])
            shift[t] = self.solve(out, t, start) - angles_in
            done.append(t)
        between = np.array([t for t in range(a, b + 1) if t not in shift], int)
        if not len(between):
            return
        eul = ik.euler_xyz(out[between][:, chain.joints, :3, :3])
        guess = np.array([_between(shift, solved, t) for t in between])
        theta = np.clip(eul[:, chain._k, chain._a] + guess, chain.lower, chain.upper)
        eul[:, chain._k, chain._a] = theta
        ok, hand = self._passes(eul, out[between], between)
        for _ in range(MAIN_STEPS):  # steps of the main task (eq. 2-1, dz = 0) on the others, then the test again
            bad = np.flatnonzero(~ok)
            if not len(bad):
                break
            eul[bad] = self._main_step(eul[bad], out[between[bad]], between[bad])
            ok[bad], hand[bad] = self._passes(eul[bad], out[between[bad]], between[bad])
        for k, t in enumerate(between):
            start = out[t].copy()
            start[chain.joints, :3, :3] = ik.matrix_xyz(eul[k])
            if ok[k]:
                out[t] = start
                err = float(np.linalg.norm(hand[k] - self.tp[t])) if self.target_clear[t] else None
                self.tally.add(self.depth_in[t], 0.0, err, 0)
            else:
                self.solve(out, t, start)

    def _passes(self, eul, basis, idx):
        """Per pose (eul (B, n, 3) of the chain on basis (B, J, 4, 4) at frames idx): the test a
        corrected frame ends on: every sensor at least half the margin clear (the hand's sensor
        the whole margin: inside it the hand's goal would be pushed) and the hand on its target.
        Returns (passes (B,), hand positions (B, 3))."""
        chain, cor = self.chain, self.cor
        wf = _chain_frames_many(chain, eul, basis, self.world_in[idx])
        pts = (wf[:, cor.pos, :3, :3] @ cor.local[:, :, None])[..., 0] + wf[:, cor.pos][..., :3, 3]
        depth, _ = cor.vols.depths(pts)
        depth = depth.max(axis=-1, initial=-np.inf)  # (B, S)
        limit = np.where(cor.ends, -self.margin, -0.5 * self.margin)
        tip = wf[:, chain._tip_k]
        hand = tip[:, :3, :3] @ chain.point + tip[:, :3, 3]
        ok = (depth <= limit).all(axis=1) & (np.linalg.norm(self.tp[idx] - hand, axis=1) < 2e-4)
        if self.tr is not None:
            ok &= ik.rot_angle(self.tr[idx] @ np.swapaxes(tip[:, :3, :3], 1, 2)) < 1e-3
        return ok, hand

    def _main_step(self, eul, basis, idx):
        """One damped least-squares step (ik.null_space_step without the secondary term) toward
        the hand's target for B poses at once; returns the new angles (B, n, 3)."""
        chain = self.chain
        wf, axes = _chain_frames_many(chain, eul, basis, self.world_in[idx], with_axes=True)
        tip = wf[:, chain._tip_k]
        x = tip[:, :3, :3] @ chain.point + tip[:, :3, 3]
        ep = np.clip(self.tp[idx] - x, -0.05, 0.05)
        w = axes[:, chain._k, chain._a]  # (B, n, 3)
        lin = ik.cross(w, x[:, None, :] - wf[:, chain._k][..., :3, 3])
        if self.tr is not None:
            er = _rot_log_many(self.tr[idx] @ np.swapaxes(tip[:, :3, :3], 1, 2))
            jac = np.concatenate((0.15 * w, lin), axis=2).transpose(0, 2, 1)  # (B, 6, n)
            dx = np.concatenate((0.15 * er, ep), axis=1)
        else:
            jac, dx = lin.transpose(0, 2, 1), ep
        u, sv, vt = np.linalg.svd(jac, full_matrices=False)
        eps, lam_max = 0.02, 0.05  # ik.damped_pinv's rule
        smin = sv[:, -1]
        lam2 = np.where(smin >= eps, 0.0, lam_max ** 2 * (1.0 - (smin / eps) ** 2))
        y = np.einsum("bji,bj->bi", u, dx) * sv / (sv ** 2 + lam2[:, None])
        dq = np.einsum("bij,bi->bj", vt, y)
        out = eul.copy()
        out[:, chain._k, chain._a] = np.clip(eul[:, chain._k, chain._a] + dq, chain.lower, chain.upper)
        return out


def _rot_log_many(r):
    """ik.rot_log of (B, 3, 3) rotations away from a half turn."""
    v = np.stack((r[:, 2, 1] - r[:, 1, 2], r[:, 0, 2] - r[:, 2, 0], r[:, 1, 0] - r[:, 0, 1]), axis=1)
    s = 0.5 * np.sqrt(np.einsum("bi,bi->b", v, v))
    th = np.arctan2(s, 0.5 * (r[:, 0, 0] + r[:, 1, 1] + r[:, 2, 2] - 1.0))
    return v * np.where(th < 1e-6, 0.5, th / (2.0 * np.maximum(s, 1e-300)))[:, None]


def _chain_frames_many(chain, eul, basis, world, with_axes=False):
    """World frames (B, n, 4, 4) of the chain's bones for B poses: angles eul (B, n, 3) on
    basis (B, J, 4, 4), the chain's base from the world frames (B, J, 4, 4)."""
    p = chain.skeleton.parents[chain.joints[0]]
    b = len(eul)
    base = np.broadcast_to(np.eye(4), (b, 4, 4)) if p < 0 else world[:, p]
    local = ik.matrix_xyz(eul)
    bt = basis[:, chain.joints][..., :3, 3]
    out = np.zeros((b, len(chain.joints), 4, 4))
    out[..., 3, 3] = 1.0
    pr, pp = base[:, :3, :3], base[:, :3, 3]
    pre = np.empty((b, len(chain.joints), 3, 3))  # each bone's rest orientation in world, before its turn
    for k in range(len(chain.joints)):
        r = pr @ chain._rest_r[k]
        pp = pr @ chain._rest_t[k] + pp + (r @ bt[:, k, :, None])[..., 0]
        pr = r @ local[:, k]
        pre[:, k] = r
        out[:, k, :3, :3] = pr
        out[:, k, :3, 3] = pp
    if not with_axes:
        return out
    axes = np.empty((b, len(chain.joints), 3, 3))  # as Chain.frames: the X, Y' and Z'' axes in world
    a = eul[..., 0][..., None]
    axes[:, :, 0] = pre[..., 0]
    axes[:, :, 1] = pre[..., 1] * np.cos(a) + pre[..., 2] * np.sin(a)
    axes[:, :, 2] = out[:, :, :3, 2]
    return out, axes


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
