"""Armature to solver Skeleton: bones, units, roles (detected, then the animator's overrides)."""

import logging

import numpy as np

from ..solver import rotations
from ..solver.errors import RigError
from ..solver.role_detection import detect_roles, require_roles
from ..solver.skeleton import Skeleton
from .properties import role_overrides

log = logging.getLogger(__name__)


def unit_scale(obj, scene):
    """Metres per armature unit: the object's uniform scale and the scene's unit scale."""
    scale = np.array(obj.matrix_world.to_scale())
    if np.any(scale <= 0.0) or np.ptp(scale) > 1e-4 * scale.max():
        raise RigError(f"'{obj.name}' has a non-uniform or negative scale {tuple(np.round(scale, 4))}: "
                       "apply the scale (Ctrl+A > Scale) first")
    return float(scale.mean()) * float(scene.unit_settings.scale_length)


def armature_to_world(obj, scene):
    """The object's rigid transform (rotation and translation in metres), scale removed."""
    m = np.array(obj.matrix_world, dtype=float)
    m[:3, :3] /= np.linalg.norm(m[:3, :3], axis=0)
    m[:3, 3] *= scene.unit_settings.scale_length
    return m


def bone_arrays(obj, scale):
    """Names, parents, rest frames (metres) and lengths of every bone, parents first."""
    bones = list(obj.data.bones)  # Blender lists parents before children
    index = {b.name: i for i, b in enumerate(bones)}
    parents = np.array([index[b.parent.name] if b.parent else -1 for b in bones], dtype=int)
    rest = np.empty((len(bones), 16))
    obj.data.bones.foreach_get("matrix_local", rest.ravel())
    rest = rest.reshape(-1, 4, 4).transpose(0, 2, 1).copy()  # column-major per matrix
    # Blender stores them in single precision, rigid to ~1e-7: make them exact rotations so
    # forward and inverse kinematics agree to round-off
    rest[:, :3, :3] = rotations.to_matrix(rotations.from_matrix(rest[:, :3, :3]))
    rest[:, :3, 3] *= scale
    lengths = np.array([b.length for b in bones]) * scale
    connected = np.array([b.use_connect for b in bones], dtype=bool)
    return [b.name for b in bones], parents, rest, lengths, connected


def detect(obj):
    """Body roles found from the bones' names, hierarchy and geometry (no overrides)."""
    names, parents, rest, lengths, _ = bone_arrays(obj, 1.0)
    return _detect(obj, names, parents, rest, lengths)


def _detect(obj, names, parents, rest, lengths):
    heads = rest[:, :3, 3]
    deform = [obj.data.bones[n].use_deform for n in names]
    return detect_roles(names, parents, heads, heads + rest[:, :3, 1] * lengths[:, None], deform)


def joint_limits(obj, names):
    dof = np.ones((len(names), 3), dtype=bool)
    limits = np.tile([-np.inf, np.inf], (len(names), 3, 1)).astype(float)
    for j, name in enumerate(names):
        pb = obj.pose.bones[name]
        for a, axis in enumerate("xyz"):
            if getattr(pb, f"lock_ik_{axis}"):
                dof[j, a] = False
            elif getattr(pb, f"use_ik_limit_{axis}"):
                limits[j, a] = getattr(pb, f"ik_min_{axis}"), getattr(pb, f"ik_max_{axis}")
    return dof, limits


def skeleton_from_armature(obj, scene, total_mass=None, require=True, detection=None):
    """The solver's Skeleton of an armature object, with its roles and mass model. `detection`:
    detect(obj) when the caller already has it (role detection is the slow part on big rigs)."""
    if obj is None or obj.type != "ARMATURE":
        raise RigError("select an armature object")
    if len(obj.data.bones) == 0:
        raise RigError(f"'{obj.name}' has no bones")
    scale = unit_scale(obj, scene)
    names, parents, rest, lengths, connected = bone_arrays(obj, scale)
    detection = detection or _detect(obj, names, parents, rest, lengths)
    roles = detection.roles.with_overrides(role_overrides(obj.data.humananim))
    unknown = [b for bones in roles.bones.values() for b in bones if b not in obj.data.bones]
    if unknown:
        raise RigError(f"role override names bones that do not exist: {', '.join(unknown)}")
    if require:
        require_roles(type(detection)(roles, detection.convention, tuple(roles.missing()), detection.notes))
    dof, limits = joint_limits(obj, names)
    n = len(names)
    skeleton = Skeleton(names, parents, rest, lengths, connected, dof, limits,
                        np.zeros(n), np.zeros((n, 3)), np.zeros((n, 3, 3)), roles, scale)
    from .mass_model import mass_model_for
    mass, com, inertia = mass_model_for(obj, scene, skeleton, total_mass)
    return skeleton.with_mass_model(mass, com, inertia)
