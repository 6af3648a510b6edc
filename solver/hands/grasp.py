"""Automatic grasping (Huang 1996 sec. 4.3): the grasp type from the object's primitive and the
hand's size (table of sec. 4.3.2), the grasp frame (thumb on the visible side, palm not facing
away from the body, least weighted change of hand translation and rotation), the reach (IK gives
the final arm posture, a PD servo per DOF moves the arm there, eq. 4-1) and the closing (fingers
follow a hand motion pattern until a sensor touches; a touching sensor stops its ancestors'
DOFs, the others go on, sec. 4.3.4)."""

from dataclasses import dataclass, field

import numpy as np

from ..body_roles import FINGERS, sided
from ..errors import HumanAnimError
from ..vectors import cross
from . import ik
from .primitives import Box, Sphere, dimensions, kind, shape_frame
from .self_collision import remove_self_collisions
from .sensors import default_hand_sensors, sensor_centres, sensor_layout

TYPES = ("LATERAL", "PINCH", "TRIPOD", "WRAP", "DISK")
# fingers each type closes on the object (the proof checks every one touches)
TYPE_FINGERS = {"LATERAL": ("thumb", "index"), "PINCH": ("thumb", "index"),
                "TRIPOD": ("thumb", "index", "middle"), "WRAP": FINGERS, "DISK": FINGERS}
# thresholds relative to the hand's size (wrist to middle fingertip, ~0.19 m on an adult)
TOO_SMALL = 0.12  # below this every shape is pinched ("if the primitive is too small, pinch")
SMALL = 0.22  # "small diameter" of a cylinder or frustum: pinch
SPHERE_SMALL = 0.3  # "small diameter" of a sphere: tripod
THIN = 0.08  # a box this thin is held laterally
TOO_LARGE = 0.6  # above this across every grip direction, two hands
FLAT = 0.45  # a cylinder whose height is under this share of its diameter is a disk


@dataclass
class HandGeometry:
    """The hand in its own bone frame: palm centre, palm normal, across (index to pinky) and
    along (fingers) axes; size = wrist to middle fingertip."""
    palm: np.ndarray
    normal: np.ndarray
    across: np.ndarray
    along: np.ndarray
    size: float
    palm_radius: float


def hand_geometry(skeleton, side, world):
    hand = skeleton.role_index(sided("hand", side))
    h = world[hand]
    inv = rigid_inv(h)

    def local(p):
        return inv[:3, :3] @ p + inv[:3, 3]

    roots = {f: skeleton.index(skeleton.roles.chain(sided(f, side))[0]) for f in FINGERS
             if skeleton.roles.chain(sided(f, side))}
    if not {"thumb", "index", "pinky"} <= set(roots):
        raise HumanAnimError(f"the {side} hand needs thumb, index and pinky finger roles")
    tip = {}
    for f in roots:
        last = skeleton.index(skeleton.roles.chain(sided(f, side))[-1])
        tip[f] = local(world[last][:3, :3] @ [0, skeleton.lengths[last], 0] + world[last][:3, 3])
    root = {f: local(world[j][:3, 3]) for f, j in roots.items()}
    knuckles = np.mean([root[f] for f in roots if f != "thumb"], axis=0)
    palm = 0.5 * knuckles + 0.5 * np.array([0, 0.45 * skeleton.lengths[hand], 0])
    along = knuckles / np.linalg.norm(knuckles)
    across = root["pinky"] - root["index"]
    across -= along * (across @ along)
    across /= np.linalg.norm(across)
    normal = cross(along, across)
    # the palm is the side the thumb's tip lies on
    if normal @ (tip["thumb"] - palm) < 0:
        normal = -normal
    mid = "middle" if "middle" in tip else "index"
    size = float(np.linalg.norm(tip[mid]))
    return HandGeometry(palm, normal, across, along, size, max(0.008, 0.18 * skeleton.lengths[hand]))


def grasp_type(shape, hand_size):
    """The table of sec. 4.3.2 -> (type, hands)."""
    dims = np.sort(dimensions(shape)) / hand_size
    k = kind(shape)
    if k == "SPHERE":
        d = dims[0]
        if d > TOO_LARGE:
            return "WRAP", 2
        return ("PINCH" if d < TOO_SMALL else "TRIPOD" if d < SPHERE_SMALL else "WRAP"), 1
    if k == "BOX":
        if dims[0] > TOO_LARGE:
            return "WRAP", 2
        if dims[2] < TOO_SMALL:
            return "PINCH", 1
        return ("LATERAL" if dims[0] < THIN else "PINCH"), 1
    d = 2 * max(shape.radius, getattr(shape, "r0", 0.0), getattr(shape, "r1", 0.0)) / hand_size
    h = 2 * shape.half / hand_size
    if min(d, h) > TOO_LARGE:
        return "WRAP", 2
    if max(d, h) < TOO_SMALL:
        return "PINCH", 1
    if h < FLAT * d and d >= SMALL:
        return "DISK", 1
    return ("PINCH" if d < SMALL else "WRAP"), 1


def rigid_inv(m):
    out = np.eye(4)
    out[:3, :3] = m[:3, :3].T
    out[:3, 3] = -m[:3, :3].T @ m[:3, 3]
    return out


# --- hand motion patterns --------------------------------------------------------------------
CLOSE_ANGLES = {  # radians of flexion at the end of the built-in pattern, per phalanx
    "WRAP": (1.6, 1.7, 1.2), "DISK": (1.2, 1.3, 1.0), "PINCH": (1.1, 1.2, 0.9),
    "TRIPOD": (1.1, 1.2, 0.9), "LATERAL": (1.3, 1.5, 1.1)}
OPEN_HAND = {"thumb": -0.5, "index": -0.1, "middle": -0.1, "ring": -0.1, "pinky": -0.1}  # pre-shape shares
REST_CURL = 0.5  # fingers the type does not use curl this share of the way


def builtin_pattern(skeleton, side, world, geom, gtype, centre_local, unused_curl=None, basis=None, scales=None):
    """Target local rotations (J, 3, 3) of the finger bones: each phalanx turns about the axis
    that brings its finger's tip toward the grasp centre (in front of the palm), so fingers curl
    onto the object and the thumb opposes them."""
    hand = skeleton.role_index(sided("hand", side))
    h = world[hand]
    centre = h[:3, :3] @ centre_local + h[:3, 3]
    across_w = h[:3, :3] @ geom.across
    used = TYPE_FINGERS[gtype]
    normal_w = h[:3, :3] @ geom.normal
    joints, tips, aims, uses, angle = [], [], [], [], []
    for f in FINGERS:
        names = skeleton.roles.chain(sided(f, side))
        if not names:
            continue
        idx = [skeleton.index(n) for n in names]
        last = idx[-1]
        tip = world[last][:3, :3] @ [0, skeleton.lengths[last], 0] + world[last][:3, 3]
        share = 1.0 if f in used else REST_CURL if unused_curl is None else unused_curl
        if scales is not None:
            share = scales.get(f, share)
        angles = CLOSE_ANGLES[gtype]
        if f == "thumb":
            angles = tuple(0.7 * a for a in angles)
        # each finger curls in its own plane toward the centre (the centre moved across the
        # palm to the finger's knuckle); unused fingers curl toward the palm, out of the way
        aim = centre + across_w * (across_w @ (world[idx[0]][:3, 3] - centre)) if gtype in ("WRAP", "DISK") \
            and f != "thumb" else centre
        for k, j in enumerate(idx):
            joints.append(j)
            tips.append(tip)
            aims.append(aim)
            uses.append(f in used)
            angle.append(share * angles[min(k, len(angles) - 1)])
    if not joints:
        return {}
    # every phalanx at once: the axis turning its finger's tip toward the aim (or the palm)
    joints = np.array(joints)
    p = world[joints, :3, 3]
    tips = np.array(tips)
    to_palm = cross(tips - p, normal_w)
    axis = np.where(np.array(uses)[:, None], cross(tips - p, np.array(aims) - p), to_palm)
    axis = np.where((np.linalg.norm(axis, axis=1) < 1e-9)[:, None], to_palm, axis)
    axis /= np.linalg.norm(axis, axis=1)[:, None]
    local_axis = (np.swapaxes(world[joints, :3, :3], 1, 2) @ axis[:, :, None])[..., 0]
    turn = ik.rodrigues(local_axis * np.array(angle)[:, None])
    start = np.broadcast_to(np.eye(3), turn.shape) if basis is None else basis[joints, :3, :3]
    rots = start @ turn
    return {int(j): rots[k] for k, j in enumerate(joints)}


def pattern_from_pose(skeleton, side, pose_basis):
    """A pose from the animator's library as a pattern: the finger bones' local rotations."""
    out = {}
    for f in FINGERS:
        for n in skeleton.roles.chain(sided(f, side)):
            j = skeleton.index(n)
            out[j] = np.asarray(pose_basis[j])[:3, :3]
    return out


PINCHES = ("PINCH", "TRIPOD", "LATERAL")
APPROACH = 0.06  # metres the palm backs off along its normal before the final approach


def _flexion_axis(skeleton, j, world, normal_w, tip):
    """The bone's local axis closest to its flexion axis (the one that curls the tip palmward)."""
    axis = cross(tip - world[j][:3, 3], normal_w)
    local = world[j][:3, :3].T @ axis
    return int(np.argmax(np.abs(local)))


def pinch_pattern(skeleton, side, basis, world, geom, gtype, aperture, point_local=None):
    """The built-in pattern of a pinch, tripod or lateral grasp: the used fingertips meet at a
    point in front of the index (found by IK on each finger: flexion at every phalanx, spread at
    the knuckle, all three axes at the thumb's base; the thumb first, the others meet its tip);
    the other fingers curl toward the palm. The pre-shape opens the used tips `aperture` apart
    from the meeting point along the pinch axis, so they close onto the object from both sides.
    Returns (closed pattern, pre-shape, meeting point and pinch axis in the hand's frame)."""
    return pinch_open(pinch_closed(skeleton, side, basis, world, geom, gtype, point_local), basis, aperture)


@dataclass
class PinchClosed:
    """The closed part of a pinch pattern, which does not depend on the aperture."""
    pattern: dict
    solvers: dict  # finger -> (chain, base, closed basis)
    tips: dict
    used: list
    normal_w: np.ndarray
    meet_local: np.ndarray
    u_w: np.ndarray
    hand_inv: np.ndarray


def pinch_closed(skeleton, side, basis, world, geom, gtype, point_local=None, warm=None):
    """The closed pinch pattern (see `pinch_pattern`); `warm` (an earlier PinchClosed of the same
    hand) starts each finger's IK from its closed pose there."""
    hand = skeleton.role_index(sided("hand", side))
    h = world[hand]
    if point_local is None:
        point_local = geom.palm + geom.along * (0.3 * geom.size) + geom.normal * (0.2 * geom.size)
    point = h[:3, :3] @ point_local + h[:3, 3]
    normal_w = h[:3, :3] @ geom.normal
    across_w = h[:3, :3] @ geom.across
    pattern = builtin_pattern(skeleton, side, world, geom, gtype, point_local, unused_curl=0.0, basis=basis)
    chains = finger_chains(skeleton, side)
    used = [f for f in sorted(TYPE_FINGERS[gtype], key=lambda f: f != "thumb") if f in chains]
    solvers, tips, open_tip = {}, {}, {}
    for f in used:
        chain = chains[f]
        last = chain[-1]
        tip = world[last][:3, :3] @ [0, skeleton.lengths[last], 0] + world[last][:3, 3]
        allowed = {}
        for k, j in enumerate(chain):
            fa = _flexion_axis(skeleton, j, world, normal_w, tip)
            allowed[j] = (0, 1, 2) if (f == "thumb" and k == 0) else (fa, 2 if fa != 2 else 0) if k == 0 else (fa,)
        ch = ik.Chain(skeleton, chain, last, np.array([0, 0.8 * skeleton.lengths[last], 0]), allowed=allowed)
        base = world[skeleton.parents[chain[0]]]
        target = point + (across_w * 0.016 if f == "middle" else 0.0)
        start = basis if warm is None or f not in warm.solvers else warm.solvers[f][2]
        res = ik.solve(ch, start, base, target, iterations=60)
        for j in chain:
            pattern[j] = res.basis[j, :3, :3]
        tips[f] = ch.effector(ch.frames(ch.euler(res.theta, start), start, base)[0])[0]
        open_tip[f] = ch.effector(ch.frames(ch.euler(ch.angles(basis), basis), basis, base)[0])[0]
        solvers[f] = (ch, base, res.basis)
        if f == "thumb":
            point = tips[f]
    meet = np.mean(list(tips.values()), axis=0)
    # pinch axis: from the thumb's tip toward the opposing fingers' tips, at the open hand
    others = [f for f in used if f != "thumb"]
    u = np.mean([open_tip[f] for f in others], axis=0) - open_tip.get("thumb", meet) if others and "thumb" in used \
        else normal_w
    u = u - normal_w * (u @ normal_w) * 0.5
    u /= np.linalg.norm(u)
    inv = rigid_inv(h)
    return PinchClosed(pattern, solvers, tips, used, normal_w, inv[:3, :3] @ meet + inv[:3, 3], u, inv)


def pinch_open(closed, basis, aperture, warm=None):
    """The pre-shape of a closed pinch pattern at an aperture: (closed pattern, pre-shape, meeting
    point and pinch axis in the hand's frame). `warm` (a pre-shape at another aperture) starts
    the fingers' IK there."""
    preshape = dict(closed.pattern)  # the fingers the type does not use stay open, out of the way
    u, normal_w = closed.u_w, closed.normal_w
    for f in closed.used:
        ch, base, shut = closed.solvers[f]
        sign = -1.0 if f == "thumb" else 1.0
        start = shut
        if warm is not None:
            start = shut.copy()
            for j in ch.joints:
                start[j, :3, :3] = warm[j]
        res = ik.solve(ch, start, base, closed.tips[f] + sign * u * aperture - normal_w * 0.3 * aperture,
                       iterations=60)
        for j in ch.joints:
            preshape[j] = res.basis[j, :3, :3]
    return dict(closed.pattern), preshape, closed.meet_local, closed.hand_inv[:3, :3] @ u


# --- closing with sensors ----------------------------------------------------------------
def finger_chains(skeleton, side):
    return {f: [skeleton.index(n) for n in skeleton.roles.chain(sided(f, side))] for f in FINGERS
            if skeleton.roles.chain(sided(f, side))}


def _finger_world(skeleton, chain, world, basis_rots, basis, rest_local=None):
    rest_local = skeleton.rest_local if rest_local is None else rest_local
    out = {}
    for j in chain:
        p = skeleton.parents[j]
        parent = out[p] if p in out else world[p]
        b = basis[j].copy()
        b[:3, :3] = basis_rots[j]
        out[j] = parent @ rest_local[j] @ b
    return out


def _sensor_depths(skeleton, sensors, frames, shapes):
    pts = np.array([frames[s.joint][:3, :3] @ (np.array([0, s.along * skeleton.lengths[s.joint], 0]) + s.offset)
                    + frames[s.joint][:3, 3] for s in sensors])
    radii = np.array([s.radius for s in sensors])
    if not shapes:
        return np.full(len(sensors), -np.inf)
    return np.max([radii - sh.distance(pts) for sh in shapes], axis=0)


def close_fingers(skeleton, side, basis, world, pattern, shapes, frames=12, tolerance=0.0003, sensors=None):
    """Fingers move from their current rotations toward the pattern's (slerp, one share per DOF
    group) over `frames` steps; a sensor within `tolerance` of the object stops its bone and that
    bone's ancestors in the finger, the others go on. Returns the per-frame finger rotations
    {joint: (frames+1, 3, 3)}, the touching sensors and their depths."""
    return close_hands(skeleton, {side: (pattern, sensors)}, basis, world, shapes, frames, tolerance)[side]


def close_hands(skeleton, hands, basis, world, shapes, frames=12, tolerance=0.0003):
    """close_fingers for several hands ({side: (pattern, sensors or None)}): the fingers of every
    hand whose chains have the same length close together, one batch per length. Returns
    {side: (track, touching, sensors)}."""
    out, groups = {}, {}
    for side, (pattern, sensors) in hands.items():
        out[side] = ({}, {}, sensors or default_hand_sensors(skeleton, side))
        for chain in finger_chains(skeleton, side).values():
            groups.setdefault(len(chain), []).append((side, chain))
    patterns = {j: r for pattern, _ in hands.values() for j, r in pattern.items()}
    sensors = [x for _, _, hand_sensors in out.values() for x in hand_sensors]
    for members in groups.values():
        group = _FingersClose(skeleton, [c for _, c in members], basis, world, patterns, sensors, shapes)
        shares = group.close(frames, tolerance, [out[side][1] for side, _ in members])  # (frames+1, F, n)
        rots = group.rotations(shares)
        for fi, (side, chain) in enumerate(members):
            for k, j in enumerate(chain):
                out[side][0][j] = rots[:, fi, k]
    return out


class _FingersClose:
    """The closing of fingers with chains of one length (sec. 4.3.4): each bone's share of its way
    from its start rotation to the pattern's; forward kinematics and sensor depths for many
    share arrays (..., F, n) at once."""

    SAMPLES = np.arange(1, 16) / 16.0  # the first touch within a step: 15 samples a level ...
    REFINE = 2  # ... refined once (1/256 of the step: ~0.03 mm of a fingertip's way)

    def __init__(self, skeleton, chains, basis, world, pattern, sensors, shapes):
        self.chains, self.shapes = chains, shapes
        nf, n = len(chains), len(chains[0])
        self.start = np.array([[basis[j, :3, :3] for j in c] for c in chains])  # (F, n, 3, 3)
        self.rel = np.array([[ik.rot_log(basis[j, :3, :3].T @ pattern.get(j, basis[j, :3, :3])) for j in c]
                             for c in chains])
        rest = np.array([skeleton.rest_local[c] for c in chains])
        self.rest_r, self.rest_t = rest[..., :3, :3], rest[..., :3, 3]
        self.bt = np.array([basis[c, :3, 3] for c in chains])
        # parent of each bone: its index in the finger, or -1 with the (fixed) frame it hangs from
        self.parent = np.array([[c.index(skeleton.parents[j]) if skeleton.parents[j] in c else -1 for j in c]
                                for c in chains])
        self.outer = np.array([[world[skeleton.parents[j]] for j in c] for c in chains])  # (F, n, 4, 4)
        self.sensors = [[x for x in sensors if x.joint in c] for c in chains]
        smax = max(1, max(len(x) for x in self.sensors))
        self.pos = np.zeros((nf, smax), int)
        self.local = np.zeros((nf, smax, 3))
        self.radii = np.full((nf, smax), -np.inf)  # padding never touches
        for fi, (c, ss) in enumerate(zip(chains, self.sensors)):
            if ss:
                self.pos[fi, :len(ss)] = [c.index(x.joint) for x in ss]
                self.local[fi, :len(ss)] = sensor_layout(ss, skeleton)[1]
                self.radii[fi, :len(ss)] = [x.radius for x in ss]
        self._fi = np.arange(nf)[:, None]
        self.n = n
        self.path = bool(np.all(self.parent == np.arange(n) - 1))
        # exp(s rel) = I + sin(s th) K + (1 - cos(s th)) K^2 (K the unit axis's cross matrix):
        # with the start and rest rotations folded in, a pose is three matrices' blend per bone
        self.th = np.linalg.norm(self.rel, axis=-1)
        axis = self.rel / np.where(self.th > 1e-12, self.th, 1.0)[..., None]
        kk = np.zeros(axis.shape + (3,))
        kk[..., 0, 1], kk[..., 0, 2], kk[..., 1, 2] = -axis[..., 2], axis[..., 1], -axis[..., 0]
        kk = kk - np.swapaxes(kk, -1, -2)
        self.s0, self.s1, self.s2 = self.start, self.start @ kk, self.start @ kk @ kk
        self.a0, self.a1, self.a2 = self.rest_r @ self.s0, self.rest_r @ self.s1, self.rest_r @ self.s2
        self.off = self.rest_t + (self.rest_r @ self.bt[..., None])[..., 0]

    def rotations(self, shares):
        """(..., F, n, 3, 3) rotations of share arrays (..., F, n)."""
        a = np.asarray(shares) * self.th
        return self.s0 + np.sin(a)[..., None, None] * self.s1 + (1.0 - np.cos(a))[..., None, None] * self.s2

    def depth(self, shares):
        """(M, F, S) sensor depths in the objects (positive inside) of share arrays (M, F, n)."""
        if self.path:  # each bone hangs from the one before, the first from the hand
            a = np.asarray(shares) * self.th
            loc = self.a0 + np.sin(a)[..., None, None] * self.a1 + (1.0 - np.cos(a))[..., None, None] * self.a2
            wr, wp = np.empty(loc.shape), np.empty(loc.shape[:-1])
            pr, pp = self.outer[:, 0, :3, :3], self.outer[:, 0, :3, 3]
            for k in range(self.n):
                wp[:, :, k] = (pr @ self.off[:, k, :, None])[..., 0] + pp
                pr = wr[:, :, k] = pr @ loc[:, :, k]
                pp = wp[:, :, k]
            return self._depths(wr, wp)
        rots = self.rotations(shares)
        wr, wp = np.empty(rots.shape), np.empty(rots.shape[:-1])
        fi = np.arange(len(self.chains))
        for k in range(self.n):
            p = self.parent[:, k]
            inner = p >= 0
            pr = np.where(inner[:, None, None], wr[:, fi, np.maximum(p, 0)], self.outer[:, k, :3, :3])
            pp = np.where(inner[:, None], wp[:, fi, np.maximum(p, 0)], self.outer[:, k, :3, 3])
            r = pr @ self.rest_r[:, k]
            wp[:, :, k] = (pr @ self.rest_t[:, k, :, None])[..., 0] + pp + (r @ self.bt[:, k, :, None])[..., 0]
            wr[:, :, k] = r @ rots[:, :, k]
        return self._depths(wr, wp)

    def _depths(self, wr, wp):
        sr, sp = wr[:, self._fi, self.pos], wp[:, self._fi, self.pos]  # (M, F, S, ...)
        pts = (sr @ self.local[..., None])[..., 0] + sp
        if not self.shapes:
            return np.full(pts.shape[:-1], -np.inf)
        d = self.radii - self.shapes[0].distance(pts)  # the padding's radius -inf keeps it -inf
        for sh in self.shapes[1:]:
            d = np.maximum(d, self.radii - sh.distance(pts))
        return d

    def close(self, frames, tolerance, touching):
        """The shares (frames+1, F, n); touching[f] (a dict per finger) gets its touching sensors."""
        nf = len(self.chains)
        share = np.zeros((nf, self.n))
        moving = np.ones((nf, self.n), bool)
        out = [share.copy()]
        step = 1.0 / frames
        m0 = self.SAMPLES
        k = np.arange(nf)
        d_share = None  # the depths at `share`, once needed
        for _ in range(frames):
            trial = np.where(moving, np.minimum(1.0, share + step), share)
            d = self.depth(trial[None])[0]  # (F, S)
            hit = d.max(axis=1) > 0
            if hit.any():
                # the first touch between share and trial, per finger that would sink in; the
                # depths at the last sample before it (`lo`) are the new pose's
                if d_share is None:
                    d_share = self.depth(share[None])[0]
                lo, hi, d_lo = np.zeros(nf), np.ones(nf), d_share
                for _ in range(self.REFINE):
                    m = lo[None] + (hi - lo)[None] * m0[:, None]  # (K, F)
                    dm = self.depth(share[None] + m[..., None] * (trial - share)[None])  # (K, F, S)
                    dd = dm.max(axis=2) > 0
                    first = np.where(dd.any(axis=0), np.argmax(dd, axis=0), len(m0))
                    lo = np.where(first > 0, m[np.maximum(first - 1, 0), k], lo)
                    d_lo = np.where((first > 0)[:, None], dm[np.maximum(first - 1, 0), k], d_lo)
                    hi = np.where(first < len(m0), m[np.minimum(first, len(m0) - 1), k], hi)
                trial = np.where(hit[:, None], share + lo[:, None] * (trial - share), trial)
                d = np.where(hit[:, None], d_lo, d)
            share, d_share = trial, d
            for fi, si in zip(*np.nonzero(d > -tolerance)):
                sensor = self.sensors[fi][si]
                touching[fi][sensor.name] = float(d[fi, si])
                # the touching bone and its ancestors in the finger stop
                j = self.pos[fi, si]
                while j >= 0:
                    moving[fi, j] = False
                    j = self.parent[fi, j]
            moving &= share < 1.0
            out.append(share.copy())
        return np.array(out)


# --- reach: PD servo per DOF (eq. 4-1) -------------------------------------------------------
def pd_servo(q0, qd, frames, fps, qd_vel=None, damping=1.0, settle=10.0):
    """Each DOF driven by tau = k (qd - q) + kv (qd' - q') on a unit inertia, critically damped,
    its gain set so the move settles within the duration (omega T = `settle`); the last frame
    holds the target exactly."""
    q0, qd = np.asarray(q0, float), np.asarray(qd, float)
    vd = np.zeros_like(qd) if qd_vel is None else np.asarray(qd_vel, float)
    duration = frames / fps
    omega = settle / duration
    k, kv = omega ** 2, 2 * damping * omega
    sub = 8
    dt = 1.0 / (fps * sub)
    if qd_vel is None:
        # every DOF has the same gains and a still goal: the substep is one linear map of
        # (q - qd, v), the same for all; its powers give the trajectory without a loop over DOFs
        a = np.array([[1.0 - k * dt * dt, (1.0 - kv * dt) * dt], [-k * dt, 1.0 - kv * dt]])
        step = np.linalg.matrix_power(a, sub)
        c, m = np.empty(frames + 1), np.eye(2)
        c[0] = 1.0
        for t in range(1, frames + 1):
            m = step @ m
            c[t] = m[0, 0]
        out = qd + c[:, None] * (q0 - qd)
        out[-1] = qd
        return out
    q, v = q0.copy(), np.zeros_like(q0)
    out = [q.copy()]
    for _ in range(frames):
        for _ in range(sub):
            tau = k * (qd - q) + kv * (vd - v)
            v = v + tau * dt  # semi-implicit Euler
            q = q + v * dt
        out.append(q.copy())
    out[-1] = qd.copy()
    return np.array(out)


# --- grasp frame ----------------------------------------------------------------------------
@dataclass
class Candidate:
    hand_world: np.ndarray  # goal frame of the hand bone
    grip: np.ndarray  # object frame in the hand bone's frame
    cost: float


def extent_along(shape, u):
    """Half extent of a shape along a world direction (or directions (..., 3))."""
    f = shape_frame(shape)[:3, :3]
    u = np.asarray(u, float)
    lu = u @ f  # f.T @ u, for any leading dimensions
    if isinstance(shape, Sphere):
        return shape.radius if u.ndim == 1 else np.full(u.shape[:-1], shape.radius)
    if isinstance(shape, Box):
        out = np.abs(lu) @ np.asarray(shape.half)
    else:
        r = max(shape.radius, getattr(shape, "r0", 0.0), getattr(shape, "r1", 0.0))
        out = r * np.sqrt(np.maximum(0.0, 1 - lu[..., 2] ** 2)) + shape.half * np.abs(lu[..., 2])
    return float(out) if u.ndim == 1 else out


def candidates(shape, gtype, geom, current_hand, eye, body_centre, sensors_local, anchor=None, pinch_axis=None):
    """Candidate hand frames over the object's symmetry (contact faces), filtered by the thesis's
    rules and ranked by the weighted change from the current hand frame."""
    f = shape_frame(shape)
    axes = f[:3, :3]
    out = []
    dirs = []
    if isinstance(shape, Sphere):
        # palm normals over the sphere (4 latitudes x 8 longitudes), 6 rolls about each
        th, ph, roll = np.meshgrid(np.linspace(0, np.pi, 6)[1:-1], np.linspace(0, 2 * np.pi, 9)[:-1],
                                   np.linspace(0, 2 * np.pi, 7)[:-1], indexing="ij")
        th, ph, roll = th.ravel(), ph.ravel(), roll.ravel()
        n = np.stack((np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)), axis=-1)
        t1 = cross(n, [0, 0, 1.0])
        t1 /= np.linalg.norm(t1, axis=1)[:, None]
        t2 = cross(n, t1)
        dirs = list(zip(n, np.cos(roll)[:, None] * t1 + np.sin(roll)[:, None] * t2))
    elif isinstance(shape, Box):
        for a in range(3):
            for s in (-1, 1):
                n = axes[:, a] * s
                for b in range(3):
                    if b != a:
                        for t in (-1, 1):
                            dirs.append((n, axes[:, b] * t))
    else:
        z = axes[:, 2]
        if gtype == "DISK":
            for s in (-1, 1):
                for roll in np.linspace(0, 2 * np.pi, 13)[:-1]:
                    dirs.append((z * s, np.cos(roll) * axes[:, 0] + np.sin(roll) * axes[:, 1]))
        else:
            for ang in np.linspace(0, 2 * np.pi, 17)[:-1]:
                n = np.cos(ang) * axes[:, 0] + np.sin(ang) * axes[:, 1]
                for s in (-1, 1):
                    dirs.append((n, z * s))
    cur_palm = current_hand[:3, :3] @ geom.palm + current_hand[:3, 3]
    if not dirs:
        return out
    # every direction at once: the hand frame of each (the palm normal n, the across axis a)
    n = np.array([d[0] for d in dirs], float)
    a = np.array([d[1] for d in dirs], float)
    a = a - n * np.sum(a * n, axis=1)[:, None]
    keep = np.linalg.norm(a, axis=1) >= 1e-6
    n, a = n[keep], a[keep] / np.linalg.norm(a[keep], axis=1)[:, None]
    local_axes = np.column_stack((geom.normal, geom.across, geom.along))
    along_w = np.sign(np.linalg.det(local_axes)) * cross(n, a)
    rot = np.stack((n, a, along_w), axis=-1) @ local_axes.T  # (D, 3, 3)
    anchor_l = geom.palm if anchor is None else anchor
    off0 = 0.0 if anchor is not None else max(0.0, float(-shape.distance(f[:3, 3]))) + geom.palm_radius
    t0 = f[:3, 3] - rot @ anchor_l  # the hand's origin at offset 0; an offset moves it along -n
    off = _offsets_clear(shape, rot, t0, n, off0, sensors_local)
    trans = t0 - n * off[:, None]
    palm_w = rot @ geom.palm + trans
    # the palm must not face away from the body: its normal points from the palm toward the object
    away = palm_w - body_centre
    away[:, 2] = 0.0
    an = np.linalg.norm(away, axis=1)
    facing = np.sum(n * away, axis=1) / np.where(an > 1e-6, an, 1.0)
    ok = ~((an > 1e-6) & (facing > 0.5))
    # the thumb stays on the visible side: the thumb side (-across) faces the eye
    thumb_dir = -(rot @ geom.across)
    to_eye = eye - palm_w
    ok &= ~(np.sum(thumb_dir * to_eye, axis=1) < -0.2 * np.linalg.norm(to_eye, axis=1))
    dt = np.linalg.norm(palm_w - cur_palm, axis=1)
    dr = ik.rot_angle(rot @ current_hand[:3, :3].T)
    cost = dt + 0.1 * dr
    if pinch_axis is not None:  # pinch across the object's thinnest side
        cost = cost + 2.0 * (extent_along(shape, rot @ pinch_axis) - 0.5 * float(np.sort(dimensions(shape))[0]))
    order = np.flatnonzero(ok)[np.argsort(cost[ok], kind="stable")]
    hw = np.zeros((len(order), 4, 4))
    hw[:, :3, :3], hw[:, :3, 3], hw[:, 3, 3] = rot[order], trans[order], 1.0
    inv = np.zeros_like(hw)  # the hands' inverses, all at once
    inv[:, :3, :3] = np.swapaxes(rot[order], 1, 2)
    inv[:, :3, 3] = -(inv[:, :3, :3] @ trans[order][:, :, None])[..., 0]
    inv[:, 3, 3] = 1.0
    grips = inv @ f
    return [Candidate(hw[i], grips[i], float(cost[k])) for i, k in enumerate(order)]


def _offsets_clear(shape, rot, t0, n, start, sensors_local, step=0.003, tries=60):
    """Per hand frame, move the object away from the palm (the hand back along -n) in `step`s
    until no hand sensor penetrates it (the thesis moves the origin toward the border until no
    collision); all frames at once. The primitives' distances are exact (they change no faster
    than the point moves), so the steps that cannot clear the deepest sensor are skipped: the
    same first clear step, without testing the ones before it."""
    pts0 = (rot[:, None] @ sensors_local[None, :, :3, None])[..., 0] + t0[:, None]  # (D, S, 3) at offset 0
    radii = sensors_local[:, 3]
    offs = np.empty(tries)  # the offsets tried, summed step by step as the search walks
    v = float(start)
    for k in range(tries):
        offs[k] = v
        v += step
    dist0 = shape.distance(pts0 - n[:, None] * offs[0])
    need = (radii + 0.001 - dist0).max(axis=1, initial=-np.inf) / np.maximum(np.linalg.norm(n, axis=1), 1e-12)
    k = np.where(need > 1e-9, np.floor((need - 1e-9) / step) + 1, 0).astype(int)
    k = np.minimum(k, tries - 1)  # none clear within the tries: the last one tried
    todo = (k < tries - 1) & ~((k == 0) & np.all(dist0 - radii > 0.001, axis=-1))
    while True:
        idx = np.flatnonzero(todo)
        if not len(idx):
            break
        p = pts0[idx] - n[idx, None] * offs[k[idx], None, None]
        clear = np.all(shape.distance(p) - radii > 0.001, axis=-1)
        last = k[idx] >= tries - 1
        todo[idx[clear | last]] = False
        k[idx[~clear & ~last]] += 1
    return offs[k]


def _shape_normal(shape, p, h=1e-5):
    g = np.array([(shape.distance(p + e) - shape.distance(p - e)) / (2 * h) for e in np.eye(3) * h])
    n = np.linalg.norm(g)
    return g / n if n > 1e-12 else np.array([0.0, 0.0, 1.0])


def _keep_off_object(skeleton, frames, armature_to_world, side, chain, shape, reach_frames, margin=0.003,
                     sensors=None, world=None, moved=()):
    """On the way in, a hand sensor that would pass through the object gives the hand a
    temporary goal pushed out along the surface normal (sec. 4.6.3's alternative, applied to the
    object); the last frame (the grasp itself) is left alone. `world` is the world of
    `frames[0]`, where the frames differ from it only in the chain and the bones `moved`."""
    sensors = sensors or default_hand_sensors(skeleton, side)
    radii = np.array([x.radius for x in sensors])
    hand = skeleton.role_index(sided("hand", side))
    if reach_frames < 2:
        return
    # every frame of the way in at once: only the chain and the hand below it move
    if world is None:
        world = skeleton.world_frames(frames[0], armature_to_world)
    span = frames[1:reach_frames]
    w_all = ik.update_world(skeleton, span, world, chain.joints + moved, armature_to_world=armature_to_world)
    depth_all = radii - shape.distance(sensor_centres(sensors, w_all, skeleton))
    for t in 1 + np.flatnonzero(depth_all.max(axis=1) > 0):
        w = w_all[t - 1]
        for _ in range(6):
            pts = sensor_centres(sensors, w, skeleton)
            depth = radii - shape.distance(pts)
            k = int(np.argmax(depth))
            if depth[k] <= 0:
                break
            push = _shape_normal(shape, pts[k]) * (depth[k] + margin)
            goal = w[hand].copy()
            goal[:3, 3] += push
            base = ik.chain_base(chain, w)
            res = ik.solve(chain, frames[t], base, goal[:3, 3], goal[:3, :3], iterations=30)
            frames[t] = res.basis
            w = ik.update_world(skeleton, frames[t], w, chain.joints, armature_to_world=armature_to_world)


# --- the whole grasp ------------------------------------------------------------------------
@dataclass
class HandGrasp:
    side: str
    grip: np.ndarray  # object frame in the hand bone frame
    touching: dict  # sensor name -> depth at the end
    fingers_touching: tuple
    reach_error: float
    sensors: list = field(default_factory=list)


@dataclass
class GraspResult:
    gtype: str
    primitive: str
    hands: list
    basis: np.ndarray  # (frames, J, 4, 4): reach then close
    frame_count: int
    reach_frames: int
    close_frames: int
    world: np.ndarray  # (J, 4, 4) final world frames


def body_landmarks(skeleton, world):
    chest = skeleton.role_index("chest")
    head = skeleton.role_index("head")
    pelvis = skeleton.role_index("pelvis")
    c = world[chest if chest is not None else pelvis][:3, 3]
    eye = world[head][:3, 3] if head is not None else c + [0, 0, 0.4]
    return c, eye


def choose_side(skeleton, world, shape):
    c = shape_frame(shape)[:3, 3]
    d = {s: np.linalg.norm(world[skeleton.role_index(sided("upper_arm", s))][:3, 3] - c) for s in ("L", "R")}
    return min(d, key=d.get)


@dataclass
class HandPlan:
    """One hand's plan before any frame is written: its arm chain, the chosen grip candidate, the
    arm's IK solution at the grip and at the backed-off approach point, and its finger pattern as
    (closed pattern or None, pre-shape)."""
    chain: object
    candidate: object
    solution: object
    geom: object
    pattern: tuple
    approach: object


def _preshape(skeleton, side, basis, world, geom, gtype, shape, pattern):
    """The hand's shape during the reach -> (pattern pair, anchor, pinch axis, first closed pinch).
    A pinch finds where its fingertips meet first (the grip candidates are placed around that
    point); the other types simply open the hand."""
    if gtype not in PINCHES or pattern is not None:
        # the hand opens during the reach: thumb abducted, fingers straight
        guess = geom.palm + geom.normal * 0.05
        preshape = builtin_pattern(skeleton, side, world, geom, gtype, guess, basis=basis, scales=OPEN_HAND)
        return (None, preshape), None, None, None
    aperture = 0.5 * float(np.sort(dimensions(shape))[0]) + 0.015
    first = pinch_closed(skeleton, side, basis, world, geom, gtype)
    closed, preshape, anchor, pinch_axis = pinch_open(first, basis, aperture)
    return (closed, preshape), anchor, pinch_axis, first


def _grip_candidates(skeleton, side, basis, world, geom, gtype, shape, sens, preshape, anchor, pinch_axis,
                     eye, body_c, hands, armature_to_world):
    """The grip frames worth trying, best first, tested for clearance with the pre-shaped hand."""
    hand = skeleton.role_index(sided("hand", side))
    pre = basis.copy()
    for j, r in preshape.items():
        pre[j, :3, :3] = r
    wpre = ik.update_world(skeleton, pre, world, list(preshape), armature_to_world=armature_to_world)
    inv = rigid_inv(wpre[hand])
    cen = sensor_centres(sens, wpre, skeleton) @ inv[:3, :3].T + inv[:3, 3]
    loc = np.column_stack((cen, [x.radius for x in sens]))
    cands = candidates(shape, gtype, geom, world[hand], eye, body_c, loc, anchor, pinch_axis)
    if hands == 2:  # each hand on its own side of the object
        obj_c = shape_frame(shape)[:3, 3]
        lateral = world[skeleton.role_index(sided("upper_arm", side))][:3, 3] - body_c
        lateral[2] = 0
        lateral /= np.linalg.norm(lateral)
        cands = [c for c in cands if (c.hand_world[:3, :3] @ geom.palm + c.hand_world[:3, 3] - obj_c) @ lateral
                 > 0.5 * np.linalg.norm(c.hand_world[:3, :3] @ geom.palm + c.hand_world[:3, 3] - obj_c)]
    return cands


def _best_grip(chain, goal, base, cands, geom):
    """The first candidate the arm reaches exactly (2 mm, 1 degree), else the closest of the first 40."""
    best = None
    for c in cands[:40]:
        target_r = c.hand_world[:3, :3]
        target_p = c.hand_world[:3, :3] @ geom.palm + c.hand_world[:3, 3]
        res = ik.solve(chain, goal, base, target_p, target_r, iterations=80)
        if res.position_error < 0.002 and res.rotation_error < np.radians(1.0):
            return c, res
        if best is None or res.position_error < best[1].position_error:
            best = (c, res)
    if best is None:
        raise HumanAnimError("no grasp frame found for the object")
    return best


def _pinch_at_grip(skeleton, side, basis, world, geom, gtype, shape, sens, goal, chain, grip, pinch_axis, first,
                   armature_to_world):
    """A pinch's fingertips meet inside the object where the chosen grip put it; the pre-shape
    opens 1 cm wider at a time until the pre-shaped fingers clear the object -> (closed, pre-shape)."""
    hand = skeleton.role_index(sided("hand", side))
    hw = ik.update_world(skeleton, goal, world, chain.joints, armature_to_world=armature_to_world)
    aperture = extent_along(shape, hw[hand][:3, :3] @ pinch_axis) + 0.012
    shut = pinch_closed(skeleton, side, basis, world, geom, gtype, grip[:3, 3], warm=first)
    preshape = None
    for _ in range(8):
        closed, preshape, _, _ = pinch_open(shut, basis, aperture, warm=preshape)
        pre = goal.copy()
        for j, r in preshape.items():
            pre[j, :3, :3] = r
        wpre = ik.update_world(skeleton, pre, hw, list(preshape), armature_to_world=armature_to_world)
        depth = np.array([x.radius for x in sens]) - shape.distance(sensor_centres(sens, wpre, skeleton))
        if depth.max() < -0.001:
            break
        aperture += 0.01
    return closed, preshape


def _plan_hand(skeleton, side, basis, world, goal, shape, gtype, hands, pattern, with_spine, eye, body_c,
               hand_sensors, armature_to_world):
    """One hand's grip, arm solution and finger pattern; `goal` is the posture its IK starts from
    (the other hand's solution when both hands grasp)."""
    geom = hand_geometry(skeleton, side, world)
    sens = (hand_sensors or {}).get(side) or default_hand_sensors(skeleton, side)
    fingers, anchor, pinch_axis, first = _preshape(skeleton, side, basis, world, geom, gtype, shape, pattern)
    # the clearance test sees the pre-shaped hand
    cands = _grip_candidates(skeleton, side, basis, world, geom, gtype, shape, sens, fingers[1], anchor, pinch_axis,
                             eye, body_c, hands, armature_to_world)
    chain = ik.Chain.arm(skeleton, side, point=geom.palm, with_spine=with_spine)
    # the chain's base (above the shoulder or the pelvis) is moved by neither arm
    base = ik.chain_base(chain, world)
    c, res = _best_grip(chain, goal, base, cands, geom)
    # the approach: the palm first comes to a point backed off along its normal
    n_w = c.hand_world[:3, :3] @ geom.normal
    target_p = c.hand_world[:3, :3] @ geom.palm + c.hand_world[:3, 3]
    approach = ik.solve(chain, res.basis, base, target_p - n_w * APPROACH, c.hand_world[:3, :3], iterations=40)
    if fingers[0] is not None:
        fingers = _pinch_at_grip(skeleton, side, basis, world, geom, gtype, shape, sens, res.basis, chain, c.grip,
                                 pinch_axis, first, armature_to_world)
    return HandPlan(chain, c, res, geom, fingers, approach)


def _reach(basis, plans, reach_frames, close_frames, fps):
    """The frames of the reach, held through the close: a PD servo per arm DOF toward the approach
    point then the grip, the fingers pre-shaping on the way (a smooth-step slerp)."""
    frames = np.repeat(basis[None], reach_frames + close_frames + 1, axis=0)
    for plan in plans.values():
        chain, res, approach, fingers = plan.chain, plan.solution, plan.approach, plan.pattern
        th0 = chain.angles(basis)
        n1 = max(1, int(round(reach_frames * 0.7)))
        traj = np.vstack((pd_servo(th0, approach.theta, n1, fps),
                          pd_servo(approach.theta, res.theta, reach_frames - n1, fps)[1:]))
        frames[:reach_frames + 1] = chain.apply(traj, frames[:reach_frames + 1])
        frames[reach_frames:] = chain.apply(res.theta, frames[reach_frames])[None]
        if fingers is not None:
            x = np.arange(reach_frames + 1) / reach_frames
            ease = x * x * (3 - 2 * x)
            js = list(fingers[1])
            goal = np.array([fingers[1][j] for j in js])
            rel = np.array([ik.rot_log(basis[j, :3, :3].T @ r) for j, r in zip(js, goal)])  # (B, 3)
            frames[:reach_frames + 1, js, :3, :3] = basis[js, :3, :3] @ ik.rodrigues(ease[:, None, None] * rel)
            frames[reach_frames:, js, :3, :3] = goal
    return frames


def _keep_clear(skeleton, frames, armature_to_world, plans, shape, reach_frames, world, moved, with_spine,
                avoid_body, hand_sensors):
    """The way in keeps the hands out of the object and (with `avoid_body`) the arms out of the
    trunk and head (sec. 4.6); edits `frames` in place."""
    for s, plan in plans.items():
        _keep_off_object(skeleton, frames, armature_to_world, s, plan.chain, shape, reach_frames,
                         sensors=(hand_sensors or {}).get(s), world=world, moved=moved)
    if avoid_body:
        # (the reach moves the arms and fingers only: their share of the kinematics, every frame at once)
        reach = frames[:reach_frames + 1]
        reach_world = ik.update_world(skeleton, reach, world, moved, armature_to_world=armature_to_world)
        frames[:reach_frames + 1], _ = remove_self_collisions(skeleton, reach, armature_to_world,
                                                              sides=tuple(plans), with_spine=with_spine,
                                                              legs=(), world=reach_world)
        frames[reach_frames:] = frames[reach_frames][None]


def _close_fingers(skeleton, frames, plans, shape, gtype, pattern, world_f, hand_sensors, reach_frames,
                   close_frames):
    """The fingers close on the object from the reached posture (the animator's pattern, else the
    pinch's, else the built-in one); writes the closing frames -> one HandGrasp per hand."""
    final = frames[reach_frames]
    closing = {}
    for s, plan in plans.items():
        hand = skeleton.role_index(sided("hand", s))
        centre_local = rigid_inv(world_f[hand]) @ shape_frame(shape)
        pat = pattern if pattern is not None else plan.pattern[0] if plan.pattern[0] is not None else builtin_pattern(
            skeleton, s, world_f, plan.geom, gtype, centre_local[:3, 3], basis=final)
        if pattern is not None and not isinstance(pattern, dict):
            pat = pattern_from_pose(skeleton, s, pattern)
        closing[s] = (pat, (hand_sensors or {}).get(s))
    closed = close_hands(skeleton, closing, final, world_f, [shape], close_frames)
    results = []
    for s, plan in plans.items():
        hand = skeleton.role_index(sided("hand", s))
        track, touching, sensors = closed[s]
        for j, rots in track.items():
            frames[reach_frames:, j, :3, :3] = rots
        fingers = tuple(sorted({x.split(".")[0] for x in touching}))
        results.append(HandGrasp(s, rigid_inv(world_f[hand]) @ shape_frame(shape), touching, fingers,
                                 plan.solution.position_error, sensors))
    return results


def grasp(skeleton, basis, armature_to_world, shape, side="AUTO", gtype=None, reach_frames=24,
          close_frames=12, fps=24.0, pattern=None, with_spine=False, eye=None, two_hands=None, avoid_body=True,
          hand_sensors=None):
    """Reach for and close on `shape` (world). Returns a GraspResult with per-frame bases.
    `hand_sensors` {side: sensors} replaces the bone-sized sensors (e.g. sized from the skin).
    The steps: the grasp type (sec. 4.3.2) and the hands, each hand's plan, the reach, keeping
    clear of the object and the body, then the close."""
    basis = np.array(basis, float)
    world = skeleton.world_frames(basis, armature_to_world)
    side0 = choose_side(skeleton, world, shape) if side in (None, "AUTO") else side
    auto_type, hands = grasp_type(shape, hand_geometry(skeleton, side0, world).size)
    gtype = gtype or auto_type
    if two_hands is not None:
        hands = 2 if two_hands else 1
    sides = [side0] if hands == 1 else ["L", "R"]
    body_c, head = body_landmarks(skeleton, world)
    eye = head if eye is None else np.asarray(eye, float)
    goal = basis.copy()
    plans = {}
    for s in sides:
        plans[s] = _plan_hand(skeleton, s, basis, world, goal, shape, gtype, hands, pattern, with_spine, eye, body_c,
                              hand_sensors, armature_to_world)
        goal = plans[s].solution.basis
    frames = _reach(basis, plans, reach_frames, close_frames, fps)
    moved = sorted({j for p in plans.values() for j in p.chain.joints}
                   | {j for p in plans.values() if p.pattern is not None for j in p.pattern[1]})
    _keep_clear(skeleton, frames, armature_to_world, plans, shape, reach_frames, world, moved, with_spine,
                avoid_body, hand_sensors)
    world_f = ik.update_world(skeleton, frames[reach_frames], world, moved, armature_to_world=armature_to_world)
    results = _close_fingers(skeleton, frames, plans, shape, gtype, pattern, world_f, hand_sensors, reach_frames,
                             close_frames)
    world_end = ik.update_world(skeleton, frames[-1], world, moved, armature_to_world=armature_to_world)
    return GraspResult(gtype, kind(shape), results, frames, reach_frames + close_frames + 1, reach_frames,
                       close_frames, world_end)
