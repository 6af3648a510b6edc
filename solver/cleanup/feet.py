"""Feet on the floor: contacts found from the motion, the floor under them, and foot skate
removed with the legs' analytic IK (motion_control.limb_ik) while the body keeps its path.

Foot points: each foot's ball (the foot bone's tail) and toe tip (the toe bone's tail), as the
motion QA plants them. A point is planted when it is low (within `height_on` of its own lowest
level in the clip) and slow (slower than `speed_on` over the ground), and stays planted until it
rises above `height_off` or moves faster than `speed_off` (hysteresis: motion_control.contacts);
contacts shorter than `min_seconds` are merged into their neighbours.
"""

import numpy as np

from .. import rotations
from ..dynamics.spatial import quat_log
from ..motion_control.contacts import hysteresis, remove_short_runs, runs

HEIGHT_ON, HEIGHT_OFF = 0.03, 0.05  # m above the point's own lowest level
SPEED_ON, SPEED_OFF = 0.3, 0.6  # m/s over the ground
MIN_SECONDS = 0.1
RAMP_SECONDS = 0.15  # the IK correction fades in and out over this time around a contact
FLOOR_PERCENTILE = 10.0


def foot_points(skeleton, world):
    """{side: (F, k, 3)} world points of each foot (ball, toe tip) from world frames (F, J, 4, 4)."""
    out = {}
    for side in ("L", "R"):
        joints = [j for j in (skeleton.role_index(f"{r}.{side}") for r in ("foot", "toe")) if j is not None]
        if joints:
            w = world[:, joints]
            tails = w[..., :3, 3] + w[..., :3, 1] * skeleton.lengths[joints][None, :, None]
            out[side] = tails
    return out


def sole_points(skeleton, world):
    """{side: (F, m, 3)} every point of each foot that must stay on or above the ground: the
    heads and tails of the foot bone and of every bone under it (the ankle, the ball, the toe tip
    and any toe-end bone, whatever role, if any, the rig's toes were given; a Bandai Namco toe
    has none, so its tip is not a foot point). From world frames (F, J, 4, 4)."""
    out = {}
    for side in ("L", "R"):
        foot = skeleton.role_index(f"foot.{side}")
        if foot is None:
            continue
        chain = [foot] + list(skeleton.descendants(foot))
        w = world[:, chain]
        heads = w[..., :3, 3]
        out[side] = np.concatenate((heads, heads + w[..., :3, 1] * skeleton.lengths[chain][None, :, None]), axis=1)
    return out


def lowest_above(points, sole=None, ground=None, shift=None):
    """(F,) the height of a foot's lowest point above the ground under it (heights_above): of its
    foot points (F, k, 3) and, when given, its sole points (F, m, 3, sole_points)."""
    low = heights_above(points, ground, shift).min(axis=1)
    return low if sole is None else np.minimum(low, heights_above(sole, ground, shift).min(axis=1))


def planted_points(points, fps):
    """{side: bool (F, k)} each foot point is planted (low and slow, with hysteresis)."""
    out = {}
    shortest = max(2, int(round(MIN_SECONDS * fps)))
    for side, p in points.items():
        h = p[..., 2] - np.percentile(p[..., 2], 5, axis=0)
        moving = np.gradient(p[..., :2], axis=0) if len(p) > 1 else np.zeros_like(p[..., :2])  # one frame: still
        speed = np.linalg.norm(moving, axis=-1) * fps
        down = hysteresis(h < HEIGHT_ON, speed < SPEED_ON, (h > HEIGHT_OFF) | (speed > SPEED_OFF))
        out[side] = np.stack([remove_short_runs(d, shortest) for d in down.T], axis=1)
    return out


def find_contacts(points, fps):
    """{side: bool (F,)} the foot is planted (any of its points). `points` from foot_points."""
    return {side: d.any(axis=1) for side, d in planted_points(points, fps).items()}


def contact_runs(mask):
    return [(a, b) for on, a, b in runs(mask) if on]  # b exclusive


def heights_above(points, ground=None, shift=None):
    """(F, k) height of each foot point above the ground under it (`ground`: a height, a surface
    from solver.cleanup.ground, or None for Z = 0), the points first moved by shift (F, 2) over
    the ground; +inf where there is no ground under a point (off a mesh)."""
    from .ground import as_ground
    g = as_ground(0.0 if ground is None else ground)
    xy = points[..., :2] if shift is None else points[..., :2] + shift[:, None, :]
    under = g.height(xy)
    return np.where(np.isfinite(under), points[..., 2] - under, np.inf)


TERRAIN_SECONDS = 0.5  # the body follows a ground's rise and fall smoothed over this time


def terrain_under(points, contacts, ground, fps):
    """(F,) the height of the ground under the planted feet, smoothed over TERRAIN_SECONDS and
    eased between contacts: how far the body rises or falls with a ground that is not flat
    (constant on a flat floor)."""
    from scipy.ndimage import uniform_filter1d
    from .ground import as_ground
    g = as_ground(ground)
    F = len(next(iter(points.values())))
    total, count = np.zeros(F), np.zeros(F)
    for side, p in points.items():
        lowest = p[np.arange(F), p[..., 2].argmin(axis=1)]
        h = g.height(lowest[:, :2])
        use = contacts[side] & np.isfinite(h)
        total[use] += h[use]
        count[use] += 1
    known = count > 0
    if not known.any():
        return np.full(F, np.nan)
    idx = np.arange(F)
    under = np.zeros(F)
    under[known] = total[known] / count[known]
    if not known.all():
        under[~known] = _ease(idx[~known], idx[known], under[known])
    return uniform_filter1d(under, max(1, int(round(TERRAIN_SECONDS * fps))), mode="nearest")


def find_floor(points, contacts=None, ground=None):
    """The floor: a low percentile, over the frames, of the lowest foot point's height (above
    `ground` when given, see heights_above; else its world Z), over the contact frames when
    given, so a few toe dips or a foot through the floor do not set it, and few planted frames
    hover above it (lowering a foot needs a leg that can still stretch)."""
    low = np.min([heights_above(p, ground).min(axis=1) for p in points.values()], axis=0)
    on = np.any([c for c in contacts.values()], axis=0) if contacts else np.ones(len(low), bool)
    if on.sum() < 3:
        on = np.ones(len(low), bool)
    low = low[on & np.isfinite(low)]
    if not len(low):
        from ..errors import MotionError
        raise MotionError("no foot is over the ground: the ground mesh does not lie under the motion")
    return float(np.percentile(low, FLOOR_PERCENTILE))


def _segments(values):
    """Runs (first, end exclusive) of equal consecutive values."""
    cuts = np.flatnonzero(np.diff(values)) + 1
    return list(zip(np.r_[0, cuts], np.r_[cuts, len(values)]))


def _ease(x, xp, fp):
    """Like np.interp, but eased (smoothstep) between known values, so a correction fades in and
    out with no jump in speed."""
    right = np.clip(np.searchsorted(xp, x), 1, len(xp) - 1)
    left = right - 1
    s = np.clip((x - xp[left]) / np.maximum(xp[right] - xp[left], 1e-12), 0.0, 1.0)
    w = s * s * (3 - 2 * s)
    return fp[left] + w * (fp[right] - fp[left])


def _heading(v):
    return np.arctan2(v[..., 1], v[..., 0])


def own_level(low, on):
    """A foot's own level (m) above the floor: the low percentile of its contacts' lowest heights
    `low` (F,) over the contact frames `on`, where at least three contacts all sit higher (a
    marker or a sole placed higher), else 0."""
    lows = [low[a:b].min() for a, b in contact_runs(on)]
    lows = [x for x in lows if np.isfinite(x)]
    return max(0.0, float(np.percentile(lows, FLOOR_PERCENTILE))) if len(lows) >= 3 else 0.0


def own_levels(points, planted, floor, sole=None):
    """{side: own_level} of each foot, its heights taken above a flat `floor` (m): the capture's
    own floor, so a ground that is not flat under the feet is not taken for a foot placed higher.
    `sole`: each foot's sole_points, so its lowest point is the lowest of them all."""
    return {side: own_level(lowest_above(p, (sole or {}).get(side), floor), planted[side].any(axis=1))
            for side, p in points.items()}


def foot_offsets(points, fps, floor=None, skate=True, planted=None, levels=None, sole=None, captured=None):
    """{side: (F, 7)} how to move each foot: a translation (0:3), a turn about the vertical (3)
    and the point it turns about (4:7). Horizontally (skate): while a point of the foot is
    planted, back to where that point landed (the ball while it is down, else the toe tip, so the
    heel can rise and the foot roll); while both are down, the foot turned back to its heading at
    landing. Vertically (with `floor`, a height or a surface from solver.cleanup.ground): each contact moved so its lowest point is on the floor
    (or at the foot's own level, the low percentile of its contacts, where that is higher); a
    contact more than HEIGHT_ON above that stands on something else and is left; a contact
    through the floor is lifted whole. No frame's foot goes below the floor. Faded in and out around each contact. `planted`: the contacts
    (planted_points) when already known, e.g. found before the floor repair flattened them.
    `levels`: each foot's own level (own_levels) when known, e.g. measured on the capture's flat
    floor before the body was put on a ground that is not flat; else measured here. `sole`: each
    foot's sole_points (the ankle, toe ends), kept above the floor with the foot points: a
    contact's lowest point is the lowest of them all. `captured`: {side: (F,)} each foot's lowest
    point above the capture's own flat floor (lowest_above), where a contact's height decides
    whether it stands on something else: a bump under it is not taken for that."""
    ramp = max(1, int(round(RAMP_SECONDS * fps)))
    planted = planted_points(points, fps) if planted is None else planted
    out = {}
    for side, p in points.items():
        F, k = p.shape[:2]
        d = np.zeros((F, 7))
        down = planted[side]
        on = down.any(axis=1)
        pick = np.where(down[:, 0], 0, np.argmax(down, axis=1))  # the ball first
        d[:, 4:7] = p[np.arange(F), pick]
        flat = down.all(axis=1) if k > 1 else np.zeros(F, bool)
        if skate:
            # the held point is held from where it is when it is picked (with the correction then
            # in force), so the foot does not jump when the hold passes from the ball to the toe
            for a, b in contact_runs(on):
                for s, e in _segments(pick[a:b]):
                    s, e = a + s, a + e
                    anchor = p[s, pick[s], :2] + (d[s - 1, :2] if s > a else 0.0)
                    d[s:e, :2] = anchor - p[s:e, pick[s], :2]
            for a, b in contact_runs(flat):
                h = _heading(p[a:b, 1, :2] - p[a:b, 0, :2])
                d[a:b, 3] = np.angle(np.exp(1j * (h[0] - h)))
        if floor is not None:  # planted: each contact's lowest point on the floor (the foot
            # rolls as captured); in the air: never below it. Heights above the ground under
            # each point where the hold puts it.
            low = lowest_above(p, (sole or {}).get(side), floor, d[:, :2])
            # a foot whose contacts all sit higher than the other's (a marker or a sole placed
            # higher) keeps its own level above the floor rather than being pushed to it
            # (seen over several contacts: a single one that hovers is lowered)
            level = own_level(low, on) if levels is None else levels.get(side, 0.0)
            seen = low if captured is None or side not in captured else captured[side]
            for a, b in contact_runs(on):
                gap = low[a:b].min() - level
                # a contact far above the floor stands on something else: left where it is
                # (judged by its height in the capture, so a ground's dip under it is not that)
                above_floor = 0.0 < gap and seen[a:b].min() - level <= HEIGHT_ON
                d[a:b, 2] = -gap if above_floor else max(-low[a:b].min(), 0.0)
            d[~on, 2] = np.maximum(-low[~on], 0.0)
        moved = on | (d[:, 2] > 0)
        # frames more than a ramp from any moved frame ("full" then centred: "same" would be
        # the kernel's length on a clip shorter than the kernel)
        far = np.convolve(moved.astype(float), np.ones(2 * ramp + 1))[ramp:ramp + F] == 0
        idx = np.arange(F)
        for c, known in ((0, moved), (1, moved), (2, moved), (3, flat if skate else moved)):
            known = known | far
            if known.any() and not known.all():
                d[~known, c] = _ease(idx[~known], idx[known], d[known, c])
        if floor is not None:  # a fade that lowers a hovering foot stops at the floor
            d[:, 2] = np.maximum(d[:, 2], -lowest_above(p, (sole or {}).get(side), floor, d[:, :2]))
        out[side] = d
    return out


def _axis_rotation(axis, angle):
    """(F, 3, 3) rotations by `angle` (F,) about unit `axis` (F, 3) (Rodrigues)."""
    k = np.zeros(axis.shape[:-1] + (3, 3))
    k[..., 0, 1], k[..., 0, 2], k[..., 1, 2] = -axis[..., 2], axis[..., 1], -axis[..., 0]
    k -= np.swapaxes(k, -1, -2)
    s, c = np.sin(angle)[..., None, None], np.cos(angle)[..., None, None]
    return np.eye(3) + s * k + (1 - c) * (k @ k)


def _unit(v):
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


def knee_hinge(skeleton, quats, side):
    """The axis (shin bone frame) the knee bends about in this motion: the principal direction of
    its rotation vectors, signed so the mean bend is positive; the bone's X axis (Blender's knee
    axis) for a knee that hardly bends."""
    r = quat_log(quats[:, skeleton.role_index(f"shin.{side}")])
    if np.linalg.norm(r, axis=1).max() < np.radians(5):
        return np.array([1.0, 0.0, 0.0])
    axis = np.linalg.eigh(r.T @ r)[1][:, -1]
    return axis if (r @ axis).mean() >= 0 else -axis


MIN_KNEE_BEND_DEG = 8.0  # a solved stance knee is never straighter than this, or than in the capture
ROOT_EASE_SECONDS = 0.2  # the pelvis is lowered and raised back over about this time
MAX_PELVIS_DROP = 0.03  # m: a foot further out of reach is left hovering (and reported)


def _leg(skeleton, side):
    sk = skeleton
    thigh, shin, foot = (sk.role_index(f"{r}.{side}") for r in ("thigh", "shin", "foot"))
    if None in (thigh, shin, foot) or sk.parents[shin] != thigh or sk.parents[foot] != shin:
        raise ValueError(f"leg {side}: thigh, shin and foot must be a parent-child chain")
    return thigh, shin, foot


def foot_targets(skeleton, world, side, offset):
    """World ankle targets (F, 3) and foot orientations (F, 3, 3) that move the foot by `offset`
    ((F, 3), or (F, 7) from foot_offsets: with a turn about a pivot)."""
    thigh, shin, foot = _leg(skeleton, side)
    ankle = world[:, foot, :3, 3]
    off = np.asarray(offset, float)
    if off.shape[1] < 7:
        off = np.concatenate((off[:, :3], np.zeros((len(off), 1)), ankle), axis=1)
    turn = _axis_rotation(np.broadcast_to([0.0, 0.0, 1.0], (len(off), 3)), off[:, 3])
    pivot = off[:, 4:7]
    return pivot + off[:, :3] + np.einsum("fij,fj->fi", turn, ankle - pivot), turn @ world[:, foot, :3, :3]


def _knee_terms(skeleton, world, side, hinge):
    """Per frame the knee's reach about its hinge: the thigh's and shin's lengths a, b, the
    distance hip-ankle c(t)^2 = a^2 + b^2 + 2 (A + R cos(t - psi)) for a turn t of the shin about
    the hinge (psi: the turn that straightens the leg), and the hinge in the world."""
    thigh, shin, foot = _leg(skeleton, side)
    hip, knee, ankle = (world[:, j, :3, 3] for j in (thigh, shin, foot))
    u, v = knee - hip, ankle - knee
    n = _unit(np.einsum("fij,j->fi", world[:, shin, :3, :3], hinge))
    v_par = np.einsum("fi,fi->f", n, v)[:, None] * n
    A = np.einsum("fi,fi->f", u, v_par)
    B = np.einsum("fi,fi->f", u, v - v_par)
    C = np.einsum("fi,fi->f", u, np.cross(n, v))
    a, b = np.linalg.norm(u, axis=1), np.linalg.norm(v, axis=1)
    return a, b, A, np.hypot(B, C), np.arctan2(C, B), n


def allowed_reach(skeleton, world, side, hinge):
    """(F,) the longest hip-ankle distance a solve may ask of each leg: the knee bent at least
    MIN_KNEE_BEND_DEG, or as much as in the capture where it is straighter (a straight stance leg
    asked to stretch further would snap straight: a knee pop)."""
    a, b, A, R, psi, _ = _knee_terms(skeleton, world, side, hinge)
    bend = np.abs(np.angle(np.exp(-1j * psi)))
    least = np.minimum(bend, np.radians(MIN_KNEE_BEND_DEG))
    return np.sqrt(np.maximum(a * a + b * b + 2 * (A + R * np.cos(least)), 0.0))


def pelvis_drop(skeleton, traj, targets, ease_frames):
    """(F,) how far (m) to lower the pelvis so every leg reaches its ankle target (targets {side:
    (F, 3)}, NaN where the foot is left alone) with its knee bent as allowed_reach says: the
    least drop per frame, widened and smoothed over `ease_frames` so the body eases down and up
    (never below what a frame needs), at most MAX_PELVIS_DROP."""
    world = traj.world_frames(skeleton)
    need = np.zeros(traj.frame_count)
    for side, target in targets.items():
        hip = world[:, _leg(skeleton, side)[0], :3, 3]
        reach_max = allowed_reach(skeleton, world, side, knee_hinge(skeleton, traj.rotations, side))
        d = target - hip
        flat2 = np.sum(d[:, :2] ** 2, axis=1)
        height = np.sqrt(np.maximum(reach_max ** 2 - flat2, 0.0))  # the hip's height over the target
        drop = np.where(np.isfinite(d[:, 2]), -d[:, 2] - height, 0.0)
        need = np.maximum(need, np.nan_to_num(drop, nan=0.0))
    need = np.minimum(need, MAX_PELVIS_DROP)
    if not need.any():
        return need
    r = max(1, int(ease_frames))
    from scipy.ndimage import maximum_filter1d, uniform_filter1d
    wide = maximum_filter1d(need, 4 * r + 1, mode="nearest")
    return uniform_filter1d(uniform_filter1d(wide, 2 * r + 1, mode="nearest"), 2 * r + 1, mode="nearest")


def reach(skeleton, traj, side, target, foot_rotation, frames):
    """Local rotations (n, 3, 4) of thigh, shin and foot on `frames` that put the ankle at
    target[frames] (world) with the foot's world rotation foot_rotation[frames], changing the leg
    least: the shin turns about the knee's own hinge in this motion (knee_hinge) by the turn that
    gives the hip-ankle distance (exactly, for a hinge at any angle to the bones, on the side the
    knee bends to over each run of frames), then the thigh swings (no twist) to point the ankle at
    its target. The thigh keeps its twist and the knee its off-hinge rotation, which a
    hinge-and-swivel solve (motion_control.limb_ik.LimbIK) would re-derive: on CMU's three-axis
    knees that moved the thighs' twist by up to 90 deg for a 0.1 mm target."""
    sk = skeleton
    thigh, shin, foot = _leg(sk, side)
    world = sk.world_frames(traj.basis()[frames], traj.armature_to_world)
    R = world[..., :3, :3]
    hip, knee, ankle = (world[:, j, :3, 3] for j in (thigh, shin, foot))
    target = np.asarray(target, float)[frames]
    hinge = knee_hinge(sk, traj.rotations, side)
    a, b, A, Rk, psi, n = _knee_terms(sk, world, side, hinge)
    # a target beyond the allowed reach (the pelvis lowered only so far) is reached from above:
    # the foot hovers rather than slides, and the knee keeps its bend
    longest = allowed_reach(sk, world, side, hinge)
    d = target - hip
    far = np.linalg.norm(d, axis=1) > longest
    flat2 = np.sum(d[far, :2] ** 2, axis=1)
    target = target.copy()
    target[far, 2] = hip[far, 2] - np.sqrt(np.maximum(longest[far] ** 2 - flat2, 0.0))
    c_new = np.linalg.norm(target - hip, axis=1)
    cos_alpha = np.clip(((c_new ** 2 - a * a - b * b) / 2 - A) / np.maximum(Rk, 1e-12), -1.0, 1.0)
    alpha = np.arccos(cos_alpha)  # the bend from straight that gives c_new
    bent = np.angle(np.exp(-1j * psi))  # the bend now (positive: the way this knee bends)
    sign = np.ones(len(frames))
    for run in np.split(np.arange(len(frames)), np.flatnonzero(np.diff(frames) > 1) + 1):
        sign[run] = 1.0 if np.median(bent[run]) >= 0 else -1.0  # one side per run: no flip through straight
    turn = np.angle(np.exp(1j * (psi + sign * alpha)))
    bend = _axis_rotation(n, turn)
    ankle1 = knee + np.einsum("fij,fj->fi", bend, ankle - knee)
    p, q = _unit(ankle1 - hip), _unit(target - hip)
    axis = np.cross(p, q)
    swing = _axis_rotation(_unit(axis), np.arctan2(np.linalg.norm(axis, axis=1), np.einsum("fi,fi->f", p, q)))
    r_thigh = swing @ R[:, thigh]
    r_shin = swing @ bend @ R[:, shin]
    r_foot = np.asarray(foot_rotation, float)[frames]
    rest = sk.rest_local[:, :3, :3]
    parent = sk.parents[thigh]
    r_parent = R[:, parent] if parent >= 0 else traj.armature_to_world[:3, :3]
    local = [np.swapaxes(r_parent @ rest[thigh], -1, -2) @ r_thigh,
             np.swapaxes(r_thigh @ rest[shin], -1, -2) @ r_shin,
             np.swapaxes(r_shin @ rest[foot], -1, -2) @ r_foot]
    return np.stack([rotations.from_matrix(m) for m in local], axis=1), (thigh, shin, foot)


def move_feet(skeleton, traj, offsets, tolerance=1e-5):
    """Trajectories with each leg solved (`reach`) so its foot moves by offsets[side] (F, 3 or 7)
    and keeps its world orientation (turned by the offset's turn). Where a leg would have to
    stretch straighter than allowed_reach, the pelvis is lowered (eased in and out; its path over
    the ground is kept). Returns (trajectories, {side: frames moved, "pelvis_drop": (F,) m})."""
    from ..trajectories import Trajectories
    world = traj.world_frames(skeleton)
    goals, chosen = {}, {}
    for side, d in offsets.items():
        goals[side] = foot_targets(skeleton, world, side, d)
        chosen[side] = np.linalg.norm(d[:, :4], axis=1) > tolerance
    drop = pelvis_drop(skeleton, traj, {s: np.where(chosen[s][:, None], g[0], np.nan) for s, g in goals.items()},
                       ROOT_EASE_SECONDS * traj.fps) if goals else np.zeros(traj.frame_count)
    if drop.any():
        position, orientation = traj.root_pose(skeleton)
        traj = traj.with_root_pose(skeleton, position - drop[:, None] * [0.0, 0.0, 1.0], orientation)
    chosen = {s: np.flatnonzero(c | (drop > 1e-9)) for s, c in chosen.items()}  # a lowered body: every leg
    quats = traj.rotations.copy()
    moved = {}
    for side, (target, r_foot) in goals.items():
        if not len(chosen[side]):
            continue
        q, joints = reach(skeleton, traj, side, target, r_foot, chosen[side])
        quats[np.ix_(chosen[side], joints)] = q
        moved[side] = chosen[side]
    moved["pelvis_drop"] = drop
    quats = rotations.make_continuous(quats)
    return Trajectories(traj.frames, traj.fps, quats, traj.translations, traj.armature_to_world), moved


MAX_TOE_TURN_DEG = 90.0  # about the toes' own range of extension


def pin_toes(skeleton, traj, floor=None, planted=None):
    """Trajectories whose toe tips stay where they landed while they are down (the foot's hold,
    foot_offsets, keeps the ball, or the toe from where the hold passed to it): each toe bone
    turned about its head (the ball) to put its tip back, faded out over RAMP_SECONDS after the
    contact, by at most MAX_TOE_TURN_DEG. Where the held tip would be under the ground (the ball
    lower than at landing), it is put on the ground as near as it reaches, and moved["lift"][side]
    (F,) says how far the foot would have to rise to keep the tip where it landed (hold_feet does).
    Returns (trajectories, {side: frames moved, "lift": {side: (F,) m}})."""
    from ..trajectories import Trajectories
    sk, fps = skeleton, traj.fps
    world = traj.world_frames(sk)
    points = foot_points(sk, world)
    planted = planted_points(points, fps) if planted is None else planted
    ramp = max(1, int(round(RAMP_SECONDS * fps)))
    quats = traj.rotations.copy()
    moved = {"lift": {}}
    for side, p in points.items():
        toe, foot = sk.role_index(f"toe.{side}"), sk.role_index(f"foot.{side}")
        if toe is None or p.shape[1] < 2 or sk.parents[toe] != foot:
            continue
        F = len(p)
        omega = np.zeros((F, 3))
        lift = np.zeros(F)
        head = world[:, toe, :3, 3]
        for a, b in contact_runs(planted[side][:, 1]):  # while the tip is down
            now = p[a:b, 1] - head[a:b]
            reach = np.linalg.norm(now, axis=1)
            want = np.zeros_like(now)
            want[:, :2] = p[a, 1, :2] - head[a:b, :2]
            flat = np.linalg.norm(want[:, :2], axis=1)
            want[:, 2] = (1.0 if now[0, 2] >= 0 else -1.0) * np.sqrt(np.maximum(reach ** 2 - flat ** 2, 0.0))
            if floor is not None:  # the tip stays on or above the floor: then as near as it reaches
                tip = head[a:b] + want
                low = want[:, 2] - heights_above(tip[:, None], floor)[:, 0]  # the tip's lowest offset
                lifted = want[:, 2] < low
                lift[a:b][lifted] = low[lifted] - want[lifted, 2]  # how far the foot would have to rise
                want[lifted, 2] = np.minimum(low[lifted], reach[lifted])
                side_room = np.sqrt(np.maximum(reach[lifted] ** 2 - want[lifted, 2] ** 2, 0.0))
                want[lifted, :2] = _unit(want[lifted, :2]) * side_room[:, None]
            axis = np.cross(_unit(now), _unit(want))
            angle = np.arctan2(np.linalg.norm(axis, axis=1), np.einsum("fi,fi->f", _unit(now), _unit(want)))
            omega[a:b] = _unit(axis) * np.minimum(angle, np.radians(MAX_TOE_TURN_DEG))[:, None]
            end = min(F, b + ramp)
            fade = np.arange(1, end - b + 1) / (ramp + 1)
            omega[b:end] = omega[b - 1] * (1.0 - fade * fade * (3 - 2 * fade))[:, None]  # eased out
            lift[b:end] = lift[b - 1] * (1.0 - fade * fade * (3 - 2 * fade))
        if lift.any():
            moved["lift"][side] = lift
        if floor is not None:  # where a turn (e.g. fading out after the contact) would put the
            # tip (or a toe-end bone's point) under the ground, the turn is cut back as far as needed
            ends = [k for k in sk.descendants(toe)]
            tips = [p[:, 1]] + [world[:, k, :3, 3] for k in ends] + \
                   [world[:, k, :3, 3] + world[:, k, :3, 1] * sk.lengths[k] for k in ends]
            omega = _keep_tip_up(omega, np.stack(tips, axis=1) - head[:, None], head, floor)
        frames = np.flatnonzero(np.linalg.norm(omega, axis=1) > 1e-9)
        if not len(frames):
            continue
        turn = _axis_rotation(_unit(omega[frames]), np.linalg.norm(omega[frames], axis=1))
        parent = world[frames, foot, :3, :3] @ sk.rest_local[toe, :3, :3]
        local = np.swapaxes(parent, -1, -2) @ turn @ world[frames, toe, :3, :3]
        quats[frames, toe] = rotations.from_matrix(local)
        moved[side] = frames
    quats = rotations.make_continuous(quats)
    return Trajectories(traj.frames, traj.fps, quats, traj.translations, traj.armature_to_world), moved


LIFT_PASSES = 3
SETTLE_TOLERANCE = 1e-5  # m: a contact raised less than this by the toe's hold is left


def _lowest(skeleton, traj, floor):
    """{side: (F,)} each foot's lowest point (foot and sole points) above the floor."""
    world = traj.world_frames(skeleton)
    sole = sole_points(skeleton, world)
    return {s: lowest_above(p, sole.get(s), floor) for s, p in foot_points(skeleton, world).items()}


def _settle(low, reference, on, fps):
    """(F,) how far to lower a foot whose contacts the toe's hold raised: per contact (runs of
    `on`), its lowest point `low` (F,) back to where the foot's move put it (`reference`), eased
    in and out over RAMP_SECONDS; never so far that a frame's lowest point goes under the floor."""
    F = len(low)
    drop, known = np.zeros(F), np.zeros(F, bool)
    for a, b in contact_runs(on):
        rise = low[a:b].min() - reference[a:b].min()
        drop[a:b] = rise if rise > SETTLE_TOLERANCE else 0.0
        known[a:b] = True
    if not drop.any():
        return drop
    ramp = max(1, int(round(RAMP_SECONDS * fps)))
    known |= np.convolve(known.astype(float), np.ones(2 * ramp + 1))[ramp:ramp + F] == 0
    idx = np.arange(F)
    if not known.all():
        drop[~known] = _ease(idx[~known], idx[known], drop[known])
    return np.clip(drop, 0.0, np.maximum(low, 0.0))


def hold_feet(skeleton, traj, offsets, floor=None, planted=None):
    """Feet moved by offsets (foot_offsets: move_feet) and toe tips held (pin_toes). Where a held
    toe tip would have to go under the ground (the captured ball sinking while the tip is down),
    the foot is raised by that much (eased out after the contact) and solved again, so the tip
    stays where it landed, on the ground, rather than sliding over it. Where holding the tip
    raises a contact instead (the captured toe bending a little while the tip is down: held, it
    keeps its pitch at landing), the foot is lowered by as much, so the contact's lowest point
    stays where move_feet put it, on the ground, not hovering above it. Returns (trajectories,
    {side: frames moved, "pelvis_drop": (F,) m, "lift": {side: (F,) m}})."""
    start = traj
    traj, moved = move_feet(skeleton, start, offsets)
    if floor is not None:  # where the foot's move put each contact
        reference = _lowest(skeleton, traj, floor)
        if planted is None:
            planted = planted_points(foot_points(skeleton, start.world_frames(skeleton)), start.fps)
    traj, toes = pin_toes(skeleton, traj, floor, planted)
    total = {}
    for _ in range(LIFT_PASSES):  # the raised foot turns the leg a little: a second look
        if floor is None:
            break
        low = _lowest(skeleton, traj, floor)
        settle = {s: _settle(low[s], reference[s], planted[s].any(axis=1), traj.fps)
                  for s in reference if s in planted and s in offsets}
        if not toes["lift"] and not any(d.any() for d in settle.values()):
            break
        offsets = {s: d.copy() for s, d in offsets.items()}
        for side, lift in toes["lift"].items():
            offsets[side][:, 2] += lift
            total[side] = total.get(side, 0.0) + lift
        for side, drop in settle.items():
            offsets[side][:, 2] -= drop
        traj, moved = move_feet(skeleton, start, offsets)
        traj, toes = pin_toes(skeleton, traj, floor, planted)
    moved["lift"] = total
    return traj, moved


TIP_TOLERANCE = 1e-6  # m: how far under the ground the bisection may leave a turned tip (rounding)


def _keep_tip_up(omega, tip, head, floor, iterations=12):
    """omega (F, 3) scaled down, frame by frame, to the largest share (found by bisection, so it
    changes smoothly from frame to frame) that keeps the toe tip (head + turned tip; tip (F, 3),
    or (F, m, 3): the tip and the points of any toe-end bone) on or above the ground; frames
    already under it keep their turn."""
    out = omega.copy()
    tip = tip[:, None] if tip.ndim == 2 else tip
    angle = np.linalg.norm(omega, axis=1)
    moving = np.flatnonzero(angle > 1e-9)
    if not len(moving):
        return out
    def above(share):
        turn = _axis_rotation(_unit(omega[moving]), share * angle[moving])
        moved = head[moving, None] + np.einsum("fij,fmj->fmi", turn, tip[moving])
        return heights_above(moved, floor).min(axis=1) >= -TIP_TOLERANCE
    ones = np.ones(len(moving))
    chosen = ones.copy()  # a tip under the ground without the turn keeps the turn (it lifts)
    cut = above(0.0 * ones) & ~above(ones)
    lo, hi = np.zeros(len(moving)), ones.copy()
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        ok = above(mid)
        lo, hi = np.where(ok, mid, lo), np.where(ok, hi, mid)
    chosen[cut] = lo[cut]
    out[moving] = omega[moving] * chosen[:, None]
    return out


def planted_slide(skeleton, traj, planted):
    """The largest distance (m) a planted foot point moves over the ground from where it landed,
    over the contacts `planted` ({side: (F, k) bool}, from planted_points, e.g. of the input)."""
    points = foot_points(skeleton, traj.world_frames(skeleton))
    worst = 0.0
    for side, down in planted.items():
        for i in range(down.shape[1]):
            for a, b in contact_runs(down[:, i]):
                p = points[side][a:b, i, :2]
                worst = max(worst, float(np.linalg.norm(p - p[0], axis=1).max()))
    return worst
