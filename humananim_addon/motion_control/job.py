"""Dynamic motion control in Blender (Oshita 2003, ch. 2): its settings, loads, impulses from
arrow Empties, colliders sampled from another armature or a moving mesh, and the result back
out as a new action with stress and balance curves, plus the per-frame data the viewport
overlay draws (kept in memory, never in the .blend)."""

import math
import time
from dataclasses import dataclass, replace

import bpy
import numpy as np

from ...solver.errors import MotionError, RigError
from .. import actions
from ..actions import bone_path
from ..armature import skeleton_from_armature
from ..arrows import arrow_forces
from ..forces import add_arrow, gravity_of, hand_loads
from ..rig.capability import RigView

STRESS = "humananim_stress"  # N m: torque beyond the muscles' strength, magnitude over the axes
BALANCE_ERROR = "humananim_balance_error"  # m: ZMP outside the support polygon
FALLING_BALANCE = -1.0  # the balance error's value while falling (nothing to measure against)
FALLING = "humananim_falling"  # 0/1: the figure turns about its edge of support

CONTROL_KINDS = ("none", "passive", "comfort", "balance")  # ControlResult.control codes 0..3


# ---- the overlay's data: in memory only ---------------------------------------------------------

@dataclass
class OverlayData:
    """Per frame, in Blender units and world space: what the viewport overlay draws."""

    frames: np.ndarray  # (F,) Blender frames
    ghost: np.ndarray  # (F, J, 2, 3) input bones: head, tail
    bones: np.ndarray  # (F, J, 2, 3) result bones
    control: np.ndarray  # (F, J) int8, CONTROL_KINDS
    stress: np.ndarray  # (F, J) N m
    zmp: np.ndarray  # (F, 2), NaN when nothing is on the ground
    polygons: list  # per frame (k, 2)
    ground: float  # height of the ground (Blender units)
    falling: np.ndarray  # (F,) bool
    forward: np.ndarray = None  # (2,) horizontal direction the body faces (from the hips), if known


CACHE = {}  # (object name, result action name) -> OverlayData


def overlay_data(obj):
    """The overlay data for the action `obj` shows (active or on an unmuted NLA track), or None."""
    ad = obj.animation_data
    if ad is None:
        return None
    names = [ad.action.name] if ad.action else []
    names += [s.action.name for t in ad.nla_tracks if not t.mute for s in t.strips if s.action]
    for name in names:
        data = CACHE.get((obj.name, name))
        if data is not None:
            return data
    return None


# ---- from the panel's settings to the solver's --------------------------------------------------

def frame_range(props, action):
    start = props.frame_start or action.frame_range[0]
    end = props.frame_end or action.frame_range[1]
    if end <= start:
        raise MotionError(f"the frame range {start:g}-{end:g} is empty")
    return start, end


def _time(traj, frame):
    return max(0.0, (frame - traj.frames[0]) / traj.fps)


def loads(props, skeleton, traj):
    from ...solver.motion_control.controller import Load
    start = _time(traj, props.load_frame) if props.load_frame else 0.0
    return [Load(bone=hand, mass=kg, start_time=start) for hand, kg in hand_loads(props, skeleton, required=True)]


def impulses(props, skeleton, traj, scene):
    """Each arrow becomes an impulse (or a force over its duration) on its bone (see arrows)."""
    from ...solver.motion_control.controller import Impulse
    return [Impulse(time=seconds, bone=item.bone, point=point, direction=direction, magnitude=item.magnitude,
                    duration=item.duration)
            for item, seconds, point, direction in arrow_forces(props.impulses, skeleton, traj, scene)]


def colliders(props, obj, traj, scene):
    """The collider object sampled on the clip's frames: a Collider of spheres, or nothing."""
    other = props.collider
    if other is None:
        return []
    if other == obj:
        raise RigError(f"'{obj.name}' can't collide with itself: choose another object")
    if other.type not in {"ARMATURE", "MESH"}:
        raise RigError(f"'{other.name}' is a {other.type.lower()}: collide with an armature or a mesh")
    from ...solver.motion_control.controller import Collider
    scale = scene.unit_settings.scale_length
    saved = scene.frame_current, scene.frame_subframe
    try:
        if other.type == "ARMATURE":
            positions, radii = _armature_spheres(other, scene, traj.frames, props.collider_radius)
        else:
            positions, radii = _mesh_spheres(other, scene, traj.frames, props.collider_spheres)
    finally:
        scene.frame_set(saved[0], subframe=saved[1])
    positions, radii = positions * scale, radii * scale
    if not np.isfinite(positions).all():
        raise MotionError(f"'{other.name}' has NaN or infinite positions in the frame range")
    velocities = np.gradient(positions, traj.times, axis=0) if traj.frame_count > 1 else np.zeros_like(positions)
    mass = props.collider_mass if props.collider_mass > 0.0 else math.inf
    return [Collider(positions, radii, velocities, mass=mass)]


def _frames(scene, frames):
    for f in frames:
        scene.frame_set(int(np.floor(f)), subframe=float(f - np.floor(f)))
        yield


def _armature_spheres(other, scene, frames, radius):
    """Spheres every `radius` along each bone from head to tail (Blender units), per frame."""
    bones = list(other.data.bones)
    if not bones:
        raise RigError(f"'{other.name}' has no bones to collide with")
    lengths = np.array([b.length for b in bones])
    counts = np.maximum(2, np.ceil(lengths * np.mean(other.matrix_world.to_scale()) / radius).astype(int) + 1)
    ts = np.concatenate([np.linspace(0.0, 1.0, c) for c in counts])
    owner = np.repeat(np.arange(len(bones)), counts)
    n = len(bones)
    mats = np.empty(n * 16)
    out = np.empty((len(frames), len(ts), 3))
    for i, _ in enumerate(_frames(scene, frames)):
        other.pose.bones.foreach_get("matrix", mats)
        m = np.array(other.matrix_world) @ mats.reshape(n, 4, 4).transpose(0, 2, 1)
        heads = m[:, :3, 3]
        tails = (m @ np.column_stack((np.zeros(n), lengths, np.zeros(n), np.ones(n)))[..., None])[:, :3, 0]
        out[i] = heads[owner] + ts[:, None] * (tails - heads)[owner]
    return out, np.full(len(ts), radius)


def _mesh_spheres(other, scene, frames, count):
    """`count` spheres over the mesh's evaluated vertices, split along its longest axis at the
    first frame; each sphere's centre follows its vertices, its radius covers them on every frame."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    groups = local = None
    centres, radii = [], np.zeros(count)
    for i, _ in enumerate(_frames(scene, frames)):
        evaluated = other.evaluated_get(depsgraph)
        mesh = evaluated.to_mesh()
        try:
            co = np.empty(len(mesh.vertices) * 3)
            mesh.vertices.foreach_get("co", co)
        finally:
            evaluated.to_mesh_clear()
        co = co.reshape(-1, 3)
        if local is None:
            if len(co) == 0:
                raise RigError(f"'{other.name}' has no vertices to collide with")
            local = co
            groups = _split_groups(co, count)
        elif len(co) != len(local):  # topology changes (e.g. a remesh): follow the object's transform
            co = local
        m = np.array(evaluated.matrix_world)
        world = co @ m[:3, :3].T + m[:3, 3]
        c = np.array([(world[g].min(axis=0) + world[g].max(axis=0)) / 2 for g in groups])
        radii = np.maximum(radii, [np.linalg.norm(world[g] - c[k], axis=1).max() for k, g in enumerate(groups)])
        centres.append(c)
    return np.array(centres), np.maximum(radii, 1e-3)


def _split_groups(co, count):
    centred = co - co.mean(axis=0)
    axis = np.linalg.svd(centred, full_matrices=False)[2][0] if len(co) > 1 else np.array([1.0, 0.0, 0.0])
    order = np.argsort(centred @ axis)
    return [g for g in np.array_split(order, min(count, len(co))) if len(g)]


def solver_settings(scene, props, obj, skeleton, traj):
    from ...solver.motion_control.controller import ControlSettings
    gravity = gravity_of(scene)
    height = None if props.ground == "MOTION" else props.ground_height * scene.unit_settings.scale_length
    return ControlSettings(gravity=gravity, ground_height=height, loads=tuple(loads(props, skeleton, traj)),
                           impulses=tuple(impulses(props, skeleton, traj, scene)),
                           colliders=tuple(colliders(props, obj, traj, scene)),
                           strength_scale=props.strength_scale, substeps=props.substeps,
                           tracking_only=props.tracking_only)


def contact_overrides(action, frames):
    """The source action's foot pose markers, as the Motion Queue reads them
    (synthesis.marker_overrides): `foot.L=supporting` plants the foot from that frame to the
    limb's next marker (or the range's end), another constraint lifts it; hand and root markers
    are the Motion Queue's alone."""
    from ...solver.motion_control.contacts import Contact
    from ..synthesis.job import marker_overrides
    return tuple(Contact(limb[-1], start, end, cons == "supporting")
                 for limb, start, end, cons in marker_overrides(action, frames) if limb.startswith("foot."))


# ---- the job ------------------------------------------------------------------------------------

def stress_channels(obj, skeleton, result):
    """Custom-property curves: stress per bone, balance error and falling on the object."""
    stress = np.linalg.norm(np.asarray(result.stress, float), axis=-1)  # (F, J)
    channels = {}
    for j, bone in enumerate(skeleton.names):
        pb = obj.pose.bones[bone]
        if STRESS not in pb:
            pb[STRESS] = 0.0  # the property must exist for its curve to evaluate
        channels[(f'{bone_path(bone)}["{STRESS}"]', bone)] = stress[:, j]
    for prop in (BALANCE_ERROR, FALLING):
        if prop not in obj:
            obj[prop] = 0.0
    channels[(f'["{BALANCE_ERROR}"]', "HumanAnim")] = np.nan_to_num(result.balance_error, nan=FALLING_BALANCE)
    channels[(f'["{FALLING}"]', "HumanAnim")] = np.asarray(result.falling, float)
    return channels


def bone_segments(skeleton, traj):
    """World heads and tails (F, J, 2, 3) in metres."""
    world = traj.world_frames(skeleton)
    heads = world[..., :3, 3]
    tails = heads + world[..., :3, 1] * skeleton.lengths[:, None]
    return np.stack((heads, tails), axis=2)


def facing(skeleton, traj):
    """The horizontal direction the input faces on average (left hip to right hip, turned), or None."""
    left, right = skeleton.role_index("thigh.L"), skeleton.role_index("thigh.R")
    if left is None or right is None:
        return None
    heads = traj.world_frames(skeleton)[:, :, :3, 3]
    lateral = (heads[:, left, :2] - heads[:, right, :2]).mean(axis=0)
    if np.linalg.norm(lateral) < 1e-6:
        return None
    lateral /= np.linalg.norm(lateral)
    return np.array([lateral[1], -lateral[0]])  # left x up


def ground_of(settings, skeleton, traj):
    if settings.ground_height is not None:
        return float(settings.ground_height)
    from ...solver.motion_control.contacts import contact_floor
    return contact_floor(skeleton, traj)


def run(obj, scene):
    """The dynamic control job: read the source motion, control it, write a new action with
    stress curves and keep the overlay's data. Yields progress; returns a summary dict."""
    from ...solver.motion_control.controller import iter_control
    if obj is None or obj.type != "ARMATURE":
        raise RigError("select an armature object")
    props = scene.humananim_control
    source = props.action or (obj.animation_data.action if obj.animation_data else None)
    if source is None:
        raise MotionError(f"'{obj.name}' has no action to control: choose a source action")
    rig = RigView(obj, scene)  # a control rig: the deform bones as Blender shows them, keyed through the controls
    skeleton = rig.skeleton
    traj = yield from rig.iter_read(source, frame_range=frame_range(props, source))
    if traj.frame_count < 3:
        raise MotionError(f"'{source.name}' has {traj.frame_count} frames in the range: at least 3 are needed")
    settings = replace(solver_settings(scene, props, obj, skeleton, traj),
                       support_overrides=contact_overrides(source, traj.frames))
    t0 = time.perf_counter()
    result = yield from iter_control(skeleton, traj, settings)
    seconds = time.perf_counter() - t0
    out = yield from rig.iter_write(result.trajectories, f"{source.name}.control", scene.humananim.output, source,
                                    stress_channels(obj, skeleton, result))
    unit = scene.unit_settings.scale_length
    stress = np.linalg.norm(np.asarray(result.stress, float), axis=-1)
    CACHE[(obj.name, out.name)] = OverlayData(
        frames=traj.frames.copy(), ghost=bone_segments(skeleton, traj) / unit,
        bones=bone_segments(skeleton, result.trajectories) / unit, control=np.asarray(result.control, np.int8),
        stress=stress, zmp=np.asarray(result.zmp, float) / unit,
        polygons=[np.asarray(p, float).reshape(-1, 2) / unit for p in result.polygon],
        ground=ground_of(settings, skeleton, traj) / unit, falling=np.asarray(result.falling, bool),
        forward=facing(skeleton, traj))
    peak = np.unravel_index(np.argmax(stress), stress.shape) if stress.size else (0, 0)
    control = np.asarray(result.control)
    balance = np.asarray(result.balance_error, float)
    return {"source_action": source.name, "action": out.name, "frames": traj.frame_count, "fps": traj.fps,
            "frame_range": [float(traj.frames[0]), float(traj.frames[-1])],
            "simulated_seconds": traj.frame_count / traj.fps, "seconds": round(seconds, 3),
            "control_seconds": round(seconds, 3),
            "real_time_factor": traj.frame_count / traj.fps / max(seconds, 1e-9),
            "peak_stress_nm": float(stress.max()) if stress.size else 0.0,
            "peak_stress_bone": skeleton.names[peak[1]],
            "peak_stress_frame": float(traj.frames[peak[0]]),
            "max_balance_error_m": float(np.nanmax(balance)) if np.isfinite(balance).any() else 0.0,
            "frames_falling": int(np.count_nonzero(result.falling)),
            "max_foot_slide_mm": float(np.nanmax(np.asarray(result.foot_slide, float)) * 1000.0)
            if np.size(result.foot_slide) else 0.0,
            "frames_controlled": {kind: int(np.count_nonzero((control == code).any(axis=1)))
                                  for code, kind in enumerate(CONTROL_KINDS) if code},
            "loads_kg": {load.bone: load.mass for load in settings.loads},
            "impulses": len(settings.impulses), "colliders": [props.collider.name] if settings.colliders else [],
            "ground_height_m": ground_of(settings, skeleton, traj) if settings.ground_height is None
            else settings.ground_height, **rig.summary()}


def add_impulse(obj, scene, bone_name, frame, direction=None, magnitude=30.0, duration=0.0):
    """An arrow Empty in front of the bone (see arrows.place_arrow), registered as an impulse."""
    return add_arrow(obj, scene, scene.humananim_control, "impulses", "impulse_index", bone_name, frame, direction,
                     magnitude, duration, "Impulse")
