"""Flexible characters (issue 8): the bridge between Blender data and the flexible solver.

The character is an object deformed by a Lattice (a Lattice modifier). The deformation modes are
the lattice's shape keys (offsets from their relative key = the matrix d of eq. 4.2, their value
the amplitude gamma). Point masses are samples of the object's undeformed mesh in lattice space,
or the lattice points. Results are baked as NEW actions: the lattice object's location and
rotation (and the object's, when it doesn't follow the lattice as its child), and the shape-key
values on the lattice's Key datablock, each in an action of its own; the source is untouched."""

import logging
import time

import bpy
import numpy as np
from mathutils import Matrix, Quaternion, Vector

from ...solver import rotations
from ...solver.flexible import FlexibleBody, FlexibleError, Ground, ModeGains, Settings, Simulator, Spring
from ...solver.flexible.control import AnnealSettings, CostSpec, anneal, motion_measures
from ...solver.flexible.demo import TABLE_MODES, table_lattice
from ...solver.flexible.body import quat_matrix
from ...solver.flexible.ffd import lattice_params
from ...solver.flexible.forces import Plane
from ...solver.flexible.keyframe import animate
from ...solver.flexible.simulate import Controller, State
from .. import action_api
from ..actions import rotation_channels, scene_fps
from .properties import MAX_ACTIVE

log = logging.getLogger(__name__)

# -- reading the character ------------------------------------------------------------------------

def find_lattice(obj):
    props = obj.humananim_flexible
    if props.lattice is not None:
        if props.lattice.type != "LATTICE":
            raise FlexibleError(f"'{props.lattice.name}' is not a Lattice")
        return props.lattice
    if obj.type == "LATTICE":
        return obj
    for mod in getattr(obj, "modifiers", ()):
        if mod.type == "LATTICE" and mod.object is not None:
            return mod.object
    raise FlexibleError(f"'{obj.name}' has no Lattice modifier with a lattice, and no lattice is set")


def sync_modes(obj):
    """One mode entry per shape key of the lattice (the Basis excepted), keeping the settings of
    keys already listed."""
    lat = find_lattice(obj)
    props = obj.humananim_flexible
    keys = lat.data.shape_keys
    names = [kb.name for kb in keys.key_blocks[1:]] if keys else []
    old = {m.key: (m.use, m.active, m.stiffness, m.damping) for m in props.modes}
    props.modes.clear()
    for name in names:
        m = props.modes.add()
        m.key = name
        if name in old:
            m.use, m.active, m.stiffness, m.damping = old[name]
    return names


def lattice_frame(lat):
    """(location, rotation quaternion (w,x,y,z), scale) of the lattice in the world."""
    loc, rot, scale = lat.matrix_world.decompose()
    return np.array(loc), np.array(rot), np.array(scale)


def read_lattice(lat, mode_names):
    """dims, regular grid (lattice local), basis points and mode offsets in the body frame
    (local coordinates times the lattice's scale)."""
    data = lat.data
    dims = (data.points_u, data.points_v, data.points_w)
    n = len(data.points)
    grid = np.empty(n * 3)
    data.points.foreach_get("co", grid)
    grid = grid.reshape(n, 3)
    _, _, scale = lattice_frame(lat)
    keys = data.shape_keys
    if keys is None:
        if mode_names:
            raise FlexibleError(f"lattice '{lat.name}' has no shape keys")
        basis = np.empty(n * 3)
        data.points.foreach_get("co_deform", basis)
        return dims, grid, basis.reshape(n, 3) * scale, np.zeros((0, n, 3))
    blocks = keys.key_blocks
    basis = _key_points(blocks[0], n)
    offsets = []
    for name in mode_names:
        kb = blocks.get(name)
        if kb is None:
            raise FlexibleError(f"lattice '{lat.name}' has no shape key '{name}'")
        ref = kb.relative_key if kb.relative_key is not None else blocks[0]
        offsets.append((_key_points(kb, n) - _key_points(ref, n)) * scale)
    return dims, grid, basis * scale, np.array(offsets).reshape(len(offsets), n, 3)


def _key_points(kb, n):
    co = np.empty(n * 3)
    kb.data.foreach_get("co", co)
    return co.reshape(n, 3)


def mesh_points_in_lattice(obj, lat, surface_samples=0):
    """The object's undeformed mesh vertices in the lattice's local space (with
    `surface_samples` more points spread over its faces by area, seeded so repeatable), and its
    volume (m^3)."""
    mesh = obj.data
    n = len(mesh.vertices)
    co = np.empty(n * 3)
    mesh.vertices.foreach_get("co", co)
    co = co.reshape(n, 3)
    to_lattice = np.array(lat.matrix_world.inverted() @ obj.matrix_world)
    local = co @ to_lattice[:3, :3].T + to_lattice[:3, 3]
    world = np.array(obj.matrix_world)
    mesh.calc_loop_triangles()
    tris = np.empty(len(mesh.loop_triangles) * 3, dtype=np.int32)
    mesh.loop_triangles.foreach_get("vertices", tris)
    tris = tris.reshape(-1, 3)
    wco = co @ world[:3, :3].T + world[:3, 3]
    a, b, c = wco[tris[:, 0]], wco[tris[:, 1]], wco[tris[:, 2]]
    volume = abs(float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum()) / 6.0)
    if surface_samples and len(tris):
        la, lb, lc = local[tris[:, 0]], local[tris[:, 1]], local[tris[:, 2]]
        area = np.linalg.norm(np.cross(b - a, c - a), axis=1)
        if area.sum() > 0:
            rng = np.random.default_rng(0)
            pick = rng.choice(len(tris), size=surface_samples, p=area / area.sum())
            r1, r2 = rng.random(surface_samples), rng.random(surface_samples)
            flip = r1 + r2 > 1
            r1[flip], r2[flip] = 1 - r1[flip], 1 - r2[flip]
            extra = la[pick] + r1[:, None] * (lb[pick] - la[pick]) + r2[:, None] * (lc[pick] - la[pick])
            local = np.vstack([local, extra])
    return local, volume


def farthest_points(points, count):
    """`count` well-spread points (farthest-point sampling, deterministic)."""
    count = min(count, len(points))
    centre = points.mean(axis=0)
    chosen = [int(np.argmax(((points - centre) ** 2).sum(1)))]
    dist = ((points - points[chosen[0]]) ** 2).sum(1)
    for _ in range(count - 1):
        i = int(np.argmax(dist))
        chosen.append(i)
        dist = np.minimum(dist, ((points - points[i]) ** 2).sum(1))
    return points[np.array(chosen)]


def build_body(obj):
    """(FlexibleBody, lattice, used mode entries, info) from the object's settings."""
    props = obj.humananim_flexible
    lat = find_lattice(obj)
    bpy.context.view_layer.update()  # current world matrices of the object and its lattice
    if not len(props.modes):
        sync_modes(obj)
    modes = [m for m in props.modes if m.use]
    names = [m.key for m in modes]
    dims, grid, basis, offsets = read_lattice(lat, names)
    _, _, scale = lattice_frame(lat)
    if props.points == "LATTICE" or obj.type != "MESH":
        local = grid
        volume = float(np.prod(np.ptp(grid, axis=0) * scale))
    else:
        verts, volume = mesh_points_in_lattice(obj, lat, 40 * props.sample_count)
        if volume <= 1e-12:  # an open or flat mesh: its bounding box
            volume = float(np.prod(np.maximum(np.ptp(verts, axis=0) * scale, 1e-3)))
        local = farthest_points(verts, props.sample_count)
    mass = props.mass if props.mass > 0 else volume * props.density
    uvw = lattice_params(local, grid)
    if (uvw < -1e-6).any() or (uvw > 1 + 1e-6).any():
        log.warning("%s: some sample points lie outside the lattice; they are clamped to it", obj.name)
    body = FlexibleBody(dims, basis, offsets, names, np.clip(uvw, 0, 1), np.full(len(uvw), mass / len(uvw)))
    info = {"lattice": lat.name, "lattice_points": list(dims), "points": len(uvw), "mass_kg": round(mass, 4),
            "modes": names, "active_modes": [m.key for m in modes if m.active]}
    return body, lat, modes, info


def ground_of(props, scene_gravity):
    slope, heading = props.ground_slope, props.ground_heading
    axis = np.array([np.cos(heading), np.sin(heading), 0.0])
    normal = np.array([-axis[0] * np.sin(slope), -axis[1] * np.sin(slope), np.cos(slope)])
    return Ground(planes=[Plane((0.0, 0.0, props.ground_height), normal)], stiffness=props.ground_stiffness,
                  normal_damping=props.ground_damping, friction_damping=props.friction_damping,
                  friction=props.friction)


def controller_of(props, body, modes, source=None):
    active = [i for i, m in enumerate(modes) if m.active]
    if not props.use_control or not active:
        return None
    if len(active) > MAX_ACTIVE:
        raise FlexibleError(f"at most {MAX_ACTIVE} active modes can be posed ({len(active)} are active)")
    source = source or props.controller
    poses = props.best_poses if source == "BEST" else props.poses
    if not len(poses):
        raise FlexibleError("the pose graph is empty: add poses, or run the optimisation first"
                            if source == "POSES" else "no best controller stored yet: run the optimisation")
    values = np.array([[p.values[i] for i in range(len(active))] for p in poses])
    durations = np.array([p.duration for p in poses])
    m = body.modal_masses()[active]
    w = 2 * np.pi * props.control_frequency
    return Controller(active, values, durations, m * w * w, 2 * props.control_damping * w * m)


def gains_of(body, modes):
    return ModeGains.from_frequency(body, [m.stiffness for m in modes], [m.damping for m in modes])


def start_state(lat, body):
    loc, rot, _ = lattice_frame(lat)
    return State.rest(body.mode_count, t=loc, quat=rot)


def keyed_amplitudes(lat, names, scene, frames):
    """The lattice's shape-key values as Blender evaluates them (its own animation) at frames."""
    keys = lat.data.shape_keys
    blocks = [keys.key_blocks[n] for n in names]
    saved = scene.frame_current
    out = np.empty((len(frames), len(names)))
    try:
        for i, f in enumerate(frames):
            scene.frame_set(int(f))
            out[i] = [kb.value for kb in blocks]
    finally:
        scene.frame_set(saved)
    return out


def simulation_settings(props, scene, dt, integrator):
    return Settings(dt=dt, integrator=integrator, gravity=tuple(scene.gravity),
                    ground=ground_of(props, scene.gravity), springs=springs_of(props, scene))


def springs_of(props, scene):
    """Springs to objects: a fixed anchor, or for an animated object its path sampled on the
    frames from the start (interpolated in between, held after the end)."""
    out = []
    fps = scene_fps(scene)
    for sp in props.springs:
        if sp.target is None:
            raise FlexibleError("a spring has no object to hold on to")
        anchor = tuple(sp.target.matrix_world.translation)
        if sp.target.animation_data is not None:
            frames = np.arange(props.frame_start, props.frame_end + 1)
            path = _object_path(sp.target, scene, frames)
            times = (frames - props.frame_start) / fps
            anchor = _PathAnchor(times, path)
        out.append(Spring(uvw=tuple(sp.point), anchor=anchor, stiffness=sp.stiffness, damping=sp.damping,
                          rest_length=sp.rest_length, anchor_object=sp.target.name))
    return out


class _PathAnchor:
    def __init__(self, times, path):
        self.times, self.path = times, path

    def __call__(self, time):
        return np.array([np.interp(time, self.times, self.path[:, k]) for k in range(3)])


def _object_path(obj, scene, frames):
    saved = scene.frame_current
    out = np.empty((len(frames), 3))
    try:
        for i, f in enumerate(frames):
            scene.frame_set(int(f))
            out[i] = obj.matrix_world.translation
    finally:
        scene.frame_set(saved)
    return out


def add_spring(obj, target=None):
    props = obj.humananim_flexible
    sp = props.springs.add()
    sp.target = target
    props.spring_index = len(props.springs) - 1
    return sp


# -- simulate and bake ----------------------------------------------------------------------------

def run(obj, scene):
    """Key-framed until the hand-over frame, simulated after; bake new actions. A step generator
    returning the summary."""
    t0 = time.perf_counter()
    props = obj.humananim_flexible
    body, lat, modes, info = build_body(obj)
    if props.frame_end <= props.frame_start:
        raise FlexibleError("the frame range is empty: End must be after Start")
    fps = scene_fps(scene)
    dt = 1.0 / fps / props.substeps
    settings = simulation_settings(props, scene, dt, props.integrator)
    sim = Simulator(body, gains_of(body, modes), settings, controller_of(props, body, modes))
    start = start_state(lat, body)
    names = [m.key for m in modes]
    handover = min(max(props.handover_frame, props.frame_start), props.frame_end)
    duration = (props.frame_end - props.frame_start) / fps
    keys = None
    if handover > props.frame_start and lat.data.shape_keys is not None:
        frames = np.arange(props.frame_start, handover + 1)
        keys = ((frames - props.frame_start) / fps, keyed_amplitudes(lat, names, scene, frames))
        start.gamma = keys[1][0].copy()
    hold = tuple(props.hold_point) if props.use_hold else None
    track, result = yield from animate(sim, start, duration, fps, keys, (handover - props.frame_start) / fps, hold)
    frames = props.frame_start + np.round(track.times * fps)
    written = write_result(obj, lat, names, frames, track)
    summary = {"object": obj.name, **info, **written, "frames": len(frames),
               "frame_range": [int(frames[0]), int(frames[-1])], "handover_frame": int(handover),
               "simulated_seconds": round(float(track.times[-1] - track.times[track.handover - 1]), 4),
               "time_step_s": dt, "integrator": props.integrator,
               "condition_number_max": round(result.cond_max, 2) if result else None,
               "warnings": list(result.warnings) if result else [],
               "controller": props.controller if sim.controller is not None else None,
               "seconds": round(time.perf_counter() - t0, 3)}
    if result is not None:
        summary.update({k: round(v, 4) for k, v in motion_measures(result, _direction(props)).items()})
        end = result.final
        pts = body.positions(end.t, quat_matrix(end.quat), end.gamma)
        ground = settings.ground.planes[0]
        summary["end_lowest_point_m"] = round(float(((pts - ground.point) @ ground.normal).min()), 5)
    return summary


def _direction(props):
    d = np.array(props.direction, float)
    n = np.linalg.norm(d)
    if n < 1e-9:
        raise FlexibleError("the travel direction is zero")
    return d / n


def write_result(obj, lat, names, frames, track):
    """New actions: the lattice's transform, the Key's shape-key values, and the object's
    transform when it isn't the lattice's child. Returns their names."""
    out = {}
    _, _, scale = lattice_frame(lat)
    worlds = [Matrix.LocRotScale(Vector(t), Quaternion(q), Vector(scale)) for t, q in zip(track.t, track.quat)]
    out["lattice_action"] = _bake_transform(lat, worlds, frames, f"{lat.name} Flexible").name
    if obj != lat and not _descends_from(obj, lat):
        rest = lat.matrix_world.inverted() @ obj.matrix_world
        out["object_action"] = _bake_transform(obj, [w @ rest for w in worlds], frames, f"{obj.name} Flexible").name
    key = lat.data.shape_keys
    if key is not None and names:
        widened = []
        for name in names:
            kb = key.key_blocks[name]
            if kb.slider_min > -1.0:  # negative amplitudes would be clamped when played back
                kb.slider_min = -1.0
                widened.append(name)
        out["key_action"] = _bake_keys(key, names, frames, track.gamma).name
        out["slider_min_widened"] = widened
    return out


def _descends_from(obj, ancestor):
    p = obj.parent
    while p is not None:
        if p == ancestor:
            return True
        p = p.parent
    return False


def _bake_transform(obj, worlds, frames, name):
    """A new action keying location and rotation (in the object's rotation mode)."""
    parent = (obj.parent.matrix_world @ obj.matrix_parent_inverse).inverted() if obj.parent else Matrix.Identity(4)
    locs, quats = [], []
    for w in worlds:
        loc, rot, _ = (parent @ w).decompose()
        locs.append(tuple(loc))
        quats.append(tuple(rot))
    quats = rotations.make_continuous(np.array(quats))
    prop, values = rotation_channels(quats, obj.rotation_mode)
    old = obj.animation_data.action if obj.animation_data else None
    if old is not None:
        old.use_fake_user = True  # the source stays, unassigned but kept
    action = bpy.data.actions.new(name)
    writer = action_api.ChannelWriter(action, obj)
    writer.key_columns("location", "Object Transforms", frames, np.array(locs))
    writer.key_columns(prop, "Object Transforms", frames, values)
    action_api.assign_action(obj, action, writer.slot)
    return action


def _bake_keys(key, names, frames, gamma):
    """A new action on the Key datablock with one F-curve per mode's shape-key value."""
    old = key.animation_data.action if key.animation_data else None
    if old is not None:
        old.use_fake_user = True
    action = bpy.data.actions.new(f"{key.user.name if key.user else key.name} Modes")
    writer = action_api.ChannelWriter(action, key, id_type="KEY")
    for k, name in enumerate(names):
        writer.key_columns(f'key_blocks["{bpy.utils.escape_identifier(name)}"].value', "Shape Keys", frames,
                           gamma[:, k:k + 1])
    action_api.assign_action(key, action, writer.slot)
    return action


# -- optimise ---------------------------------------------------------------------------------------

def optimize(obj, scene):
    """Simulated annealing of the pose graph (Fig. 5.2); stores the best controller on the object.
    A step generator returning the summary; closed early (Esc), it stores nothing."""
    t0 = time.perf_counter()
    props = obj.humananim_flexible
    body, lat, modes, info = build_body(obj)
    ctl = controller_of(props, body, modes, "POSES")
    if ctl is None:
        raise FlexibleError("optimisation needs Pose Control on and at least one active mode")
    cost = CostSpec(props.cost, tuple(props.direction), props.cost_scale, props.w_energy, props.w_distance,
                    props.w_speed, props.w_tilt)
    settings = AnnealSettings(optimize=props.optimize, trials=props.trials, duration=props.trial_seconds,
                              start_temperature=max(props.start_temperature, props.frozen_temperature),
                              frozen_temperature=props.frozen_temperature, seed=props.seed)
    sim_settings = simulation_settings(props, scene, props.trial_step, "semi_implicit")
    gains = gains_of(body, modes)
    Simulator(body, gains, sim_settings)  # checks the modes once, before the trials
    sim_settings.check_modes = False
    start = start_state(lat, body)
    result = yield from anneal(lambda c: Simulator(body, gains, sim_settings, c), ctl, start, cost, settings)
    store_best(props, result)
    return {"object": obj.name, **info, "trials": result.trials, "accepted": result.accepted,
            "uphill": result.uphill, "initial_cost": result.initial_cost, "best_cost": result.cost,
            "best_poses": result.poses.round(4).tolist(), "best_durations": result.durations.round(4).tolist(),
            "costs": [float(c) for c in result.costs], "cost": props.cost, "seed": props.seed,
            **{k: round(v, 4) for k, v in result.measures.items()},
            "seconds": round(time.perf_counter() - t0, 3)}


def store_best(props, result):
    props.best_poses.clear()
    for values, duration in zip(result.poses, result.durations):
        pose = props.best_poses.add()
        pose.values = list(values) + [0.0] * (MAX_ACTIVE - len(values))
        pose.duration = float(duration)
    props.best_cost = float(result.cost)
    props.best_distance = float(result.measures["distance_m"])
    props.best_energy = float(result.measures["energy_j"])


def add_pose(obj):
    props = obj.humananim_flexible
    pose = props.poses.add()
    if len(props.poses) > 1:
        prev = props.poses[len(props.poses) - 2]
        pose.values, pose.duration = prev.values, prev.duration
    props.pose_index = len(props.poses) - 1
    return pose


# -- demo ----------------------------------------------------------------------------------------------

def create_demo_table(context, location=(0.0, 0.0, 0.0)):
    """The thesis's table: a mesh (top and four legs) parented to a 4x2x4 lattice with shear,
    bend, squash and horizontal squash shape keys, set up with a hopping pose graph."""
    rest, offsets = table_lattice()
    size = np.ptp(rest, axis=0)
    L, D, H = size
    lat_data = bpy.data.lattices.new("Flexible Table Lattice")
    lat_data.points_u, lat_data.points_v, lat_data.points_w = 4, 2, 4
    lat = bpy.data.objects.new("Flexible Table Lattice", lat_data)
    lat.location = (location[0], location[1], location[2] + H / 2)
    grid = np.empty(len(lat_data.points) * 3)
    lat_data.points.foreach_get("co", grid)
    extent = np.ptp(grid.reshape(-1, 3), axis=0)          # Blender spaces new lattice points by 1
    local_scale = size / np.where(extent > 0, extent, 1.0)
    lat.scale = tuple(local_scale)
    context.scene.collection.objects.link(lat)
    lat.shape_key_add(name="Basis", from_mix=False)
    for name in TABLE_MODES:
        kb = lat.shape_key_add(name=name, from_mix=False)
        co = _key_points(kb, len(rest)) + offsets[name] / local_scale
        kb.data.foreach_set("co", co.ravel())
        kb.slider_min = -1.0
    mesh = bpy.data.meshes.new("Flexible Table")
    verts, faces = [], []
    top = 0.05
    boxes = [((-L / 2, -D / 2, H / 2 - top), (L / 2, D / 2, H / 2))]
    leg = 0.08
    for sx in (-1, 1):
        for sy in (-1, 1):
            x0 = sx * L / 2 - (leg if sx > 0 else 0)
            y0 = sy * D / 2 - (leg if sy > 0 else 0)
            boxes.append(((x0, y0, -H / 2), (x0 + leg, y0 + leg, H / 2 - top)))
    for lo, hi in boxes:
        base = len(verts)
        verts += [(x, y, z) for z in (lo[2], hi[2]) for y in (lo[1], hi[1]) for x in (lo[0], hi[0])]
        faces += [[base + i for i in f] for f in ((0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3),
                                                    (0, 4, 6, 2), (1, 3, 7, 5))]
    # vertices in the lattice's local space (its scale applies to both)
    sx, sy, sz = local_scale
    mesh.from_pydata([(x / sx, y / sy, z / sz) for x, y, z in verts], [], faces)
    mesh.update()
    obj = bpy.data.objects.new("Flexible Table", mesh)
    context.scene.collection.objects.link(obj)
    obj.parent = lat
    mod = obj.modifiers.new("Lattice", "LATTICE")
    mod.object = lat
    props = obj.humananim_flexible
    props.lattice = lat
    sync_modes(obj)
    for m in props.modes:
        m.active = m.key in ("shear", "bend", "squash")
    props.poses.clear()
    for values, duration in (((0.2, 0.0, 0.2), 0.3), ((-0.2, 0.0, -0.2), 0.3)):
        pose = props.poses.add()
        pose.values = list(values) + [0.0] * (MAX_ACTIVE - 3)
        pose.duration = duration
    props.sample_count = 24
    props.density = 500.0
    props.frame_start, props.frame_end, props.handover_frame = 1, 1 + int(round(4 * scene_fps(context.scene))), 1
    props.trials = 60
    context.view_layer.objects.active = obj
    obj.select_set(True)
    context.view_layer.update()  # world matrices, read right away by the bridge
    return obj, lat
