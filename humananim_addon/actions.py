"""Actions to dense trajectories and back: every rotation mode, rolls, units, both action APIs."""

import logging
import re

import bpy
import numpy as np

from ..solver import rotations
from ..solver.errors import MotionError
from ..solver.progress import run_to_end
from ..solver.skeleton import compose, decompose
from ..solver.trajectories import Trajectories
from . import action_api
from .armature import armature_to_world

log = logging.getLogger(__name__)

_BONE_PATH = re.compile(r'^pose\.bones\["((?:[^"\\]|\\.)*)"\]\.(location|rotation_quaternion|rotation_euler|rotation_axis_angle)$')
EULER_MODES = set(rotations.EULER_ORDERS)


def scene_fps(scene):
    return scene.render.fps / scene.render.fps_base


def needs_evaluation(obj):
    """Constraints or drivers make F-curve values differ from what Blender shows."""
    ad = obj.animation_data
    return any(pb.constraints for pb in obj.pose.bones) or bool(ad and len(ad.drivers))


def sample_frames(action, obj, frame_range=None, on_keys=False):
    """Integer frames over the range (the action's own by default), or the union of its key times."""
    if on_keys:
        keys = {round(k.co[0], 6) for fc in action_api.fcurves_of(action, obj) for k in fc.keyframe_points}
        frames = np.array(sorted(keys))
        if frame_range is not None:
            frames = frames[(frames >= frame_range[0]) & (frames <= frame_range[1])]
    else:
        start, end = frame_range if frame_range is not None else action.frame_range
        frames = np.arange(int(np.floor(start)), int(np.ceil(end)) + 1, dtype=float)
    if len(frames) == 0:
        raise MotionError(f"'{action.name}' has no keys in the frame range")
    return frames


def read_action(obj, scene, skeleton, action=None, frame_range=None, on_keys=False, exact=None):
    """Trajectories of `action` (the active one by default) on `skeleton`.

    `exact` (default: when the rig has constraints or drivers) evaluates every frame through
    the depsgraph; otherwise F-curves are sampled directly, which is much faster."""
    return run_to_end(iter_read_action(obj, scene, skeleton, action, frame_range, on_keys, exact))


def iter_read_action(obj, scene, skeleton, action=None, frame_range=None, on_keys=False, exact=None):
    """read_action as steps: yields progress in [0, 1], returns the Trajectories. Closing it
    early restores the scene (frame, assigned action) and returns nothing."""
    ad = obj.animation_data
    action = action or (ad.action if ad else None)
    if action is None:
        raise MotionError(f"'{obj.name}' has no action to read")
    frames = sample_frames(action, obj, frame_range, on_keys)
    if exact is None:
        exact = needs_evaluation(obj)
    if exact:
        basis = yield from _evaluated_basis(obj, scene, skeleton, action, frames)
    else:
        basis = _fcurve_basis(obj, skeleton, action, frames)
    trans, quats = decompose(basis)
    return Trajectories(frames, scene_fps(scene), rotations.make_continuous(quats),
                        trans * skeleton.unit_scale, armature_to_world(obj, scene))


def bone_channel(data_path):
    """(bone name, transform property) an F-curve's path keys, or None for anything else."""
    m = _BONE_PATH.match(data_path)
    return (bpy.utils.unescape_identifier(m.group(1)), m.group(2)) if m else None


def _fcurve_basis(obj, skeleton, action, frames):
    channels = {}
    for fc in action_api.fcurves_of(action, obj):
        channel = bone_channel(fc.data_path)
        if channel and not fc.mute:
            channels[(*channel, fc.array_index)] = fc
    n_frames, n = len(frames), skeleton.joint_count
    trans, quats = np.zeros((n_frames, n, 3)), np.zeros((n_frames, n, 4))
    for j, name in enumerate(skeleton.names):
        pb = obj.pose.bones[name]
        mode = pb.rotation_mode
        if not skeleton.connected[j]:  # Blender ignores a connected bone's location
            trans[:, j] = _sample(channels, name, "location", pb.location, frames)
        if mode == "QUATERNION":
            quats[:, j] = rotations.normalize(_sample(channels, name, "rotation_quaternion",
                                                      pb.rotation_quaternion, frames))
        elif mode == "AXIS_ANGLE":
            quats[:, j] = rotations.from_axis_angle(_sample(channels, name, "rotation_axis_angle",
                                                            pb.rotation_axis_angle, frames))
        else:
            quats[:, j] = rotations.from_euler(_sample(channels, name, "rotation_euler",
                                                       pb.rotation_euler, frames), mode)
    if not (np.isfinite(trans).all() and np.isfinite(quats).all()):
        bad = np.flatnonzero(~(np.isfinite(trans).all(axis=(1, 2)) & np.isfinite(quats).all(axis=(1, 2))))
        raise MotionError(f"'{action.name}' has NaN or infinite keys (first at frame {frames[bad[0]]:g})")
    return compose(trans, quats)


def _sample(channels, bone, prop, current, frames):
    out = np.empty((len(frames), len(current)))
    for i, value in enumerate(current):
        fc = channels.get((bone, prop, i))
        out[:, i] = value if fc is None else [fc.evaluate(f) for f in frames]
    return out


def _evaluated_basis(obj, scene, skeleton, action, frames):
    """Pose through the depsgraph, turned into the basis a plain FK rig would need."""
    ad = obj.animation_data_create() if obj.animation_data is None else obj.animation_data
    saved = (ad.action, getattr(ad, "action_slot", None), ad.use_nla, scene.frame_current, scene.frame_subframe)
    n = skeleton.joint_count
    pose = np.empty((len(frames), n * 16))
    try:
        if ad.action != action:
            action_api.assign_action(obj, action, action_api.object_slot(action, obj))
        ad.use_nla = False
        for i, f in enumerate(frames):
            scene.frame_set(int(np.floor(f)), subframe=float(f - np.floor(f)))
            obj.pose.bones.foreach_get("matrix", pose[i])
            yield (i + 1) / len(frames)
    finally:
        if ad.action != saved[0]:
            ad.action = saved[0]
            if saved[1] is not None and saved[0] is not None:
                ad.action_slot = saved[1]
        ad.use_nla = saved[2]
        scene.frame_set(saved[3], subframe=saved[4])
    basis = rigid_basis(pose.reshape(len(frames), n, 4, 4).transpose(0, 1, 3, 2), skeleton)
    basis[..., :3, 3] /= skeleton.unit_scale
    return basis


def rigid_basis(matrices, skeleton):
    """Local bases (..., J, 4, 4), metres, with which a rigid FK skeleton reproduces the armature-space
    pose matrices (..., J, 4, 4) Blender evaluated (Blender units). Changes `matrices`.

    Stretch and scale (e.g. Rigify's stretchy limbs) can't live in a rigid skeleton: every bone's
    matrix is made rigid first, so the rigid chain reproduces each bone's world pose exactly."""
    matrices[..., :3, :3] /= np.linalg.norm(matrices[..., :3, :3], axis=-2, keepdims=True)
    matrices[..., :3, 3] *= skeleton.unit_scale
    parent = np.where(skeleton.parents[:, None, None] >= 0,
                      matrices[..., np.maximum(skeleton.parents, 0), :, :], np.eye(4))
    return np.linalg.solve(parent @ skeleton.rest_local, matrices)


def write_action(obj, skeleton, traj, name, output="ACTION", source=None, extra_channels=None, bones=None):
    """A new action from trajectories; `output` 'ACTION' makes it active, 'NLA' adds a track.

    `extra_channels` maps (data path, group) to (F, k) values keyed on the same frames (e.g.
    custom-property curves of joint torques). `bones`: only these are keyed (a control rig's
    controls, rig/bones.py: its constraint-driven bones are never keyed). The source action is
    never changed; it gets a fake user so it can't be lost."""
    action = bpy.data.actions.new(name)
    writer = action_api.ChannelWriter(action, obj)
    frames = traj.frames
    channels = _rotation_channels(obj, skeleton, traj)
    for j, bone in enumerate(skeleton.names):
        trans = traj.translations[:, j] / skeleton.unit_scale
        path = bone_path(bone)
        if j not in channels or (bones is not None and bone not in bones):
            continue  # rest pose throughout: no channel needed
        if not skeleton.connected[j] and not np.allclose(trans, 0.0, atol=1e-9):
            writer.key_columns(f"{path}.location", bone, frames, trans)
        prop, values = channels[j]
        writer.key_columns(f"{path}.{prop}", bone, frames, values)
    for (data_path, group), values in (extra_channels or {}).items():
        writer.key_columns(data_path, group, frames, values)
    if source is not None:
        source.use_fake_user = True
    if output == "NLA":
        track, _ = action_api.push_to_nla(obj, action, writer.slot, f"HumanAnim: {name}", frames[0])
        log.info("wrote '%s' on NLA track '%s'", action.name, track.name)
    else:
        action_api.assign_action(obj, action, writer.slot)
    return action


def _rotation_channels(obj, skeleton, traj):
    """{joint: (property, (F, k) values)} in each bone's own rotation mode, for moving bones.

    Euler curves are unrolled for all bones of one order at once (the frame loop is serial)."""
    quats = rotations.make_continuous(traj.rotations)
    still = np.all(np.isclose(np.abs(quats[..., 0]), 1.0), axis=0) & np.all(
        np.isclose(traj.translations, 0.0, atol=1e-9), axis=(0, 2))
    by_mode = {}
    for j, bone in enumerate(skeleton.names):
        if not still[j]:
            by_mode.setdefault(obj.pose.bones[bone].rotation_mode, []).append(j)
    out = {}
    for mode, joints in by_mode.items():
        prop, values = rotation_channels(quats[:, joints], mode)
        out.update({j: (prop, values[:, i]) for i, j in enumerate(joints)})
    return out


def rotation_channels(quaternions, mode):
    """(property, values) keying continuous `quaternions` (F, ..., 4) in a Blender rotation mode:
    the quaternions, axis-angle, or Euler angles of that order unrolled over the frames."""
    if mode == "QUATERNION":
        return "rotation_quaternion", quaternions
    if mode == "AXIS_ANGLE":
        return "rotation_axis_angle", rotations.to_axis_angle(quaternions)
    return "rotation_euler", rotations.unroll_euler(rotations.to_euler(quaternions, mode), mode)


def _write_channels(writer, data_path, group, frames, values):
    """ChannelWriter.key_columns under the name walking.py calls."""
    writer.key_columns(data_path, group, frames, values)


def bone_path(bone):
    return f'pose.bones["{bpy.utils.escape_identifier(bone)}"]'
