"""Clean Up Capture (issue 26): repairs for raw motion capture, each a small function on plain
arrays (glitches, jitter) or on a Skeleton and its Trajectories (floor, contacts, foot skate),
chained by `clean_up`, which reports per repair what changed (frames, bones, sizes) and the motion
QA's measures before and after it.

Order: glitches (so the filter and the contacts never see a flip), jitter, floor (the whole body
moved so the floor found under the planted feet is at `ground`), then contacts and skate (planted
feet held where they land, at the floor, the legs solved to reach them)."""

from dataclasses import dataclass

import numpy as np

from .. import qa, rotations
from ..errors import MotionError
from ..trajectories import Trajectories
from . import feet
from . import glitches as glitch_repair
from . import ground as ground_surface
from . import jitter as jitter_filter

REPAIRS = ("glitches", "jitter", "floor", "skate", "physics")
QA_KEYS = ("slide", "penetration", "pop_velocity", "pop_acceleration")


@dataclass
class Options:
    glitches: bool = True
    jitter: bool = True
    floor: bool = True
    skate: bool = True
    physics: bool = False  # the optional physical pass (dynamic control, tracking only)
    glitch_strength: float = 1.0  # detection: speed limits divided by it
    jitter_strength: float = 1.0  # 0..1: how much of the jitter is removed
    jitter_hz: float = jitter_filter.DEFAULT_CUTOFF_HZ
    # the ground the feet are put on: a height (m, world Z), a surface (solver.cleanup.ground: a
    # height field or a mesh), or None to keep the floor found under the feet
    ground: object = 0.0


def motion(skeleton, traj):
    """The motion QA's Motion of trajectories (bone heads and tails in the world)."""
    world = traj.world_frames(skeleton)
    heads = world[..., :3, 3]
    tails = heads + world[..., :3, 1] * skeleton.lengths[:, None]
    return qa.Motion(heads, traj.rotations, skeleton.names, traj.fps, skeleton.parents, tails, traj.frames)


def qa_measures(skeleton, traj, ground=None):
    """The QA measures of one motion, each {value, unit, bone, frames}."""
    m = motion(skeleton, traj)
    report = qa.measure(m, None, qa.feet_from_roles(skeleton.roles, skeleton.names), ground)
    return {k: {f: report["measures"][k].get(f) for f in ("value", "unit", "bone", "frames")}
            for k in QA_KEYS if k in report["measures"]}


def translating_joints(traj, tolerance=1e-6):
    """Joints whose location channel moves (the root, and any other that translates)."""
    t = traj.translations
    return np.flatnonzero(np.ptp(t, axis=0).max(axis=1) > tolerance)


def clean_up(skeleton, traj, options=None):
    """The cleaned Trajectories and a report: {"repairs": [per repair], "contacts": {side: [(first,
    last frame)]}, "floor_m": found floor, "ground_m": the floor it was put on}."""
    o = options or Options()
    report = {"repairs": []}
    steps = (("glitches", _glitches), ("jitter", _jitter), ("floor", _floor), ("skate", _skate),
             ("physics", _physics))
    ground = None
    for name, step in steps:
        entry = {"repair": name, "enabled": bool(getattr(o, name))}
        if entry["enabled"]:
            before = traj
            traj, details = step(skeleton, traj, o, report)
            entry.update(details)
            entry.update(_changes(skeleton, before, traj))
            ground = report.get("ground_m", ground)
            entry["qa_before"] = qa_measures(skeleton, before, ground)
            entry["qa_after"] = qa_measures(skeleton, traj, ground)
        report["repairs"].append(entry)
    report.pop("planted", None)  # arrays: not part of the report
    report.pop("surface", None)
    report.pop("levels", None)
    report.pop("captured", None)
    return traj, report


def _with(traj, quats=None, translations=None):
    return Trajectories(traj.frames, traj.fps, traj.rotations if quats is None else quats,
                        traj.translations if translations is None else translations, traj.armature_to_world)


def _glitches(skeleton, traj, o, report):
    moving = translating_joints(traj)
    q, p, events = glitch_repair.repair(traj.rotations, traj.translations[:, moving], traj.fps, o.glitch_strength)
    trans = traj.translations.copy()
    trans[:, moving] = p
    listed = []
    for kind, channel, a, b in events:
        bone = None if channel is None else skeleton.names[channel[1] if channel[0] == "rotation" else moving[channel[1]]]
        listed.append({"kind": kind if channel is None or channel[0] == "rotation" else f"position {kind}",
                       "bone": bone, "frames": [float(traj.frames[a]), float(traj.frames[b])]})
    return _with(traj, q, trans), {"strength": o.glitch_strength, "events": listed}


def _jitter(skeleton, traj, o, report):
    moving = translating_joints(traj)
    q = jitter_filter.smooth_rotations(traj.rotations, traj.fps, o.jitter_hz, o.jitter_strength)
    trans = traj.translations.copy()
    trans[:, moving] = jitter_filter.smooth_positions(trans[:, moving], traj.fps, o.jitter_hz, o.jitter_strength)
    return _with(traj, q, trans), {"strength": o.jitter_strength, "cutoff_hz": o.jitter_hz}


def _points(skeleton, traj):
    return feet.foot_points(skeleton, traj.world_frames(skeleton))


def _points_and_soles(skeleton, traj):
    """The feet's foot points and sole points (feet.foot_points, feet.sole_points) from one pass
    of forward kinematics."""
    world = traj.world_frames(skeleton)
    return feet.foot_points(skeleton, world), feet.sole_points(skeleton, world)


def _floor(skeleton, traj, o, report):
    """The whole body moved up or down so the feet's floor (found under the planted feet) is on
    the ground (a height, or a surface: a height field or a mesh, solver.cleanup.ground); then
    each contact put on it (no sinking, no hovering) by the legs' IK."""
    points, sole = _points_and_soles(skeleton, traj)
    # contacts found before the feet are put on the floor (which makes every planted frame
    # equally low and would merge them): the skate repair holds the same ones
    report["planted"] = feet.planted_points(points, traj.fps)
    contacts = {s: d.any(axis=1) for s, d in report["planted"].items()}
    found = feet.find_floor(points, contacts)  # world Z of the feet's floor
    # a foot placed higher (a marker or a sole) is seen on the capture's own flat floor, before
    # the body is put on a ground whose bumps would look like one
    report["levels"] = feet.own_levels(points, report["planted"], found, sole)
    # and so is each foot's height in the capture, which says whether a contact stands on
    # something else (far above the floor) or on the ground, wherever the ground's bumps put it
    report["captured"] = {s: feet.lowest_above(p, sole.get(s), found) for s, p in points.items()}
    surface = ground_surface.as_ground(found if o.ground is None else o.ground)
    # the body follows the ground's rise and fall under the planted feet (constant on a flat
    # floor), then the feet's floor is put on it
    terrain = feet.terrain_under(points, contacts, surface, traj.fps)
    if not np.isfinite(terrain).all():
        raise MotionError("no foot is over the ground: the ground mesh does not lie under the motion")
    lifted = {s: p + np.stack((0 * terrain, 0 * terrain, terrain), axis=1)[:, None] for s, p in points.items()}
    shift = terrain - feet.find_floor(lifted, contacts, surface)
    position, orientation = traj.root_pose(skeleton)
    position = position.copy()
    position[:, 2] += shift
    traj = traj.with_root_pose(skeleton, position, orientation)
    flat = isinstance(surface, ground_surface.Flat)
    report.update(floor_m=found, ground_m=surface.z if flat else None, surface=surface)
    points, sole = _points_and_soles(skeleton, traj)
    offsets = feet.foot_offsets(points, traj.fps, floor=surface, skate=False, planted=report["planted"],
                                levels=report["levels"], sole=sole, captured=report["captured"])
    traj, moved = feet.move_feet(skeleton, traj, offsets)
    after, sole = _points_and_soles(skeleton, traj)
    heights = {s: feet.lowest_above(p, sole.get(s), surface) for s, p in after.items()}
    # a contact hovers when even its lowest point stays above the floor
    hovering = sum(int(h[a:b].min() > 0.002) for s, h in heights.items() for a, b in feet.contact_runs(contacts[s]))
    deepest = min(float(np.min(h[np.isfinite(h)], initial=np.inf)) for h in heights.values())
    return traj, {"floor_m": found, "ground_m": surface.z if flat else None, "ground": surface.describe(),
                  "shift_m": float(np.median(shift)), "terrain_rise_m": float(np.ptp(terrain)), "feet_moved_cm": {s: float(100 * np.abs(d[:, 2]).max()) for s, d in offsets.items()},
                  "pelvis_lowered_cm": round(float(100 * moved["pelvis_drop"].max()), 2),
                  "hovering_contacts": hovering,
                  "lowest_foot_cm": round(100 * deepest, 2) if np.isfinite(deepest) else None}


def _skate(skeleton, traj, o, report):
    points, sole = _points_and_soles(skeleton, traj)
    planted = report.pop("planted", None) or feet.planted_points(points, traj.fps)
    contacts = {side: down.any(axis=1) for side, down in planted.items()}
    report["contacts"] = {s: [[float(traj.frames[a]), float(traj.frames[b - 1])] for a, b in feet.contact_runs(c)]
                          for s, c in contacts.items()}
    surface = report.get("surface")
    offsets = feet.foot_offsets(points, traj.fps, floor=surface, skate=True, planted=planted,
                                levels=report.get("levels"), sole=sole,
                                captured=report.get("captured"))
    traj, moved = feet.hold_feet(skeleton, traj, offsets, surface, planted)
    slide = {s: float(100 * np.linalg.norm(d[:, :2], axis=1).max()) for s, d in offsets.items()}
    return traj, {"contacts": report["contacts"], "largest_correction_cm": slide,
                  "toe_lift_cm": {s: round(float(100 * v.max()), 2) for s, v in moved["lift"].items()},
                  "pelvis_lowered_cm": round(float(100 * moved["pelvis_drop"].max()), 2)}


def _physics(skeleton, traj, o, report):
    """The optional physical pass: the cleaned motion run through dynamic control with tracking
    only (solver.motion_control, its public entry `control`), so the pelvis and the centre of mass
    obey gravity and the support, with no reaction added (no comfort, balance or falling). The
    contacts found here are the controller's support; the balance error (how far the ZMP leaves the
    support polygon, beyond the input's own excursion) is reported."""
    from ..motion_control.contacts import Contact
    from ..motion_control.controller import ControlSettings, control
    contacts = report.get("contacts")
    if contacts is None:  # the skate repair was off: the contacts of this motion
        planted = feet.planted_points(_points(skeleton, traj), traj.fps)
        contacts = {s: [[float(traj.frames[a]), float(traj.frames[b - 1])] for a, b in feet.contact_runs(d.any(axis=1))]
                    for s, d in planted.items()}
    overrides = tuple(Contact(side, first, last, True) for side, runs in contacts.items() for first, last in runs)
    ground = report.get("ground_m")
    settings = ControlSettings(tracking_only=True, ground_height=ground, support_overrides=overrides,
                               remove_foot_skate=False)
    result = control(skeleton, traj, settings)
    balance = np.asarray(result.balance_error, float)
    finite = balance[np.isfinite(balance)]
    worst = int(np.nanargmax(balance)) if finite.size else None
    slide = np.asarray(result.foot_slide, float)
    return result.trajectories, {
        "balance_error_max_cm": round(float(100 * finite.max()), 2) if finite.size else 0.0,
        "balance_error_median_cm": round(float(100 * np.median(finite)), 2) if finite.size else 0.0,
        "balance_error_frame": float(traj.frames[worst]) if worst is not None else None,
        "out_of_balance_frames": int(np.count_nonzero(finite > 0.01)),
        "foot_slide_max_mm": round(float(1000 * np.nanmax(slide)), 2) if np.isfinite(slide).any() else 0.0,
        "ground_m": result.ground_height}


def _changes(skeleton, before, after):
    """What a repair changed: frames and bones whose rotation moved by more than 0.1 deg or whose
    location moved more than 1 mm, and the largest changes."""
    deg = np.degrees(rotations.angle_between(before.rotations, after.rotations))  # (F, J)
    cm = 100 * np.linalg.norm(after.translations - before.translations, axis=-1)
    changed = (deg > 0.1) | (cm > 0.1)
    frames = before.frames[changed.any(axis=1)]
    bones = [skeleton.names[j] for j in np.flatnonzero(changed.any(axis=0))]
    return {"changed": bool(changed.any()), "frames": _ranges(frames), "frame_count": int(len(frames)),
            "bones": bones, "max_change_deg": round(float(deg.max()), 3) if deg.size else 0.0,
            "rms_change_deg": round(float(np.sqrt(np.mean(deg ** 2))), 4) if deg.size else 0.0,
            "max_change_cm": round(float(cm.max()), 3) if cm.size else 0.0}


def _ranges(frames):
    """Frame numbers as [[first, last], ...] runs of consecutive frames."""
    out = []
    for f in frames:
        if out and f - out[-1][1] <= 1.0 + 1e-9:
            out[-1][1] = float(f)
        else:
            out.append([float(f), float(f)])
    return out
