"""Which F-curves are processed, grouped per property, sampled and turned into working channels."""

import re
from dataclasses import dataclass, field

import bpy
import numpy as np

from ...solver import rotations
from ...solver.errors import MotionError
from ...solver.sequence import channels as seq_channels
from .. import action_api

_BONE = re.compile(r'^pose\.bones\["((?:[^"\\]|\\.)*)"\]\.(.+)$')
ROTATION_PROPS = {"rotation_quaternion": "quaternion", "rotation_euler": "euler",
                  "rotation_axis_angle": "axis_angle"}


def _enum_value(prop, item):
    return bpy.types.Keyframe.bl_rna.properties[prop].enum_items[item].value


# -- which curves ------------------------------------------------------------------------------

@dataclass
class Group:
    """F-curves processed together: one rotation property (all its components), or one curve."""

    data_path: str
    kind: str  # 'quaternion', 'euler', 'axis_angle', 'location' (metres = value * scale), 'value'
    fcurves: list  # per component: the source F-curve, or None (then `defaults`)
    defaults: list
    bone: str = None
    order: str = "XYZ"  # Euler order
    scale: float = 1.0  # metres per unit, for 'location'
    group_name: str = ""

    @property
    def indices(self):
        return range(len(self.fcurves))

    @property
    def label(self):
        if self.bone is not None:
            return f"{self.bone} {self.data_path.rsplit('.', 1)[-1]}"
        return self.data_path


def bone_of(data_path):
    m = _BONE.match(data_path)
    return bpy.utils.unescape_identifier(m.group(1)) if m else None


def _property_of(data_path):
    m = _BONE.match(data_path)
    return m.group(2) if m else data_path


@dataclass
class Selection:
    action: object
    groups: list
    note: str = ""
    others: list = field(default_factory=list)  # curves not processed (copied as they are)

    @property
    def fcurves(self):
        return [fc for g in self.groups for fc in g.fcurves if fc is not None]

    @property
    def bones(self):
        return sorted({g.bone for g in self.groups if g.bone is not None})


def location_scale(obj, scene, bone=None):
    """Metres per unit of a location channel: the armature's scale for bones, the scene's unit."""
    scale = float(scene.unit_settings.scale_length)
    if bone is not None:
        scale *= float(np.mean(np.abs(np.array(obj.matrix_world.to_scale()))))
    return scale


def _current_value(obj, data_path, index):
    try:
        value = obj.path_resolve(data_path)
    except (ValueError, AttributeError):
        return 0.0
    try:
        return float(value[index])
    except TypeError:
        return float(value)


def _make_group(obj, scene, data_path, curves, size):
    """A Group for data_path from {index: fcurve}."""
    bone = bone_of(data_path)
    prop = _property_of(data_path).rsplit(".", 1)[-1]
    kind = ROTATION_PROPS.get(prop, "location" if prop == "location" else "value")
    if kind in ("quaternion", "euler", "axis_angle"):
        size = 4 if kind != "euler" else 3
    fcs = [curves.get(i) for i in range(size)]
    defaults = [_current_value(obj, data_path, i) for i in range(size)]
    order = "XYZ"
    if kind == "euler":
        owner = obj.pose.bones.get(bone) if bone is not None and obj.pose else (obj if bone is None else None)
        mode = getattr(owner, "rotation_mode", "XYZ")
        order = mode if mode in rotations.EULER_ORDERS else "XYZ"
    first = next(fc for fc in fcs if fc is not None)
    group_name = first.group.name if first.group else (bone or "Object Transforms")
    return Group(data_path, kind, fcs, defaults, bone, order,
                 location_scale(obj, scene, bone) if kind == "location" else 1.0, group_name)


def groups_of(obj, scene, fcurves):
    """Rotation properties as whole groups (all components), locations as vectors, others alone."""
    by_path = {}
    for fc in fcurves:
        by_path.setdefault(fc.data_path, {})[fc.array_index] = fc
    groups = []
    for path, curves in by_path.items():
        prop = _property_of(path).rsplit(".", 1)[-1]
        if prop in ROTATION_PROPS or prop == "location":
            groups.append(_make_group(obj, scene, path, curves, max(curves) + 1 if prop == "location" else 0))
            if prop == "location":  # only the keyed components of a location
                g = groups[-1]
                keep = [i for i, fc in enumerate(g.fcurves) if fc is not None]
                if len(keep) < len(g.fcurves):
                    groups.pop()
                    for i in keep:
                        groups.append(_single(obj, scene, curves[i], "location"))
        else:
            for i in sorted(curves):
                groups.append(_single(obj, scene, curves[i], "value"))
    return groups


def _single(obj, scene, fc, kind):
    bone = bone_of(fc.data_path)
    return Group(fc.data_path, kind, [fc], [_current_value(obj, fc.data_path, fc.array_index)], bone,
                 scale=location_scale(obj, scene, bone) if kind == "location" else 1.0,
                 group_name=fc.group.name if fc.group else (bone or "Object Transforms"))


def select_channels(obj, scene, action, mode="ALL", bones=(), paths=None):
    """The groups to process. mode: 'CURVES' (the F-curves selected in the Graph Editor),
    'BONES' (the curves of `bones`), 'ALL'. An empty selection falls back to every curve."""
    all_curves = action_api.fcurves_of(action, obj)
    if not all_curves:
        raise MotionError(f"'{action.name}' has no F-curves for '{obj.name}'")
    note = ""
    if mode == "CURVES":
        chosen = [fc for fc in all_curves if fc.select]
        what = "no F-curves selected"
    elif mode == "BONES":
        wanted = set(bones)
        chosen = [fc for fc in all_curves if bone_of(fc.data_path) in wanted]
        what = "no keyed bones selected"
    elif mode == "PATHS":
        chosen = [fc for fc in all_curves if fc.data_path in set(paths or ())]
        what = "no matching curves"
    else:
        chosen, what = all_curves, ""
    if not chosen:
        chosen = all_curves
        note = f"{what}: all {len(all_curves)} curves" if what else ""
    # a rotation component brings its whole property
    rot_paths = {fc.data_path for fc in chosen if _property_of(fc.data_path).rsplit(".", 1)[-1] in ROTATION_PROPS}
    ids = {(fc.data_path, fc.array_index) for fc in chosen}
    chosen = [fc for fc in all_curves if (fc.data_path, fc.array_index) in ids or fc.data_path in rot_paths]
    chosen_ids = {id(fc) for fc in chosen}
    others = [fc for fc in all_curves if id(fc) not in chosen_ids]
    return Selection(action, groups_of(obj, scene, chosen), note, others)


def selection_for_context(context, obj, action, mode="AUTO"):
    """'AUTO': the Graph Editor's selected curves there, else the selected pose bones in pose
    mode, else everything."""
    scene = context.scene
    if mode == "AUTO":
        space = getattr(context, "space_data", None)
        if space is not None and space.type == "GRAPH_EDITOR":
            mode = "CURVES"
        elif obj.mode == "POSE":
            mode = "BONES"
        else:
            mode = "ALL"
    bones = ()
    if mode == "BONES":
        bones = [pb.name for pb in (getattr(context, "selected_pose_bones", None) or ()) if pb.id_data == obj]
    return select_channels(obj, scene, action, mode, bones)


# -- sampling, and the working channels ---------------------------------------------------------

def action_frames(action):
    start, end = action.frame_range
    return np.arange(int(np.floor(start)), int(np.ceil(end)) + 1, dtype=float)


def sample_group(group, frames):
    out = np.empty((len(frames), len(group.fcurves)))
    for i, (fc, default) in enumerate(zip(group.fcurves, group.defaults)):
        out[:, i] = default if fc is None else [fc.evaluate(f) for f in frames]
    return out


def as_quaternions(group, values):
    if group.kind == "axis_angle":
        return rotations.from_axis_angle(values)
    return rotations.normalize(values)


def from_quaternions(group, q):
    if group.kind == "axis_angle":
        return rotations.to_axis_angle(q)
    return q


def unrolled(groups, samples):
    """Samples made continuous: quaternions on one hemisphere, Eulers unrolled (all groups of
    one order at once: the frame loop is serial)."""
    out = list(samples)
    by_order = {}
    for k, g in enumerate(groups):
        if g.kind == "euler":
            by_order.setdefault(g.order, []).append(k)
        elif g.kind == "quaternion":
            out[k] = rotations.make_continuous(samples[k])
    for order, ks in by_order.items():
        u = rotations.unroll_euler(np.stack([samples[k] for k in ks], axis=1), order)
        for i, k in enumerate(ks):
            out[k] = u[:, i]
    return out


def to_working(groups, samples):
    """(F, C) channels to filter: tangent vectors (radians) about each rotation's mean for
    quaternions and axis-angles, unrolled angles for Eulers, values otherwise; and the layout
    to go back."""
    cols = unrolled(groups, samples)
    states = [None] * len(groups)
    rot = [k for k, g in enumerate(groups) if g.kind in ("quaternion", "axis_angle")]
    if rot:
        q = rotations.make_continuous(np.stack([as_quaternions(groups[k], samples[k]) for k in rot], axis=1))
        ref = seq_channels.mean_quaternion(q)
        v = seq_channels.to_tangent(q, ref)
        for i, k in enumerate(rot):
            cols[k], states[k] = v[:, i], (ref[i], q[:1, i])
    widths = [c.shape[1] for c in cols]
    return np.concatenate(cols, axis=1), (widths, states)


def from_working(groups, work, layout):
    widths, states = layout
    out, at = [], 0
    for g, w, state in zip(groups, widths, states):
        x = work[:, at:at + w]
        at += w
        if g.kind in ("quaternion", "axis_angle"):
            out.append(from_quaternions(g, seq_channels.from_tangent(x, state[0], like=state[1])))
        else:
            out.append(x)
    return out


def working_kinds(groups, layout):
    kinds = []
    for g, w in zip(groups, layout[0]):
        kind = "rotation" if g.kind in ("quaternion", "axis_angle", "euler") else g.kind
        kinds += [kind] * w
    return np.array(kinds)
