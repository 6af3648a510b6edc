"""Segment masses for a rig: stored values, anthropometric tables, or the bound mesh's volumes."""

import logging

import numpy as np

from ..solver.anthropometry import anthropometric_model
from ..solver.mass_properties import closed_mass_properties
from ..solver.errors import RigError

log = logging.getLogger(__name__)

_INERTIA_INDEX = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))


def mass_model_for(obj, scene, skeleton, total_mass=None):
    """Stored per-segment values when the armature has them, else a fresh model."""
    stored = read_stored(obj.data.humananim, skeleton)
    if stored is not None and total_mass is None:
        return stored
    return compute(obj, scene, skeleton, total_mass)


def compute(obj, scene, skeleton, total_mass=None):
    settings = obj.data.humananim
    total = settings.total_mass if total_mass is None else total_mass
    if settings.mass_source in {"AUTO", "MESH"}:
        meshes = bound_meshes(obj)
        if meshes:
            return mesh_model(obj, meshes, skeleton, settings.density, scene)
        if settings.mass_source == "MESH":
            log.warning("'%s' deforms no mesh: using anthropometric tables", obj.name)
    return anthropometric_model(skeleton, total, settings.body_type.lower())


def bound_meshes(armature):
    """Mesh objects deformed by the armature (through an Armature modifier)."""
    import bpy
    return [o for o in bpy.data.objects if o.type == "MESH" and any(
        m.type == "ARMATURE" and m.object == armature for m in o.modifiers)]


def segment_owner(skeleton):
    """For every joint, the joint of the nearest role bone at or above it (-1: none)."""
    role_joints = {skeleton.index(b) for bones in skeleton.roles.bones.values() for b in bones}
    owner = np.full(skeleton.joint_count, -1)
    for j, p in enumerate(skeleton.parents):
        owner[j] = j if j in role_joints else (owner[p] if p >= 0 else -1)
    return owner


def mesh_model(armature, meshes, skeleton, density, scene):
    """Each role segment's skin, capped where it meets its neighbours, integrated at `density`."""
    owner = segment_owner(skeleton)
    to_armature = np.linalg.inv(np.array(armature.matrix_world))
    pieces = {}
    for mesh_obj in meshes:
        verts, tris, segment = _mesh_segments(mesh_obj, to_armature, skeleton, owner)
        for j in np.unique(segment):
            if j >= 0:
                pieces.setdefault(j, []).append((verts, tris[segment == j]))
    n = skeleton.joint_count
    mass, com, inertia = np.zeros(n), np.zeros((n, 3)), np.zeros((n, 3, 3))
    for j, parts in pieces.items():
        m, c, i = _combine([closed_mass_properties(v, t, density) for v, t in parts])
        rot, origin = skeleton.rest[j, :3, :3], skeleton.rest[j, :3, 3]
        mass[j], com[j], inertia[j] = m, rot.T @ (c - origin), rot.T @ i @ rot
    if mass.sum() <= 0.0:
        raise RigError("the bound mesh gives no volume: is it weighted to the armature's bones?")
    return mass, com, inertia


def _mesh_segments(mesh_obj, to_armature, skeleton, owner):
    mesh = mesh_obj.data
    mesh.calc_loop_triangles()
    co = np.empty(len(mesh.vertices) * 3)
    mesh.vertices.foreach_get("co", co)
    m = to_armature @ np.array(mesh_obj.matrix_world)
    verts = (co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]) * skeleton.unit_scale
    tris = np.empty(len(mesh.loop_triangles) * 3, dtype=np.int32)
    mesh.loop_triangles.foreach_get("vertices", tris)
    tris = tris.reshape(-1, 3)
    group_joint = {g.index: _or_minus_one(skeleton.find(g.name)) for g in mesh_obj.vertex_groups}
    dominant = np.full(len(mesh.vertices), -1)
    for v in mesh.vertices:
        best = max(((g.weight, group_joint.get(g.group, -1)) for g in v.groups
                    if group_joint.get(g.group, -1) >= 0), default=(0.0, -1))
        dominant[v.index] = owner[best[1]] if best[1] >= 0 else -1
    corner = dominant[tris]
    # a triangle belongs to the segment of most of its corners (the first corner on a tie)
    segment = np.where(corner[:, 1] == corner[:, 2], corner[:, 1], corner[:, 0])
    return verts, tris, segment


def _or_minus_one(index):
    return -1 if index is None else index


def _combine(props):
    mass = sum(p[0] for p in props)
    if mass <= 0.0:
        return 0.0, np.zeros(3), np.zeros((3, 3))
    com = sum(p[0] * p[1] for p in props) / mass
    inertia = np.zeros((3, 3))
    for m, c, i in props:
        d = c - com
        inertia += i + m * (d @ d * np.eye(3) - np.outer(d, d))
    return mass, com, inertia


def store(settings, skeleton, mass, com, inertia):
    """Write the model onto the armature, where the panel shows it and the animator edits it."""
    settings.segments.clear()
    for j in np.flatnonzero(mass > 0.0):
        item = settings.segments.add()
        item.bone = skeleton.names[j]
        item.mass = mass[j]
        item.com = com[j]
        item.inertia = [inertia[j][a, b] for a, b in _INERTIA_INDEX]


def read_stored(settings, skeleton):
    if len(settings.segments) == 0:
        return None
    n = skeleton.joint_count
    mass, com, inertia = np.zeros(n), np.zeros((n, 3)), np.zeros((n, 3, 3))
    for item in settings.segments:
        j = skeleton.find(item.bone)
        if j is None:
            log.warning("stored mass model names a missing bone '%s': recomputing", item.bone)
            return None
        mass[j], com[j] = item.mass, item.com
        for value, (a, b) in zip(item.inertia, _INERTIA_INDEX):
            inertia[j][a, b] = inertia[j][b, a] = value
    return mass, com, inertia
