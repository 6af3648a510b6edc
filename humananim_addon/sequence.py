"""Keyframe sequence manipulation in Blender (Huang 1996 ch. 5): the bridge between an action's
F-curves and solver.sequence.

What is processed. The selected F-curves of the action (Graph Editor), or the channels of the
selected pose bones (3D view), or every channel when nothing is selected (the report says so).
A rotation is processed as a rotation: selecting one component of a bone's quaternion, Euler or
axis-angle property takes its whole property. Quaternion (and axis-angle) properties are
filtered and blended in the tangent space about their mean and renormalised; Euler properties
are unrolled first. Locations and any other curve (object transforms, custom properties, shape
keys) are used as they are.

What is written. A new action named after the source (".eq", ".blend", ".compressed",
".warped", ".squeezed"), assigned to the object; every curve that was not processed is copied
into it unchanged (keys, handles, interpolation), and the source action keeps its keys and gets
a fake user. With `replace=True` the processed curves of the source action are rewritten in
place instead. Filtered, blended and resampled curves are keyed on every frame (linear); key
compression, time warping of keys and squeeze/stretch write Bezier keys with FREE handles.

Units. Rotation tolerances and errors are degrees (of the bone's rotation, not of one
component); location tolerances are centimetres (through the armature's scale and the scene's
unit scale); other curves use their own units. Compression also reports the largest distance
any bone's tail, and a point 10 cm beyond it, moved on any frame (error_measures.tail_error).
"""

import logging
import re
import time
from dataclasses import dataclass, field

import bpy
import numpy as np
from bpy.props import CollectionProperty, FloatProperty, IntProperty, PointerProperty, StringProperty

from ..solver import rotations
from ..solver.errors import MotionError
from ..solver.progress import run_to_end
from ..solver.trajectories import Trajectories
from ..solver.sequence import (channels as seq_channels, equalizer, error_measures, key_reduction,
                               multiresolution_blend, pyramid, pyramid_compression, time_warp)
from . import action_api
from .actions import scene_fps
from .properties import settings_registration

log = logging.getLogger(__name__)

_BONE = re.compile(r'^pose\.bones\["((?:[^"\\]|\\.)*)"\]\.(.+)$')
ROTATION_PROPS = {"rotation_quaternion": "quaternion", "rotation_euler": "euler",
                  "rotation_axis_angle": "axis_angle"}
WARP_MARKER = re.compile(r"^\s*warp\s*[:=]\s*(-?\d+(?:\.\d+)?)\s*$", re.IGNORECASE)


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
    return m.group(1).replace('\\"', '"').replace("\\\\", "\\") if m else None


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


# -- writing -----------------------------------------------------------------------------------

def set_samples(fc, frames, values):
    """Linear keys on every frame."""
    kp = fc.keyframe_points
    kp.clear()
    kp.add(len(frames))
    kp.foreach_set("co", np.column_stack((frames, values)).ravel())
    kp.foreach_set("interpolation", np.full(len(frames), _enum_value("interpolation", "LINEAR"), np.int32))
    fc.update()


def set_keys(fc, keys):
    """Bezier keys from key_reduction.Keys with FREE handles (so update() keeps them)."""
    kp = fc.keyframe_points
    kp.clear()
    n = len(keys)
    kp.add(n)
    kp.foreach_set("co", np.column_stack((keys.times, keys.values)).ravel())
    free = np.full(n, _enum_value("handle_left_type", "FREE"), np.int32)
    kp.foreach_set("handle_left_type", free)
    kp.foreach_set("handle_right_type", free)
    kp.foreach_set("handle_left", np.asarray(keys.left, float).ravel())
    kp.foreach_set("handle_right", np.asarray(keys.right, float).ravel())
    interp = {name: _enum_value("interpolation", name) for name in ("BEZIER", "LINEAR", "CONSTANT")}
    kp.foreach_set("interpolation", np.array([interp.get(str(i), interp["BEZIER"]) for i in keys.interpolation],
                                             np.int32))
    fc.update()


_KEY_FLOATS = ("co", "handle_left", "handle_right")
_KEY_INTS = ("interpolation", "handle_left_type", "handle_right_type", "easing", "type")
_KEY_SCALARS = ("back", "amplitude", "period")


def read_keys(fc):
    """Keys of an F-curve (times, values, handles, interpolation names)."""
    n = len(fc.keyframe_points)
    co, left, right = np.empty(2 * n), np.empty(2 * n), np.empty(2 * n)
    fc.keyframe_points.foreach_get("co", co)
    fc.keyframe_points.foreach_get("handle_left", left)
    fc.keyframe_points.foreach_get("handle_right", right)
    co = co.reshape(n, 2)
    interp = np.array([k.interpolation for k in fc.keyframe_points], dtype=object)
    return key_reduction.Keys(co[:, 0].copy(), co[:, 1].copy(), left.reshape(n, 2), right.reshape(n, 2), interp)


def copy_keys(src, dst):
    """Every key of `src` into `dst` as it is."""
    n = len(src.keyframe_points)
    dst.keyframe_points.clear()
    dst.keyframe_points.add(n)
    for name in _KEY_FLOATS + _KEY_INTS + _KEY_SCALARS:
        size = 2 if name in _KEY_FLOATS else 1
        buf = np.empty(n * size, dtype=np.int32 if name in _KEY_INTS else np.float64)
        src.keyframe_points.foreach_get(name, buf)
        dst.keyframe_points.foreach_set(name, buf)
    dst.extrapolation = src.extrapolation
    dst.mute, dst.lock, dst.hide = src.mute, src.lock, src.hide
    dst.select = src.select
    dst.update()


class Output:
    """Where results go: a new action (other curves copied) or the source action in place."""

    def __init__(self, obj, source, name, replace=False):
        self.obj, self.source, self.replace = obj, source, replace
        self._curves = {}
        if replace:
            self.action = source
            self._curves = {(fc.data_path, fc.array_index): fc for fc in action_api.fcurves_of(source, obj)}
            self.writer = None
        else:
            self.action = bpy.data.actions.new(name)
            self.writer = action_api.ChannelWriter(self.action, obj)

    def fcurve(self, data_path, index, group_name):
        key = (data_path, index)
        fc = self._curves.get(key)
        if fc is None:
            if self.replace:
                fc = self._new_in_source(data_path, index, group_name)
            else:
                fc = self.writer.new_fcurve(data_path, index, group_name)
            self._curves[key] = fc
        return fc

    def _new_in_source(self, data_path, index, group_name):
        if not action_api.SLOTTED:
            return self.source.fcurves.new(data_path, index=index, action_group=group_name)
        slot = action_api.object_slot(self.source, self.obj)
        bag = self.source.layers[0].strips[0].channelbag(slot, ensure=True)
        return bag.fcurves.new(data_path, index=index)

    def copy_unprocessed(self, fcurves):
        if self.replace:
            return
        for fc in fcurves:
            group = fc.group.name if fc.group else (bone_of(fc.data_path) or "Object Transforms")
            copy_keys(fc, self.fcurve(fc.data_path, fc.array_index, group))

    def finish(self, pose_marker_map=None):
        """Pose markers copied (moved through `pose_marker_map`, or dropped where it gives None),
        the new action assigned, the source protected by a fake user."""
        if self.replace:
            return self.action
        for marker in self.source.pose_markers:
            frame = marker.frame if pose_marker_map is None else pose_marker_map(marker)
            if frame is not None:
                self.action.pose_markers.new(marker.name).frame = int(round(frame))
        self.source.use_fake_user = True
        action_api.assign_action(self.obj, self.action, self.writer.slot)
        return self.action


def write_groups(out, groups, frames, values):
    for g, v in zip(groups, values):
        if g.kind == "quaternion":
            v = rotations.make_continuous(v)
        for i, fc in enumerate(g.fcurves):
            set_samples(out.fcurve(g.data_path, i, g.group_name), frames, v[:, i])


# -- measures ----------------------------------------------------------------------------------

def group_errors(groups, a, b):
    """Largest rotation error (degrees, whole bone rotation), location error (cm) and other
    value error, between sample lists a and b, and the label where each happened."""
    out = {"deg": (0.0, ""), "cm": (0.0, ""), "value": (0.0, "")}
    for g, x, y in zip(groups, a, b):
        if g.kind in ("quaternion", "axis_angle"):
            e, key = float(error_measures.rotation_error_deg(as_quaternions(g, x), as_quaternions(g, y)).max()), "deg"
        elif g.kind == "euler":
            e, key = float(error_measures.euler_error_deg(x, y, g.order).max()), "deg"
        elif g.kind == "location":
            e, key = float(error_measures.location_error_cm(x * g.scale, y * g.scale).max()), "cm"
        else:
            e, key = float(np.abs(x - y).max()), "value"
        if e > out[key][0]:
            out[key] = (e, g.label)
    return out


def _tail_measure(obj, scene, source, groups, frames):
    """keys per group -> largest error (cm) at any bone's tail and 10 cm beyond, against the
    source, evaluated in numpy (no action is written)."""
    from .actions import read_action
    from .armature import skeleton_from_armature
    skeleton = skeleton_from_armature(obj, scene, require=False)
    base = read_action(obj, scene, skeleton, source, (frames[0], frames[-1]), exact=False)

    def measure(results):
        rot, trans = base.rotations.copy(), base.translations.copy()
        for g, keys in zip(groups, results):
            j = skeleton.find(g.bone) if g.bone else None
            if j is None:
                continue
            x = key_reduction.evaluate_channels(keys, frames)
            if g.kind == "location" and not skeleton.connected[j]:
                trans[:, j] = x * g.scale
            elif g.kind == "euler":
                rot[:, j] = rotations.from_euler(x, g.order)
            elif g.kind in ("quaternion", "axis_angle"):
                rot[:, j] = as_quaternions(g, x)
        played = Trajectories(base.frames, base.fps, rot, trans, base.armature_to_world)
        error = error_measures.tail_error(skeleton, base, played)
        return max(error.tail_cm, error.point_cm)
    return measure


def tail_errors(obj, scene, source, result, frames, beyond=0.10):
    """The largest tail and tail+`beyond` errors (cm) of every bone between two actions, as their
    F-curves evaluate (None when obj is no armature)."""
    if obj.type != "ARMATURE":
        return None
    from .actions import read_action
    from .armature import skeleton_from_armature
    skeleton = skeleton_from_armature(obj, scene, require=False)
    rng = (frames[0], frames[-1])
    a = read_action(obj, scene, skeleton, source, rng, exact=False)
    b = read_action(obj, scene, skeleton, result, rng, exact=False)
    return error_measures.tail_error(skeleton, a, b, beyond)


def _ms(t0):
    return round(1000.0 * (time.perf_counter() - t0), 1)


def _base_summary(obj, source, sel, out):
    return {"armature": obj.name, "source_action": source.name, "action": out.action.name,
            "replaced": out.replace, "curves": len(sel.fcurves), "groups": len(sel.groups),
            "bones": sel.bones, "selection_note": sel.note}


# -- equalizer ---------------------------------------------------------------------------------

MAX_LEVELS = 8


def default_levels(frame_count, levels=None):
    full = pyramid.max_levels(frame_count)
    return int(min(full, MAX_LEVELS if levels is None or levels <= 0 else levels))


def band_labels(fps, levels):
    limits = pyramid.band_limits_hz(fps, levels)
    return [f"{lo:.3g}-{hi:.3g} Hz" for lo, hi in limits[:-1]] + [f"< {limits[-1][1]:.3g} Hz (mean)"]


def equalize(obj, scene, source, sel, gains=None, levels=None, cutoff_hz=None, replace=False):
    """Band gains (finest band first, the top last) on the selected channels, or with cutoff_hz
    a low-pass removing the bands wholly above it; all gains 1 gives the source back."""
    t0 = time.perf_counter()
    frames = action_frames(source)
    if len(frames) < 3:
        raise MotionError(f"'{source.name}' is too short to filter ({len(frames)} frames)")
    fps = scene_fps(scene)
    levels = default_levels(len(frames), levels)
    if cutoff_hz:
        gains = equalizer.low_pass_gains(fps, cutoff_hz, levels)
    gains = list(gains if gains is not None else [1.0] * (levels + 1))[:levels + 1]
    gains += [1.0] * (levels + 1 - len(gains))
    samples = [sample_group(g, frames) for g in sel.groups]
    work, layout = to_working(sel.groups, samples)
    result = equalizer.equalize(work, gains, levels)
    values = from_working(sel.groups, result, layout)
    out = Output(obj, source, f"{source.name}.eq", replace)
    write_groups(out, sel.groups, frames, values)
    out.copy_unprocessed(sel.others)
    out.finish()
    changes = group_errors(sel.groups, samples, values)
    summary = _base_summary(obj, source, sel, out)
    summary.update(command="filter", frames=len(frames), levels=levels, gains=[float(g) for g in gains],
                   bands=band_labels(fps, levels), cutoff_hz=cutoff_hz,
                   largest_change_deg=round(changes["deg"][0], 4), largest_change_cm=round(changes["cm"][0], 4),
                   ms=_ms(t0))
    return summary


def band_energies(obj, scene, action, group, levels=None):
    """RMS of each band of one group's curve over the clip (degrees for rotations as tangent
    vectors, cm for locations, units otherwise), finest first, the top (mean pose) last."""
    frames = action_frames(action)
    levels = default_levels(len(frames), levels)
    work, layout = to_working([group], [sample_group(group, frames)])
    pyr = pyramid.laplacian_pyramid(work, levels)
    kind = working_kinds([group], layout)[0]
    unit = {"rotation": np.degrees(1.0), "location": 100.0 * group.scale}.get(kind, 1.0)
    energies = [float(np.sqrt((b ** 2).sum(axis=1).mean())) * unit for b in pyr.bands]
    energies.append(float(np.sqrt((pyr.top ** 2).sum(axis=1).mean())) * unit)
    units = {"rotation": "deg", "location": "cm"}.get(kind, "")
    return band_labels(scene_fps(scene), levels), energies, units


# -- multiresolution blend ---------------------------------------------------------------------

def nla_pair(obj):
    """The two NLA strips to blend: the two selected ones, else the first two in time."""
    ad = obj.animation_data
    strips = [s for t in (ad.nla_tracks if ad else ()) for s in t.strips if s.action is not None]
    chosen = [s for s in strips if s.select]
    chosen = chosen if len(chosen) == 2 else strips
    if len(chosen) < 2:
        raise MotionError(f"'{obj.name}' needs two NLA strips with actions to blend")
    a, b = sorted(chosen, key=lambda s: s.frame_start)[:2]
    start = a.action_frame_start + (b.frame_start - a.frame_start) * (a.action_frame_end - a.action_frame_start) / max(
        a.frame_end - a.frame_start, 1e-9)
    return a.action, (a.action_frame_start, a.action_frame_end), b.action, (b.action_frame_start, b.action_frame_end), start


def blend(obj, scene, action_a, action_b, start, window=0, method="MULTIRESOLUTION", mask="WINDOW",
          levels=None, sel=None, range_a=None, range_b=None, replace=False):
    """A then B, B's first frame placed at frame `start` of A; across the transition (the
    overlap, or `window` frames from `start`) A's weight eases from 1 to 0. B inside A: A
    eases out to B's middle and back. Channels of either action (all of them unless `sel`)."""
    t0 = time.perf_counter()
    fa = _frames_in(action_a, range_a)
    fb = _frames_in(action_b, range_b)
    s = int(round(start - fa[0]))
    if not 0 <= s <= len(fa) - 1:
        raise MotionError(f"B must start inside A (frames {fa[0]:g}-{fa[-1]:g}), not at {start:g}")
    transition = None
    if window and s + len(fb) - 1 >= len(fa) - 1:
        transition = (s, min(s + int(window), len(fa) - 1))
    sel = sel or select_channels(obj, scene, action_a)
    curves_a = {(fc.data_path, fc.array_index): fc for fc in action_api.fcurves_of(action_a, obj)}
    curves_b = {(fc.data_path, fc.array_index): fc for fc in action_api.fcurves_of(action_b, obj)}
    layout = list(sel.groups)
    if not sel.others:  # everything selected: the curves only B keys are blended too
        paths = {g.data_path for g in layout}
        layout += groups_of(obj, scene, [fc for (path, _), fc in curves_b.items() if path not in paths])

    def on(curves, g):
        return Group(g.data_path, g.kind, [curves.get((g.data_path, i)) for i in g.indices], g.defaults,
                     g.bone, g.order, g.scale, g.group_name)
    groups_a = [on(curves_a, g) for g in layout]
    groups_b = [on(curves_b, g) for g in layout]
    kw = {"transition": transition, "levels": levels, "mask": mask.lower()}
    if method != "MULTIRESOLUTION":
        kw = {"transition": transition}
    how = "multiresolution" if method == "MULTIRESOLUTION" else "weighted"
    values, plain_a, plain_b, plain_idx = [None] * len(groups_a), [], [], []
    for k, (ga, gb) in enumerate(zip(groups_a, groups_b)):
        xa, xb = sample_group(ga, fa), sample_group(gb, fb)
        if ga.kind in ("quaternion", "axis_angle"):
            q = multiresolution_blend.blend_quaternions(as_quaternions(ga, xa), as_quaternions(gb, xb), s,
                                                        method=how, **kw)
            values[k] = from_quaternions(ga, q)
        elif ga.kind == "euler":
            values[k] = multiresolution_blend.blend_euler(xa[:, None], xb[:, None], s, ga.order,
                                                          method=how, **kw)[:, 0]
        else:
            plain_a.append(xa), plain_b.append(xb), plain_idx.append(k)
    if plain_idx:
        fn = (multiresolution_blend.multiresolution_blend if how == "multiresolution"
              else multiresolution_blend.weighted_sum_blend)
        widths = [x.shape[1] for x in plain_a]
        res = fn(np.concatenate(plain_a, axis=1), np.concatenate(plain_b, axis=1), s, **kw)
        at = 0
        for k, w in zip(plain_idx, widths):
            values[k], at = res[:, at:at + w], at + w
    frames = fa[0] + np.arange(len(values[0]), dtype=float)
    out = Output(obj, action_a, f"{action_a.name}.blend", replace)
    write_groups(out, groups_a, frames, values)
    out.copy_unprocessed(sel.others)
    out.finish()
    w = multiresolution_blend.blend_weights(len(fa), s, len(fb), transition)
    moving = np.flatnonzero((w > 0.0) & (w < 1.0))
    summary = _base_summary(obj, action_a, Selection(action_a, groups_a, sel.note, sel.others), out)
    summary.update(command="blend", action_b=action_b.name, start=float(fa[0] + s), method=how, mask=mask.lower(),
                   frames=[float(frames[0]), float(frames[-1])],
                   transition=[float(fa[0] + moving[0]), float(fa[0] + moving[-1])] if len(moving) else None,
                   ms=_ms(t0))
    return summary


def _frames_in(action, frame_range):
    if frame_range is None:
        return action_frames(action)
    return np.arange(int(np.floor(frame_range[0])), int(np.ceil(frame_range[1])) + 1, dtype=float)


# -- key compression ---------------------------------------------------------------------------

def component_tolerances(group, degrees, centimetres, value_tolerance):
    """Per-component tolerances so the whole property stays within the animator's figure: an
    Euler triple within d degrees when each angle is within d/3; a quaternion within d degrees
    when each component is within rad(d)/4 (|dq| <= 2 e, angle <= 2 |dq|); an axis-angle with
    its angle within d/2 and its axis within rad(d)/4; a location within c cm when each
    component is within c/sqrt(3)."""
    rad = np.radians(degrees)
    n = len(group.fcurves)
    if group.kind == "euler":
        return np.full(n, rad / 3.0)
    if group.kind == "quaternion":
        return np.full(n, rad / 4.0)
    if group.kind == "axis_angle":
        return np.array([rad / 2.0, rad / 4.0, rad / 4.0, rad / 4.0])
    if group.kind == "location":
        return np.full(n, 0.01 * centimetres / group.scale / (np.sqrt(3.0) if n > 1 else 1.0))
    return np.full(n, float(value_tolerance))


def iter_compress(obj, scene, source, sel, degrees=0.5, centimetres=0.5, value_tolerance=1e-3,
                  method="HERMITE", replace=False, tail_cm=0.0):
    """Fewer keys within the tolerances on every frame (Hermite key reduction, or pyramid levels),
    as steps yielding progress; returns the summary with keys before/after and the largest errors.
    `tail_cm` > 0 also bounds the largest error at any bone's tail and 10 cm beyond it: the
    channel tolerances are scaled down until it holds."""
    t0 = time.perf_counter()
    frames = action_frames(source)
    keys_before = sum(len(fc.keyframe_points) for fc in sel.fcurves)
    samples = unrolled(sel.groups, [sample_group(g, frames) for g in sel.groups])
    tols = [component_tolerances(g, degrees, centimetres, value_tolerance) for g in sel.groups]

    def reduce(scale):
        out = []
        for g, x, tol in zip(sel.groups, samples, tols):
            if method == "PYRAMID":
                out.append(pyramid_compression.pyramid_keys(frames, x, tol * scale)[0])
            else:
                out.append(key_reduction.reduce_channels(frames, x, tol * scale))
        return out

    results = reduce(1.0)
    yield 0.5
    if tail_cm > 0.0 and obj.type == "ARMATURE":
        measure = _tail_measure(obj, scene, source, sel.groups, frames)
        results, _, _ = key_reduction.fit_to_error(lambda scale: results if scale == 1.0 else reduce(scale),
                                                   measure, tail_cm)
    yield 0.9
    out = Output(obj, source, f"{source.name}.compressed", replace)
    for g, keys in zip(sel.groups, results):
        for i, k in enumerate(keys):
            set_keys(out.fcurve(g.data_path, i, g.group_name), k)
    out.copy_unprocessed(sel.others)
    action = out.finish()
    yield 0.95
    keys_after = sum(len(k) for keys in results for k in keys)
    new_groups = [Group(g.data_path, g.kind, [out.fcurve(g.data_path, i, g.group_name) for i in g.indices],
                        g.defaults, g.bone, g.order, g.scale, g.group_name) for g in sel.groups]
    played = [sample_group(g, frames) for g in new_groups]
    errors = group_errors(sel.groups, samples, played)
    summary = _base_summary(obj, source, sel, out)
    summary.update(command="compress", method=method.lower(), frames=len(frames),
                   tolerance_deg=degrees, tolerance_cm=centimetres, tolerance_tail_cm=tail_cm, keys_before=keys_before, keys_after=keys_after,
                   ratio=round(keys_before / max(keys_after, 1), 2),
                   max_error_deg=round(errors["deg"][0], 4), max_error_deg_at=errors["deg"][1],
                   max_error_cm=round(errors["cm"][0], 4), max_error_cm_at=errors["cm"][1],
                   max_error_value=round(errors["value"][0], 6))
    if not replace:
        tail = tail_errors(obj, scene, source, action, frames)
    else:
        tail = None  # the source was rewritten: compare with the samples instead
    if tail is not None:
        summary.update(tail_error_cm=round(tail.tail_cm, 4), tail_error_bone=tail.tail_bone,
                       tail_10cm_error_cm=round(tail.point_cm, 4), tail_10cm_error_bone=tail.point_bone)
    summary["ms"] = _ms(t0)
    return summary


def compress(*args, **kw):
    return run_to_end(iter_compress(*args, **kw))


# -- time warp ---------------------------------------------------------------------------------

def marker_constraints(scene, action):
    """(new frame, old frame) from markers named 'warp:<old frame>' placed at the new frame:
    the action's pose markers and the scene's timeline markers."""
    found = {}
    for marker in list(action.pose_markers) + list(scene.timeline_markers):
        m = WARP_MARKER.match(marker.name)
        if m:
            found[float(m.group(1))] = float(marker.frame)
    return [(new, old) for old, new in sorted(found.items())]


def parse_map(text):
    """'OLD:NEW, OLD:NEW' -> [(new, old), ...]."""
    pairs = []
    for part in re.split(r"[,\s;]+", text.strip()):
        if not part:
            continue
        try:
            old, new = (float(v) for v in part.split(":"))
        except ValueError:
            raise MotionError(f"warp map {part!r}: expected OLD:NEW frame pairs") from None
        pairs.append((new, old))
    return pairs


def make_warp(constraints, frames, keep_ends=True):
    c = list(constraints)
    if keep_ends:
        olds = [old for _, old in c]
        if not olds or frames[0] < min(olds):
            c.append((frames[0], frames[0]))
        if not olds or frames[-1] > max(olds):
            c.append((frames[-1], frames[-1]))
    if len(c) < 2:
        raise MotionError("a time warp needs two constraints: add 'warp:<old frame>' markers at the new frames")
    try:
        return time_warp.TimeWarp(c)
    except ValueError as error:
        raise MotionError(f"time warp: {error}") from None


def warp(obj, scene, source, sel, constraints, keep_ends=True, resample=False, replace=False):
    """What happened at each constraint's old frame now happens at its new frame (monotone cubic
    warp, slope one outside). resample=False moves the keys (handles scaled by the warp's
    slope); True keys the warped curves on every new frame."""
    t0 = time.perf_counter()
    frames = action_frames(source)
    tw = make_warp(constraints, frames, keep_ends)
    out = Output(obj, source, f"{source.name}.warped", replace)
    if resample:
        new_frames = np.arange(np.ceil(tw(frames[0]) - 1e-9), np.floor(tw(frames[-1]) + 1e-9) + 1.0)
        samples = [sample_group(g, frames) for g in sel.groups]
        work, layout = to_working(sel.groups, samples)
        values = from_working(sel.groups, time_warp.warp_channels(frames, work, tw, new_frames), layout)
        write_groups(out, sel.groups, new_frames, values)
        keys_written = len(new_frames) * len(sel.fcurves)
    else:
        keys_written = 0
        for g in sel.groups:
            for i, fc in enumerate(g.fcurves):
                if fc is None:
                    continue
                k = time_warp.warp_keys(read_keys(fc), tw)
                set_keys(out.fcurve(g.data_path, i, g.group_name), k)
                keys_written += len(k)
    out.copy_unprocessed(sel.others)

    def marker_frame(marker):
        return None if WARP_MARKER.match(marker.name) else float(tw(marker.frame))
    out.finish(marker_frame)
    summary = _base_summary(obj, source, sel, out)
    summary.update(command="warp", constraints=[[float(old), float(new)] for new, old in zip(tw.new, tw.old)],
                   frames=[float(tw(frames[0])), float(tw(frames[-1]))], resampled=bool(resample),
                   keys=keys_written, ms=_ms(t0))
    return summary


def squeeze_stretch(obj, scene, source, sel, current, new_frame, left_limit, right_limit, replace=False):
    """Move the keys at `current` to `new_frame`; keys between the limits keep their ratio of
    distances (Huang's squeeze and stretch), handles scaled with them; keys outside stay."""
    t0 = time.perf_counter()
    tl, t, tr = float(left_limit), float(current), float(right_limit)
    if not (tl < t < tr and tl < new_frame < tr):
        raise MotionError(f"need left limit < frame, new frame < right limit (got {tl:g}, {t:g}, "
                          f"{new_frame:g}, {tr:g})")
    out = Output(obj, source, f"{source.name}.squeezed", replace)
    moved = 0
    for g in sel.groups:
        for i, fc in enumerate(g.fcurves):
            if fc is None:
                continue
            k = read_keys(fc)
            nt = time_warp.squeeze_stretch(k.times, t, new_frame, tl, tr)
            # a key's handles scale with its side's ratio (the key at T: each handle its side's)
            ratio_l = np.where((k.times > tl) & (k.times <= tr),
                               np.where(k.times <= t, (new_frame - tl) / (t - tl), (tr - new_frame) / (tr - t)), 1.0)
            ratio_r = np.where((k.times >= tl) & (k.times < tr),
                               np.where(k.times < t, (new_frame - tl) / (t - tl), (tr - new_frame) / (tr - t)), 1.0)
            left = np.column_stack((nt + (k.left[:, 0] - k.times) * ratio_l, k.left[:, 1]))
            right = np.column_stack((nt + (k.right[:, 0] - k.times) * ratio_r, k.right[:, 1]))
            moved += int(np.count_nonzero(np.abs(nt - k.times) > 1e-9))
            set_keys(out.fcurve(g.data_path, i, g.group_name),
                     key_reduction.Keys(nt, k.values, left, right, k.interpolation))
    out.copy_unprocessed(sel.others)
    out.finish()
    summary = _base_summary(obj, source, sel, out)
    summary.update(command="squeeze", frame=t, new_frame=float(new_frame), limits=[tl, tr], keys_moved=moved,
                   ms=_ms(t0))
    return summary


# -- settings and the band analysis shown by the panel -----------------------------------------

class HumanAnimBand(bpy.types.PropertyGroup):
    label: StringProperty(name="Band")
    energy: FloatProperty(name="RMS")


class HumanAnimSequence(bpy.types.PropertyGroup):
    bands: CollectionProperty(type=HumanAnimBand)
    band_index: IntProperty()
    analysed: StringProperty(name="Analysed", description="The curve whose bands are listed")
    units: StringProperty()
    levels: IntProperty(name="Bands", default=0, min=0, max=MAX_LEVELS,
                        description="Pyramid levels to analyse (0: as many as the clip allows, up to 8)")


CLASSES = (HumanAnimBand, HumanAnimSequence)


def store_bands(props, label, labels, energies, units):
    props.bands.clear()
    for text, energy in zip(labels, energies):
        item = props.bands.add()
        item.label, item.energy = text, energy
    props.analysed, props.units = label, units


register, unregister = settings_registration(CLASSES, bpy.types.Scene, "humananim_sequence", HumanAnimSequence)
