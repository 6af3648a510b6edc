"""Planted feet through a transition: after the joint angles of two motions are blended (a
transition, multiresolution_blend), a foot planted on both sides of it is dragged from where one
input puts it to where the other does. Here each foot contact that overlaps the transition is held
where it landed and kept on or above the floor, the legs solved to it with the clean-up's analytic
leg IK (solver.cleanup.feet: foot_offsets, move_feet, pin_toes); frames away from the transition
are left as blended. Any skeleton whose feet the body roles name (foot, toe)."""

import numpy as np

from .. import rotations
from ..cleanup import feet
from ..dynamics.spatial import quat_log
from ..qa import thresholds as T


def _near(mask, frames):
    """(F,) weight: 1 on `mask`, easing to 0 over `frames` frames either side."""
    F = len(mask)
    if not mask.any():
        return np.zeros(F)
    idx = np.arange(F)
    on = np.flatnonzero(mask)
    dist = np.abs(idx[:, None] - on[None, :]).min(axis=1).astype(float)
    u = np.clip(1.0 - dist / (frames + 1.0), 0.0, 1.0)
    return u * u * (3.0 - 2.0 * u)


def _hold_heading(d, foot, down, ramp):
    """Turn column d[:, 3] so a one-point foot (ball only, no toe bone) keeps the heading it
    landed with while it is planted (it turns about the ball, so the ankle would sweep), eased
    out over `ramp` frames after each contact. `foot`: the foot bone's world frames (F, 4, 4)."""
    axis = foot[:, :2, 1]  # the bone's direction over the ground
    heading = np.arctan2(axis[:, 1], axis[:, 0])
    F = len(d)
    for a, b in feet.contact_runs(down):
        d[a:b, 3] = np.angle(np.exp(1j * (heading[a] - heading[a:b])))
        end = min(F, b + ramp)
        u = np.arange(1, end - b + 1) / (ramp + 1.0)
        d[b:end, 3] = d[b - 1, 3] * (1.0 - u * u * (3.0 - 2.0 * u))


def hold_planted_feet(skeleton, traj, transition, planted_inputs=None, floor=None):
    """Trajectories with the feet held through `transition` ((F,) bool: the frames the blend
    changes). Contacts: the foot points planted on the result (feet.planted_points) or, where
    given, on both inputs at once (`planted_inputs`, {side: (F, k) bool} on the result's
    frames); only contacts overlapping the transition are held, from the transition's first
    frame at the earliest (before it the motion is the first input's, left as it is). `floor`: a height (m, world Z) or
    None for the floor found under the result's contacts (feet.find_floor). Returns
    (trajectories, report: {"held": {side: [[first, last] frame]}, "largest_correction_cm",
    "pelvis_lowered_cm", "floor_m"})."""
    transition = np.asarray(transition, bool)
    world = traj.world_frames(skeleton)
    points = feet.foot_points(skeleton, world)
    report = {"held": {}, "largest_correction_cm": {}, "pelvis_lowered_cm": 0.0, "floor_m": None}
    if not points or not transition.any():
        return traj, report
    fps = traj.fps
    planted = feet.planted_points(points, fps)
    if planted_inputs:
        planted = {s: d | planted_inputs[s] if s in planted_inputs else d for s, d in planted.items()}
    if floor is None:
        floor = feet.find_floor(points, {s: d.any(axis=1) for s, d in planted.items()})
    report["floor_m"] = float(floor)
    kept, region = {}, transition.copy()
    ramp = max(1, int(round(feet.RAMP_SECONDS * fps)))
    first = int(np.argmax(transition))
    for side, down in planted.items():
        keep = np.zeros_like(down)
        for i in range(down.shape[1]):
            for a, b in feet.contact_runs(down[:, i]):
                # held from where the blend starts to change it; a hold too short to ease in and
                # out (its start cut there) is left as blended
                if transition[a:b].any() and b - max(a, first) >= 2 * ramp:
                    keep[max(a, first):b, i] = True
        kept[side] = keep
        on = keep.any(axis=1)
        region |= on
        report["held"][side] = [[float(traj.frames[a]), float(traj.frames[b - 1])] for a, b in feet.contact_runs(on)]
    offsets = feet.foot_offsets(points, fps, floor=floor, skate=True, planted=kept)
    for side, d in offsets.items():
        if points[side].shape[1] == 1:  # a foot with no toe: its heading is held too
            _hold_heading(d, world[:, skeleton.role_index(f"foot.{side}")], kept[side][:, 0], ramp)
    weight = _near(region, ramp)
    for side, d in offsets.items():
        d[:, :4] *= weight[:, None]  # the rest of the clip stays as blended
    report["released"] = []
    while True:
        held, moved = feet.move_feet(skeleton, traj, offsets)
        held, _ = feet.pin_toes(skeleton, held, floor, kept)
        # a hold the legs can only follow with a turn faster than the blended motion's own
        # (a foot held far from where the blend puts it, let go at a run's toe off) is released
        pops = _pops(traj.rotations, held.rotations, fps)
        popping = [s for s in offsets if pops[_leg_joints(skeleton, s)].any()]
        if not popping:
            break
        side = popping[0]
        report["released"].append(side)
        offsets[side][:, :4] = 0.0
        kept[side][:] = False
        report["held"][side] = []
    # the pelvis is lowered over a longer ease (feet.pelvis_drop) than the hold: away from the
    # frames held, eased back to the motion as blended so the rest of the clip is as it was
    held = _eased_back(traj, held, _near(region, 2 * ramp))
    for side, d in offsets.items():
        report["largest_correction_cm"][side] = round(float(100 * np.linalg.norm(d[:, :3], axis=1).max()), 2)
    report["pelvis_lowered_cm"] = round(float(100 * moved["pelvis_drop"].max()), 2)
    return held, report


def _eased_back(original, changed, g):
    """`changed` where g (F,) is 1, `original` where it is 0, the rotations' and translations'
    sum weighted between (normalised: the two poses differ by a few degrees at most there)."""
    from ..trajectories import Trajectories
    w = g[:, None, None]
    qa, qb = original.rotations, changed.rotations
    qb = np.where(np.einsum("fji,fji->fj", qa, qb)[..., None] < 0.0, -qb, qb)
    q = (1.0 - w) * qa + w * qb
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    t = (1.0 - w) * original.translations + w * changed.translations
    return Trajectories(changed.frames, changed.fps, q, t, changed.armature_to_world)


def _omega(q):
    """(F - 1, J, 3) rotation vector of each joint between frames (deg)."""
    step = rotations.multiply(q[:-1] * np.array([1.0, -1.0, -1.0, -1.0]), q[1:])
    return np.degrees(quat_log(step))


def _pops(before, after, fps):
    """(J,) bool: a joint turns faster between frames, or changes that turn more, in `after` than
    anywhere in `before`, past the motion QA's pop allowance (solver.qa.thresholds)."""
    out = np.zeros(before.shape[1], bool)
    wa, wb = _omega(before), _omega(after)
    for a, b, margin in ((wa, wb, T.POP_VELOCITY_MARGIN_DEG_S / fps),
                         (np.diff(wa, axis=0), np.diff(wb, axis=0), T.POP_ACCELERATION_MARGIN_DEG_S2 / fps ** 2)):
        if len(a):
            out |= np.linalg.norm(b, axis=-1).max(axis=0) > T.POP_RATIO * np.linalg.norm(a, axis=-1).max(axis=0) + margin
    return out


def _leg_joints(skeleton, side):
    return [j for j in (skeleton.role_index(f"{r}.{side}") for r in ("thigh", "shin", "foot", "toe")) if j is not None]
