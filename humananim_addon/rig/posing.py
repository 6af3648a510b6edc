"""Solved poses keyed through a control rig's controls (see controls.py): each mapped control is
put where the solved pose puts the bone it carries, its parent carried rigidly by the nearest
ancestor whose new frame is known, then checked (and corrected frame by frame) with Blender's own
evaluation; the controls' keys and the IK/FK switches go to a NEW action."""

import bpy
import numpy as np

from ...solver import rotations
from .. import action_api, actions
from .controls import map_controls


def key_through_controls(obj, scene, skeleton, crig, frames, base, out, name,
                         advice="key the FK controls yourself, or map the roles to them"):
    """The new action keying the controls of `crig` so that the rig shows the solved local bases
    `out` (F, J, 4, 4, metres) over `frames`; `base`: the poses the solver started from."""
    moved = [j for j in range(skeleton.joint_count)
             if j not in crig.frozen and np.abs(out[:, j] - base[:, j]).max() > 1e-9]
    map_controls(obj, skeleton, crig, moved, advice)
    crig.controls = {j: v for j, v in crig.controls.items() if j in moved}
    actual = base if crig.actual is None else np.broadcast_to(crig.actual, base.shape)
    targets, known, old = control_targets(skeleton, crig, actual, out)
    bases = control_bases(obj, skeleton, targets, known, old)
    keys = write_controls(obj, scene, crig, frames, bases, name)
    sample = sorted({0, len(frames) // 2, len(frames) - 1})
    pos, ang = control_errors(obj, scene, skeleton, frames, targets, sample)
    if pos > 2e-4 or ang > 1e-3:  # a parent not carried rigidly: Blender's evaluation, frame by frame
        bases = correct_controls(obj, scene, skeleton, frames, targets, bases)
        write_controls(obj, scene, crig, frames, bases, name, keys)
    return keys.action


def control_targets(skeleton, crig, base, out):
    """Armature-space frames (metres) of every mapped control over the frames: where the solved
    pose puts the bone it carries, times the control's rest frame in the bone's. Also each
    known bone's old and new frames {bone: (old (F,4,4), new (F,4,4))}."""
    old, new = skeleton.world_frames(base), skeleton.world_frames(out)
    targets, known = {}, {}
    for j, (c, offset) in sorted(crig.controls.items()):
        targets[c] = new[:, j] @ offset
        known[c] = (old[:, skeleton.index(c)], targets[c])
        known[skeleton.names[j]] = (old[:, j], new[:, j])
    return targets, known, old


def control_bases(obj, skeleton, targets, known, old):
    """{control: (F, 4, 4) pose-bone basis (armature units)}: each control's parent is carried
    rigidly by its nearest ancestor whose new frame is known (checked afterwards by Blender's
    own evaluation, `correct_controls`)."""
    bases = {}
    for c in sorted(targets, key=skeleton.index):
        pb = obj.pose.bones[c]
        j = skeleton.index(c)
        if pb.parent is None:
            parent = np.eye(4)[None]
        else:
            p = skeleton.index(pb.parent.name)
            parent = old[:, p]
            x = pb.parent
            while x is not None:
                if x.name in known:
                    was, now = known[x.name]
                    parent = now @ np.linalg.solve(was, old[:, p])
                    break
                x = x.parent
        basis = np.linalg.solve(parent @ skeleton.rest_local[j], targets[c])
        basis[..., :3, 3] /= skeleton.unit_scale
        bases[c] = basis
    return bases


def control_errors(obj, scene, skeleton, frames, targets, sample):
    """Largest position (m) and angle (rad) between Blender's evaluated controls and their
    targets, on the frames at `sample` (indices)."""
    pos, ang = 0.0, 0.0
    keep = scene.frame_current
    for k in sample:
        scene.frame_set(int(frames[k]))
        for c, t in targets.items():
            m = np.array(obj.pose.bones[c].matrix, dtype=float)
            m[:3, :3] /= np.linalg.norm(m[:3, :3], axis=0)
            m[:3, 3] *= skeleton.unit_scale
            pos = max(pos, float(np.linalg.norm(m[:3, 3] - t[k, :3, 3])))
            cos = (np.trace(m[:3, :3].T @ t[k, :3, :3]) - 1.0) / 2.0
            ang = max(ang, float(np.arccos(np.clip(cos, -1.0, 1.0))))
    scene.frame_set(keep)
    return pos, ang


def correct_controls(obj, scene, skeleton, frames, targets, bases):
    """Blender's evaluation frame by frame: each control's basis from its evaluated parent, again
    until no control changes (a parent that follows constraints non-rigidly, e.g. a spine bone
    copying half of the chest)."""
    from mathutils import Matrix
    pbs = obj.pose.bones
    view_layer = bpy.context.view_layer
    keep = scene.frame_current
    order = sorted(targets, key=skeleton.index)
    rest_local = {c: skeleton.rest_local[skeleton.index(c)].copy() for c in order}
    for c in order:
        rest_local[c][:3, 3] /= skeleton.unit_scale
    for k, f in enumerate(frames):
        scene.frame_set(int(f))
        for _ in range(len(order) + 1):
            change = 0.0
            for c in order:
                pb = pbs[c]
                parent = np.array(pb.parent.matrix) if pb.parent else np.eye(4)
                t = targets[c][k].copy()
                t[:3, 3] /= skeleton.unit_scale
                b = np.linalg.solve(parent @ rest_local[c], t)
                b[:3, :3] /= np.linalg.norm(b[:3, :3], axis=0)
                change = max(change, float(np.abs(b - bases[c][k]).max()))
                bases[c][k] = b
                pb.matrix_basis = Matrix(b.tolist())
            if change < 1e-7:
                break
            view_layer.update()
    scene.frame_set(keep)
    return bases


def _new_action_keys(obj, source, name, copy_source):
    """A writer into a NEW action for the control rig: a copy of the source (so every other
    control keeps its keys), or a fresh one."""
    if source is not None and copy_source and (not action_api.SLOTTED or action_api.object_slot(source, obj)):
        action = source.copy()
        action.name = name
        return action_api.ChannelWriter(action, obj, existing=True)
    return action_api.ChannelWriter(bpy.data.actions.new(name), obj)


def write_controls(obj, scene, crig, frames, bases, name, keys=None):
    """Keys the controls' bases and the IK/FK switches (CONSTANT, the value before the range kept
    on the frame before) into a new action (`keys`, reused when correcting)."""
    output = getattr(getattr(scene, "humananim", None), "output", "ACTION")
    ad = obj.animation_data
    source = ad.action if ad else None
    first = keys is None
    if first:
        keys = _new_action_keys(obj, source, name, copy_source=output != "NLA")
    for c, b in bases.items():
        pb = obj.pose.bones[c]
        path = actions.bone_path(c)
        q = rotations.make_continuous(rotations.from_matrix(b[:, :3, :3]))
        prop, values = actions.rotation_channels(q, pb.rotation_mode)
        for i in range(values.shape[1]):
            keys.replace_keys(f"{path}.{prop}", i, c, frames, values[:, i])
        loc = b[:, :3, 3]
        keyed = keys.has(f"{path}.location", 0)  # the source's location keys are replaced too
        if not obj.data.bones[c].use_connect and (keyed or not np.allclose(loc, 0.0, atol=1e-7)):
            for i in range(3):
                keys.replace_keys(f"{path}.location", i, c, frames, loc[:, i])
    if first:
        for (bone, prop), value in crig.switches.items():
            path = f'{actions.bone_path(bone)}["{bpy.utils.escape_identifier(prop)}"]'
            before = _value_before(obj, source, path, frames[0] - 1, obj.pose.bones[bone][prop])
            fc = keys.replace_keys(path, 0, bone, frames, np.full(len(frames), float(value)), "CONSTANT")
            if abs(before - value) > 1e-9 and not any(abs(k.co[0] - (frames[0] - 1)) < 0.5 for k in fc.keyframe_points):
                kp = fc.keyframe_points.insert(float(frames[0] - 1), float(before), options={"FAST"})
                kp.interpolation = "CONSTANT"
                fc.update()
        if source is not None:
            source.use_fake_user = True
        if output == "NLA":
            action_api.push_to_nla(obj, keys.action, keys.slot, f"HumanAnim: {name}", frames[0])
        else:
            action_api.assign_action(obj, keys.action, keys.slot)
    return keys


def _value_before(obj, source, path, frame, current):
    for fc in (action_api.fcurves_of(source, obj) if source is not None else ()):
        if fc.data_path == path:
            return float(fc.evaluate(frame))
    return float(current)
