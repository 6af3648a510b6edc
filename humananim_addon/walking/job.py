"""Procedural walking in Blender (issue 11): the settings, the path (a curve object, or an object
whose keyed location is the root's "Global_motion"), the ground (ray casts into an evaluated
mesh), the walk written as a new action with its support constraints, and generators as NLA
strips whose actions key only their scope. Each armature keeps its own stack of generator strips
(several actors in one scene)."""

import json
import time

import bpy
import numpy as np

from ...solver.errors import HumanAnimError, MotionError
from ...solver.walking import PRESETS, Style, metrics
from ...solver.walking.generators import Generator, schedule, scope_bones
from ...solver.walking.walk import STAND
from .. import action_api, actions
from ..actions import bone_path, scene_fps
from ..armature import armature_to_world, skeleton_from_armature
from .properties import STYLE_FIELDS, apply_preset  # noqa: F401 (the operator's and the command's name)
from ..rig.capability import RigView

GENERATOR_KEY = "humananim_generator"  # on a generator's action: its scope, priority, weight, start
SUPPORT_KEY = "humananim_support"  # on a walk's action: the support intervals (JSON)
TRACK_PREFIX = "HumanAnim gen: "
STACK_KEY = "humananim_stack"  # on an armature object: its generator actions, in the order added
CACHE = {}  # (armature name, action name) -> the last WalkResult, in memory only (tests, summaries)


def style_of(props):
    if props.preset != "CUSTOM":
        return PRESETS[props.preset.lower()]
    return Style(**{name: float(getattr(props, name)) for name in STYLE_FIELDS})


def parse_pairs(text, what):
    try:
        pairs = [tuple(float(v) for v in item.split(":")) for item in text.replace(";", ",").split(",") if item.strip()]
    except ValueError:
        raise HumanAnimError(f"{what}: expected DISTANCE:SPEED pairs, e.g. 0:1.0, 5:1.6") from None
    if not pairs or any(len(p) != 2 for p in pairs):
        raise HumanAnimError(f"{what}: expected DISTANCE:SPEED pairs, e.g. 0:1.0, 5:1.6")
    return pairs


def parse_list(text, what):
    try:
        values = [float(v) for v in text.replace(";", ",").split(",") if v.strip()]
    except ValueError:
        raise HumanAnimError(f"{what}: expected numbers separated by commas") from None
    if not values:
        raise HumanAnimError(f"{what}: expected numbers separated by commas")
    return values


# ---- the path and the ground -------------------------------------------------------------------

def _chain(mesh_verts, edges):
    """Vertices of the first polyline of a curve's mesh, in order along it."""
    if not edges:
        return mesh_verts
    nbr = {}
    for a, b in edges:
        nbr.setdefault(a, []).append(b)
        nbr.setdefault(b, []).append(a)
    ends = [v for v, n in nbr.items() if len(n) == 1]
    start = min(ends) if ends else min(nbr)
    order, prev, cur = [start], None, start
    while True:
        nxt = [v for v in nbr[cur] if v != prev and v not in order[-2:]]
        if not nxt or nxt[0] == start:
            break
        prev, cur = cur, nxt[0]
        order.append(cur)
    return mesh_verts[order]


def curve_path(obj, scene):
    """The path (metres, world) of a curve object as Blender evaluates it, and the arc lengths of
    its control points (the segments of per-segment speeds)."""
    from ...solver.walking import Path
    if obj is None or obj.type != "CURVE":
        raise HumanAnimError("choose a curve object as the path")
    depsgraph = bpy.context.evaluated_depsgraph_get()
    ev = obj.evaluated_get(depsgraph)
    mesh = ev.to_mesh()
    try:
        n = len(mesh.vertices)
        if n < 2:
            raise HumanAnimError(f"the curve '{obj.name}' has fewer than two points")
        co = np.empty(n * 3)
        mesh.vertices.foreach_get("co", co)
        edges = np.empty(len(mesh.edges) * 2, dtype=np.int64)
        mesh.edges.foreach_get("vertices", edges)
    finally:
        ev.to_mesh_clear()
    m = np.array(obj.matrix_world)
    pts = co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]
    pts = _chain(pts, [tuple(e) for e in edges.reshape(-1, 2)])
    unit = scene.unit_settings.scale_length
    path = Path.from_points(pts * unit)
    controls = []
    for spline in obj.data.splines[:1]:
        points = spline.bezier_points if spline.type == "BEZIER" else spline.points
        for p in points:
            controls.append(np.array(m @ np.r_[np.array(p.co)[:3], 1.0])[:3] * unit)
    if len(controls) >= 2:
        s = np.sort(path.project(np.array(controls)))
        s[0], s[-1] = 0.0, path.length
        path.corners = np.unique(s)
    return path


def keyed_path(obj, scene):
    """Global_motion: the keyed location of `obj` sampled on every frame of its keys; returns
    (path, progress, first frame)."""
    from ...solver.walking import from_keys
    ad = obj.animation_data if obj is not None else None
    if ad is None or ad.action is None:
        raise MotionError("the path object has no keyed location: key it, or use a curve")
    f0, f1 = (int(round(v)) for v in ad.action.frame_range)
    if f1 <= f0:
        raise MotionError(f"'{obj.name}' has a single key: key it at two frames at least")
    saved = scene.frame_current
    pts = []
    try:
        for f in range(f0, f1 + 1):
            scene.frame_set(f)
            pts.append(np.array(obj.matrix_world.translation))
    finally:
        scene.frame_set(saved)
    times = (np.arange(f0, f1 + 1) - f0) / scene_fps(scene)
    path, progress = from_keys(times, np.array(pts) * scene.unit_settings.scale_length)
    return path, progress, f0


def ground_function(obj, scene, height=0.0):
    """ground(x, y) -> z in metres: ray casts straight down into the evaluated mesh of `obj` (a
    point off the mesh takes the nearest surface point's height), or a flat ground."""
    unit = scene.unit_settings.scale_length
    if obj is None:
        return lambda x, y: np.full(np.shape(x), height * unit)
    if obj.type != "MESH":
        raise HumanAnimError(f"the ground '{obj.name}' is not a mesh")
    from mathutils import Vector
    from mathutils.bvhtree import BVHTree
    depsgraph = bpy.context.evaluated_depsgraph_get()
    ev = obj.evaluated_get(depsgraph)
    mesh = ev.to_mesh()
    try:
        m = ev.matrix_world.copy()
        verts = [m @ v.co for v in mesh.vertices]
        polys = [tuple(p.vertices) for p in mesh.polygons]
    finally:
        ev.to_mesh_clear()
    if not polys:
        raise HumanAnimError(f"the ground '{obj.name}' has no faces")
    tree = BVHTree.FromPolygons(verts, polys)  # world space
    top = max(v.z for v in verts) + 10.0
    down = Vector((0.0, 0.0, -1.0))

    def ground(x, y):
        x, y = np.broadcast_arrays(np.asarray(x, float), np.asarray(y, float))
        out = np.empty(x.shape)
        for i, (xi, yi) in enumerate(zip(x.ravel() / unit, y.ravel() / unit)):
            hit = tree.ray_cast(Vector((xi, yi, top)), down)[0]
            if hit is None:
                hit = tree.find_nearest(Vector((xi, yi, top)))[0]
            out.flat[i] = hit.z * unit
        return out
    return ground


# ---- the walk ----------------------------------------------------------------------------------

def walk_armature(props, context_object):
    obj = props.armature or context_object
    if obj is None or obj.type != "ARMATURE":
        raise HumanAnimError("choose the armature that walks (or make it active)")
    return obj


def run(obj, scene):
    """The walk job: read the settings, generate, write a new action (and its NLA strip).
    Yields progress; returns a summary dict."""
    from ...solver.walking import iter_walk
    props = scene.humananim_walk
    rig = RigView(obj, scene)  # a control rig: the deform bones' body, its controls keyed (rig/capability.py)
    skeleton = rig.skeleton
    fps = scene_fps(scene)
    kwargs = {}
    if props.path_mode == "KEYED":
        path, kwargs["progress"], f0 = keyed_path(props.path, scene)
        frame_start = f0 - int(round(STAND * fps))
    else:
        path = curve_path(props.path, scene)
        frame_start = props.frame_start or scene.frame_start
        if props.speed_mode == "CONSTANT":
            kwargs["speed"] = props.speed
        elif props.speed_mode == "KEYED":
            kwargs["speed_keys"] = parse_pairs(props.speed_keys, "Speed Keys")
        else:
            kwargs["segment_speeds"] = parse_list(props.segment_speeds, "Segment Speeds")
    ground = ground_function(props.ground, scene, props.ground_height)
    t0 = time.perf_counter()
    result = yield from iter_walk(skeleton, path, style=style_of(props), ground=ground, fps=fps,
                                  frame_start=frame_start, armature_to_world=armature_to_world(obj, scene),
                                  reference=standing_motion(obj, scene, skeleton), **kwargs)
    seconds = time.perf_counter() - t0
    action = write_walk(obj, skeleton, result, f"{obj.name}.walk", rig)
    CACHE[(obj.name, action.name)] = result
    summary = metrics.summary(result)
    summary.update(action=action.name, armature=obj.name, path=props.path.name if props.path else None,
                   generate_seconds=round(seconds, 3), frame_range=[float(result.frames[0]), float(result.frames[-1])],
                   supports=len(result.constraints), style=result.style.to_dict(),
                   ms_per_walk_second=round(1000 * seconds / max(summary["walk_seconds"], 1e-9), 2))
    action["humananim_walk"] = json.dumps({k: v for k, v in summary.items() if k != "style"})
    return summary


def standing_motion(obj, scene, skeleton):
    """The rig's action as a motion to take a standing pose from, when its rest pose does not stand
    (a BVH whose bones all lie along one axis); None otherwise or when it has no action (the
    solver then says what it needs)."""
    from ...solver.walking.body import stands
    ad = obj.animation_data
    if stands(skeleton) or ad is None or ad.action is None:
        return None
    return actions.read_action(obj, scene, skeleton, ad.action)


def write_walk(obj, skeleton, result, name, rig=None):
    """The walk as a NEW action (every moving bone, the support channels and intervals), played by
    a generator strip of scope 'all' on the armature's stack; an active action the rig had is set
    aside (kept with a fake user) so the stack shows."""
    traj = result.trajectories
    controlled = rig is not None and rig.control_rig  # the controls keyed, checked against Blender
    action = rig.write(traj, name) if controlled else bpy.data.actions.new(name)
    writer = action_api.ChannelWriter(action, obj, existing=controlled)
    channels = actions._rotation_channels(obj, skeleton, traj)
    ends = traj.frames[[0, -1]]
    for j, bone in enumerate(() if controlled else skeleton.names):
        if j not in channels:  # still bones are keyed too: the walk owns every bone of its scope
            _key_rest(writer, obj, bone, ends)
            continue
        trans = traj.translations[:, j] / skeleton.unit_scale
        if not skeleton.connected[j] and not np.allclose(trans, 0.0, atol=1e-9):
            actions._write_channels(writer, f"{bone_path(bone)}.location", bone, traj.frames, trans)
        prop, values = channels[j]
        actions._write_channels(writer, f"{bone_path(bone)}.{prop}", bone, traj.frames, values)
    for side, on in result.support.items():  # Oshita's supporting constraints, frame by frame
        key = f"{SUPPORT_KEY}_{side}"
        if key not in obj:
            obj[key] = 0.0
        actions._write_channels(writer, f'["{key}"]', "Support", traj.frames, on.astype(float)[:, None])
    action[SUPPORT_KEY] = json.dumps(result.constraints)
    ad = obj.animation_data or obj.animation_data_create()
    if ad.action is not None:
        ad.action.use_fake_user = True
        ad.action = None
    action[GENERATOR_KEY] = json.dumps({"name": action.name, "scope": "all", "priority": "default",
                                        "weight": 1.0, "start": float(traj.frames[0]), "walk": True})
    # a new walk replaces the rig's previous one on its stack (that action stays in the file)
    kept = [a.name for a in generator_actions(obj) if not json.loads(a[GENERATOR_KEY]).get("walk")]
    obj[STACK_KEY] = json.dumps(kept)
    _push(obj, action)
    rebuild_stack(obj)
    return action


def _key_rest(writer, obj, bone, frames):
    """Key a bone at its rest pose on `frames` (in its own rotation mode)."""
    mode = obj.pose.bones[bone].rotation_mode
    prop, rest = {"QUATERNION": ("rotation_quaternion", (1.0, 0.0, 0.0, 0.0)),
                  "AXIS_ANGLE": ("rotation_axis_angle", (0.0, 0.0, 1.0, 0.0))}.get(
        mode, ("rotation_euler", (0.0, 0.0, 0.0)))
    frames = np.asarray(frames, float)
    actions._write_channels(writer, f"{bone_path(bone)}.{prop}", bone, frames, np.tile(rest, (len(frames), 1)))
    if not obj.data.bones[bone].use_connect:
        actions._write_channels(writer, f"{bone_path(bone)}.location", bone, frames, np.zeros((len(frames), 3)))


# ---- generators as NLA strips ------------------------------------------------------------------

def generator_actions(obj):
    """The generator actions on `obj`'s stack, in the order they were added (the list lives on the
    object, so each armature has its own stack)."""
    names = json.loads(obj.get(STACK_KEY, "[]"))
    return [bpy.data.actions[n] for n in names if n in bpy.data.actions and GENERATOR_KEY in bpy.data.actions[n]]


def _push(obj, action):
    names = [a.name for a in generator_actions(obj)] + [action.name]
    obj[STACK_KEY] = json.dumps(names)
    action.use_fake_user = True


def add_generator(obj, scene, source, scope, start, priority, weight, name=None):
    """A generator playing `source` on `scope` from frame `start`: a new action keying only the
    scope's bones (the source is not changed), then the stack is rescheduled."""
    if source is None:
        raise HumanAnimError("choose the action the generator plays")
    skeleton = skeleton_from_armature(obj, scene, require=False)
    bones = scope_bones(skeleton, scope)
    name = name or f"{source.name}.{scope}"
    action = copy_channels(source, obj, bones, f"{obj.name}.gen.{name}", key_rest=True)
    if action is None:
        raise HumanAnimError(f"'{source.name}' keys none of the bones of the {scope} scope")
    action[GENERATOR_KEY] = json.dumps({"name": name, "scope": scope, "priority": priority, "weight": float(weight),
                                        "start": float(start)})
    _push(obj, action)
    rebuild_stack(obj)
    return action


def copy_channels(source, obj, bones, name, key_rest=False):
    """A new action with the F-curves of `source` that move `bones` (a per-bone mask); with
    `key_rest`, the scope's bones the source leaves alone are keyed at rest, so the action keys
    exactly its scope. None if the source moves none of them."""
    curves = [fc for fc in action_api.fcurves_of(source, obj) if _bone_of(fc.data_path) in bones]
    if not curves:
        return None
    action = bpy.data.actions.new(name)
    writer = action_api.ChannelWriter(action, obj)
    if key_rest:
        moved = {_bone_of(fc.data_path) for fc in curves}
        for bone in sorted(set(bones) - moved):
            _key_rest(writer, obj, bone, source.frame_range)
    for fc in curves:
        bone = _bone_of(fc.data_path)
        new = writer.new_fcurve(fc.data_path, fc.array_index, bone)
        action_api.copy_keys(fc, new)
    return action


def _bone_of(data_path):
    channel = actions.bone_channel(data_path)
    return channel[0] if channel else None


def _generator_of(action, obj, bones_of_scope):
    meta = json.loads(action[GENERATOR_KEY])
    f0, f1 = action.frame_range
    motion_len = float(f1 - f0)
    keyed = {_bone_of(fc.data_path) for fc in action_api.fcurves_of(action, obj)} - {None}
    scope = bones_of_scope(meta["scope"]) & keyed if meta["scope"] != "all" else keyed
    from ...solver.trajectories import Trajectories
    dummy = Trajectories(np.array([f0, f1], float), 24.0, np.tile([1.0, 0, 0, 0], (2, 1, 1)),
                         np.zeros((2, 1, 3)), np.eye(4))
    g = Generator(meta["name"], scope, dummy, meta["start"], meta["start"] + motion_len, meta["priority"],
                  meta["weight"])
    return g, meta, f0


def rebuild_stack(obj):
    """Place the generator strips of `obj` after the priorities (sec. 6.4.3): one NLA track per
    piece of a generator (a piece keeps the bones it still runs on; an exclusive generator takes
    its bones away from the ones below), layered in schedule order."""
    ad = obj.animation_data or obj.animation_data_create()
    gens = generator_actions(obj)
    for track in list(ad.nla_tracks):
        if track.name.startswith(TRACK_PREFIX):
            for strip in track.strips:
                act = strip.action
                if act is not None and act.get("humananim_source"):
                    track.strips.remove(strip)
                    bpy.data.actions.remove(act)
            ad.nla_tracks.remove(track)
    if not gens:
        return []
    try:
        skeleton = skeleton_from_armature(obj, bpy.context.scene, require=False)
        bones_of_scope = lambda s: scope_bones(skeleton, s)  # noqa: E731
    except HumanAnimError:
        bones_of_scope = lambda s: frozenset(b.name for b in obj.data.bones)  # noqa: E731
    items = [_generator_of(a, obj, bones_of_scope) for a in gens]
    scheduled = schedule([g for g, _, _ in items])
    by_gen = {id(g): (a, meta, f0) for a, (g, meta, f0) in zip(gens, items)}
    out = []
    for s in scheduled:
        action, meta, f0 = by_gen[id(s.generator)]
        for k, (bones, a, b) in enumerate(s.pieces()):
            piece = action if bones == s.scope else _piece_action(action, obj, bones, k)
            track = ad.nla_tracks.new()
            track.name = f"{TRACK_PREFIX}{meta['name']}" + (f" ({k + 1})" if k else "")
            strip = track.strips.new(piece.name, int(round(a)), piece)
            slot = action_api.object_slot(piece, obj)
            if action_api.SLOTTED and slot is not None and hasattr(strip, "action_slot"):
                strip.action_slot = slot
            strip.action_frame_start = f0 + (a - s.start)
            strip.action_frame_end = f0 + (b - s.start)
            strip.frame_start = a
            strip.frame_end = b
            strip.extrapolation = "NOTHING"
            strip.blend_type = "REPLACE"
            if s.weight < 1.0:
                strip.use_animated_influence = True
                strip.influence = s.weight
                strip.keyframe_insert("influence", frame=a)
            out.append((meta["name"], sorted(bones), a, b, s.weight))
    return out


def _piece_action(action, obj, bones, k):
    piece = copy_channels(action, obj, bones, f"{action.name}.piece{k + 1}")
    piece["humananim_source"] = action.name
    action.use_fake_user = True  # the full generator action stays, its pieces play it
    return piece


def stack_summary(obj):
    """What the stack of `obj` is: per strip, its track, action, frames, influence and keyed bones."""
    ad = obj.animation_data
    out = []
    for track in (ad.nla_tracks if ad else ()):
        if not track.name.startswith(TRACK_PREFIX):
            continue
        for strip in track.strips:
            keyed = sorted({_bone_of(fc.data_path) for fc in action_api.fcurves_of(strip.action, obj)} - {None})
            out.append({"track": track.name, "action": strip.action.name, "frame_start": strip.frame_start,
                        "frame_end": strip.frame_end, "influence": strip.influence if strip.use_animated_influence
                        else 1.0, "bones": len(keyed)})
    return out


def clear_stack(obj):
    """Empty `obj`'s generator stack: its tracks go, the generator actions stay (fake user)."""
    n = len(stack_summary(obj))
    obj[STACK_KEY] = "[]"
    rebuild_stack(obj)
    return n
