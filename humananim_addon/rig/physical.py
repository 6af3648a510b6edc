"""The physical skeleton of any rig: its deform bones, hung in the body's hierarchy.

The solver's joints are the deform bones (what the mesh follows); a deform bone's parent is taken
from the body roles wherever the rig hangs it elsewhere (solver.rig.hierarchy), so the thigh's
parent is the pelvis even when a generated Rigify rig hangs DEF-thigh from ORG-/MCH- bones. Poses
are read from Blender's evaluation (the depsgraph) of the deform bones, so constraints, IK and
drivers are all accounted for."""

import numpy as np

from ...solver import rotations
from ...solver.errors import MotionError, RigError
from ...solver.rig.hierarchy import body_parents, parents_first
from ...solver.role_detection import require_roles
from ...solver.skeleton import Skeleton, decompose
from ...solver.trajectories import Trajectories
from .. import action_api
from ..actions import rigid_basis, sample_frames, scene_fps
from ..armature import armature_to_world, bone_arrays, detect, joint_limits, unit_scale
from ..properties import role_overrides


def physical_skeleton(obj, scene, total_mass=None, require=True):
    """The solver's Skeleton over the deform bones of armature `obj`, with roles and mass model.
    Its joints keep Blender's bone names; `skeleton.names` lists them parents first."""
    if obj is None or obj.type != "ARMATURE":
        raise RigError("select an armature object")
    scale = unit_scale(obj, scene)
    names, parents, rest, lengths, connected = bone_arrays(obj, scale)
    deform = np.array([obj.data.bones[n].use_deform for n in names], dtype=bool)
    if not deform.any():
        raise RigError(f"'{obj.name}' has no deform bones: nothing for a mesh to follow")
    detection = detect(obj)
    roles = detection.roles.with_overrides(role_overrides(obj.data.humananim))
    if require:
        require_roles(type(detection)(roles, detection.convention, tuple(roles.missing()), detection.notes))
    heads = rest[:, :3, 3]
    tails = heads + rest[:, :3, 1] * lengths[:, None]
    body = body_parents(names, parents, heads, tails, deform, roles)
    order = _depth_first(body, parents_first(body, np.flatnonzero(deform)))
    new = {j: i for i, j in enumerate(order)}
    joint_parents = np.array([new[body[j]] if body[j] >= 0 else -1 for j in order], dtype=int)
    kept = np.array([body[j] == parents[j] for j in order])  # a bone still on its own parent may stay connected
    sub = [names[j] for j in order]
    dof, limits = joint_limits(obj, sub)
    skeleton = Skeleton(sub, joint_parents, rest[order], lengths[order], connected[order] & kept, dof, limits,
                        np.zeros(len(order)), np.zeros((len(order), 3)), np.zeros((len(order), 3, 3)), roles, scale)
    from ..mass_model import mass_model_for
    return skeleton.with_mass_model(*mass_model_for(obj, scene, skeleton, total_mass))


def _depth_first(parents, order):
    """`order` (parents first) rearranged depth first, children in their given order: the order
    Blender lists an armature's bones in, so a plain copy of the physical skeleton has the same."""
    inside = set(order)
    children = {j: [] for j in order}
    roots = []
    for j in order:
        (children[parents[j]] if parents[j] in inside else roots).append(j)
    out, stack = [], roots[::-1]
    while stack:
        j = stack.pop()
        out.append(j)
        stack.extend(children[j][::-1])
    return out


def evaluated_pose(obj, scene, skeleton, frames, action=None):
    """Armature-space pose matrices (F, J, 4, 4) of the skeleton's bones on `frames`, in Blender
    units, as the depsgraph evaluates them (with `action`, the active one by default, assigned
    for the reading; scene frame and action are restored)."""
    index = {b.name: i for i, b in enumerate(obj.pose.bones)}
    try:
        pick = [index[n] for n in skeleton.names]
    except KeyError as e:
        raise RigError(f"'{obj.name}' has no bone {e.args[0]!r}") from None
    ad = obj.animation_data_create() if obj.animation_data is None else obj.animation_data
    saved = (ad.action, getattr(ad, "action_slot", None), scene.frame_current, scene.frame_subframe)
    all_bones = np.empty((len(frames), len(index) * 16))
    try:
        if action is not None and ad.action != action:
            action_api.assign_action(obj, action, action_api.object_slot(action, obj))
        for i, f in enumerate(frames):
            scene.frame_set(int(np.floor(f)), subframe=float(f - np.floor(f)))
            obj.pose.bones.foreach_get("matrix", all_bones[i])
    finally:
        if ad.action != saved[0]:
            ad.action = saved[0]
            if saved[1] is not None and saved[0] is not None:
                ad.action_slot = saved[1]
        scene.frame_set(saved[2], subframe=saved[3])
    return all_bones.reshape(len(frames), -1, 4, 4).transpose(0, 1, 3, 2)[:, pick]


def evaluated_basis(obj, scene, skeleton, frames, action=None):
    """Local bases (F, J, 4, 4), metres, with which the rigid physical skeleton reproduces the deform
    bones as Blender evaluates them (stretch removed, translations kept where a bone moved off
    its body parent)."""
    return rigid_basis(evaluated_pose(obj, scene, skeleton, frames, action), skeleton)


def physical_trajectories(obj, scene, skeleton, action=None, frame_range=None):
    """The Trajectories of `action` (the active one by default) on the physical skeleton, read
    from Blender's evaluation of the deform bones on every frame of the range."""
    ad = obj.animation_data
    action = action or (ad.action if ad else None)
    if action is None:
        raise MotionError(f"'{obj.name}' has no action to read")
    frames = sample_frames(action, obj, frame_range)
    trans, quats = decompose(evaluated_basis(obj, scene, skeleton, frames, action))
    return Trajectories(frames, scene_fps(scene), rotations.make_continuous(quats), trans,
                        armature_to_world(obj, scene))
