"""Fast plausible cloth in Blender (Oshita 2003, ch. 4): the settings, the garment and its pins,
the body per frame (skinned mesh or capsules on the bones), the simulation over a frame range,
and the result as a NEW mesh object whose vertices come from a PC2 point cache through a Mesh
Cache modifier (the coarse simulation optionally too); plus a skirt generator for any rig."""

import logging
import os
import re
import tempfile
import time

import bpy
import numpy as np

from ...solver.cloth import (CapsuleBody, ClothParams, ClothSimulation, MeshBody, PRESETS, build_mesh, capsule_ends,
                            capsule_mesh, capsules_from_roles, fit_radii, fit_skirt, write_pc2)
from ...solver.cloth.body import skin_radii, skinning_weights
from ...solver.cloth.collision import resolve_particles
from ...solver.cloth.skinned import SkinnedBody, closed_parts
from ...solver.cloth.mesh import ClothError
from ...solver.skeleton import reach_of_made_up_tail
from ..actions import scene_fps
from ..armature import detect
from ..properties import role_overrides

log = logging.getLogger(__name__)

# Blender 4.5+ warns about a '//' path unless the property says it takes one (4.2 has no such option)
FITTED_AT = "humananim_fitted_frame"  # custom property: the frame whose pose a garment was made at
PHYSICAL = ("density", "stretch", "bend", "damping", "drag", "air_damping")


def material(props):
    """The physical values: the preset's, or the custom ones."""
    if props.preset in PRESETS:
        p = PRESETS[props.preset]
        return {name: getattr(p, name) for name in PHYSICAL}
    return {name: getattr(props, name) for name in PHYSICAL}


def params_of(props):
    return ClothParams(**material(props), wind=tuple(props.wind), thickness=props.thickness,
                       substeps=props.substeps, friction=props.friction, compress_limit=props.compress_limit)


# ---- reading Blender data --------------------------------------------------------------------

def _metres(scene):
    return float(scene.unit_settings.scale_length)


def bone_world(arm, scene, rest=False):
    """World matrices (J, 4, 4) of the armature's bones at the current frame (or in the rest
    pose), metres."""
    n = len(arm.pose.bones)
    m = np.empty(n * 16)
    if rest:
        arm.data.bones.foreach_get("matrix_local", m)
    else:
        arm.pose.bones.foreach_get("matrix", m)
    world = np.array(arm.matrix_world) @ m.reshape(n, 4, 4).transpose(0, 2, 1)
    world[:, :3, :] *= _metres(scene)
    return world


def garment_data(obj, scene):
    """World positions (metres) and triangles of the garment's own mesh (modifiers ignored)."""
    mesh = obj.data
    if obj.type != "MESH" or len(mesh.polygons) == 0:
        raise ClothError(f"'{obj.name}' is not a mesh with faces: pick the coarse garment mesh")
    co = np.empty(len(mesh.vertices) * 3)
    mesh.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3) @ np.array(obj.matrix_world)[:3, :3].T + np.array(obj.matrix_world)[:3, 3]
    mesh.calc_loop_triangles()
    tris = np.empty(len(mesh.loop_triangles) * 3, dtype=np.int32)
    mesh.loop_triangles.foreach_get("vertices", tris)
    return co * _metres(scene), tris.reshape(-1, 3).astype(np.int64)


def group_weights(obj, names):
    """(V, len(names)) weights of the object's vertex groups with those names (0 where missing)."""
    out = np.zeros((len(obj.data.vertices), len(names)))
    column = {obj.vertex_groups[n].index: k for k, n in enumerate(names) if n in obj.vertex_groups}
    if column:
        for v in obj.data.vertices:
            for g in v.groups:
                k = column.get(g.group)
                if k is not None:
                    out[v.index, k] = g.weight
    return out


def pinned_vertices(obj, group):
    if not group:
        return np.zeros(0, dtype=np.int64)
    if group not in obj.vertex_groups:
        raise ClothError(f"'{obj.name}' has no vertex group '{group}' for the pinned vertices")
    return np.flatnonzero(group_weights(obj, [group])[:, 0] > 0.0)


def pin_binding(garment, pins, positions, arm, world):
    """Each pinned vertex attached to bones: the garment's own weights for vertex groups named
    after bones when it has them, else the nearest deforming bone. Returns (bones (K, B), weights
    (K, B), offsets (K, B, 3) in those bones' frames at the start frame)."""
    names = [b.name for b in arm.data.bones]
    w = group_weights(garment, names)[pins]
    heads = world[:, :3, 3]
    tails = np.array([world[j, :3, :3] @ [0.0, b.length, 0.0] + world[j, :3, 3] for j, b in enumerate(arm.data.bones)])
    deform = np.array([b.use_deform for b in arm.data.bones])
    from ...solver.cloth.collision import closest_on_segments
    q, _ = closest_on_segments(positions[pins][:, None], heads[None], tails[None])
    dist = np.linalg.norm(positions[pins][:, None] - q, axis=2)
    dist[:, ~deform] += 1e6
    nearest = np.argmin(dist, axis=1)
    weighted = w.sum(axis=1) > 0
    w[~weighted] = 0.0
    w[~weighted, nearest[~weighted]] = 1.0
    w /= w.sum(axis=1, keepdims=True)
    count = int((w > 0).sum(axis=1).max()) if len(pins) else 1
    bones = np.argsort(-w, axis=1)[:, :count]
    weights = np.take_along_axis(w, bones, axis=1)
    inv = np.linalg.inv(world)
    local = np.einsum("kbij,kj->kbi", inv[bones], np.c_[positions[pins], np.ones(len(pins))])[..., :3]
    return bones, weights, local


def pin_targets(binding, world):
    bones, weights, local = binding
    m = world[bones]  # (K, B, 4, 4)
    p = np.einsum("kbij,kbj->kbi", m[..., :3, :3], local) + m[..., :3, 3]
    return np.einsum("kb,kbi->ki", weights, p)


def body_mesh_positions(body, depsgraph, scene, triangles=True):
    """The evaluated body's world vertices (metres) and its triangles (None without
    `triangles`: per frame only the vertices move, and triangulating costs as much as reading)."""
    evaluated = body.evaluated_get(depsgraph)
    mesh = evaluated.to_mesh()
    tris = None
    try:
        co = np.empty(len(mesh.vertices) * 3)
        mesh.vertices.foreach_get("co", co)
        if triangles:
            mesh.calc_loop_triangles()
            tris = np.empty(len(mesh.loop_triangles) * 3, dtype=np.int32)
            mesh.loop_triangles.foreach_get("vertices", tris)
            tris = tris.reshape(-1, 3).astype(np.int64)
    finally:
        evaluated.to_mesh_clear()
    m = np.array(evaluated.matrix_world)
    return (co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]) * _metres(scene), tris


def skinned_collider(body, arm, triangles, positions, world):
    """The body mesh as a collider: a SkinnedBody (searched in its bones' frames, built at this
    pose) when it is one closed skin that the armature deforms through vertex groups named after
    its bones weighing every vertex; else a MeshBody (searched anew at every pose; a body of
    separate, overlapping pieces needs its union, where a point pushed out of one piece can be
    deep in another)."""
    deformed = any(m.type == "ARMATURE" and m.object == arm and m.show_viewport for m in body.modifiers)
    if deformed and len(positions) == len(body.data.vertices) and closed_parts(triangles, len(positions)).max() == 0:
        weights = group_weights(body, [b.name for b in arm.data.bones])
        if weights.sum(axis=1).min() > 0.0:
            return SkinnedBody(triangles, positions, world, weights, rest=rest_pose(body, arm))
    return MeshBody(triangles, len(positions))


def rest_pose(body, arm):
    """The body mesh's own vertices and the armature's bones in its rest pose (world, metres):
    the pose the mesh was modelled in, before the Armature modifier deforms it."""
    scene = bpy.context.scene
    co = np.empty(len(body.data.vertices) * 3)
    body.data.vertices.foreach_get("co", co)
    m = np.array(body.matrix_world)
    return (co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]) * _metres(scene), bone_world(arm, scene, rest=True)


FIGURE_HEIGHT = (0.3, 3.0)  # metres: the figures cloth accepts (its thickness, speeds and grids are for people)


def figure_height(arm, scene):
    """The rest-pose skeleton's height (metres): from its lowest to its highest bone end."""
    world = bone_world(arm, scene, rest=True)
    ends = [world[:, :3, 3]]
    ends.append(np.array([world[j, :3, :3] @ [0.0, b.length, 0.0] + world[j, :3, 3]
                          for j, b in enumerate(arm.data.bones)]))
    z = np.concatenate(ends)[:, 2]
    return float(z.max() - z.min()) if len(z) else 0.0


def check_figure(arm, scene):
    """A ClothError unless the armature is a human-sized figure."""
    height = figure_height(arm, scene)
    if not FIGURE_HEIGHT[0] <= height <= FIGURE_HEIGHT[1]:
        raise ClothError(f"the figure is {height:.3g} m tall: cloth needs a human-sized figure "
                         f"({FIGURE_HEIGHT[0]}-{FIGURE_HEIGHT[1]} m); check the clip's unit (--scale)")


def roles_of(arm):
    return detect(arm).roles.with_overrides(role_overrides(arm.data.humananim))


def reach_ends(arm, tolerance):
    """{bone index: the point it reaches, in its own frame} for bones whose tail the importer made
    up (skeleton.reach_of_made_up_tail; tolerance in armature units)."""
    bones = arm.data.bones
    heads = np.array([b.head_local for b in bones])
    parents = np.array([bones.find(b.parent.name) if b.parent else -1 for b in bones])
    ends = {}
    for j, bone in enumerate(bones):
        reach = reach_of_made_up_tail(parents, heads, j, tolerance)
        if reach is not None:
            m = np.array(bone.matrix_local)
            ends[j] = m[:3, :3].T @ (reach - m[:3, 3])
    return ends


def body_capsules(arm, scene, world, body=None, depsgraph=None):
    """Capsule specs for the armature's body roles; radii from proportions, or fitted to the body
    mesh's vertex groups (named after the bones) when a body mesh is given."""
    names = [b.name for b in arm.data.bones]
    lengths = np.array([b.length for b in arm.data.bones])
    unit = float(np.mean(arm.matrix_world.to_scale())) * _metres(scene)
    specs = capsules_from_roles(names, lengths, roles_of(arm), unit, reach_ends(arm, 0.005 / unit))
    if body is not None and body.type == "MESH" and body.vertex_groups:
        points, _ = body_mesh_positions(body, depsgraph or bpy.context.evaluated_depsgraph_get(), scene, triangles=False)
        weights = group_weights(body, names)
        radii = fit_radii(specs, world, points, weights)
        for spec, r in zip(specs, radii):
            spec.radius = float(r)
    return specs


# ---- the job --------------------------------------------------------------------------------

def frame_plan(scene, props):
    start = props.frame_start or scene.frame_start
    end = props.frame_end or scene.frame_end
    if end <= start:
        raise ClothError(f"the frame range {start}-{end} is empty")
    step = props.frame_step or max(1, int(round(scene_fps(scene) / 30.0)))
    frames = list(range(start, end + 1, step))
    if frames[-1] != end:
        frames.append(end)
    return frames


# poses read ahead of the simulation (skinned body vertices of that many frames are held)
READ_AHEAD = 16


def _chunks(items, size):
    for k in range(0, len(items), size):
        yield items[k:k + size]


class ClothJob:
    """`steps()` simulates frame by frame (yielding progress); `write()` writes what is done,
    so a cancelled job keeps its frames."""

    def __init__(self, scene, props=None, max_frames=None):
        self.scene = scene
        self.props = props or scene.humananim_cloth
        self.max_frames = max_frames  # simulate only the first few frames of the range (a preview)
        # frames whose poses are read from the scene before they are simulated: the solver then
        # runs frame after frame with its data and code in the processor's caches, which Blender's
        # frame evaluation in between would evict (a preview reads one: its body shows the
        # frame being simulated)
        self.read_ahead = 1 if max_frames else READ_AHEAD
        self.fine, self.coarse, self.frames_done = [], [], []
        self.sim = None
        self.seconds = 0.0
        self.depth_max = 0.0
        self.measure_surface = False  # also measure the rendered surface's depth (tests, benchmarks)
        self.surface_depth_max = 0.0
        self.stretch = []

    # setup
    def _check(self):
        p = self.props
        if p.garment is None:
            raise ClothError("pick the garment mesh")
        if p.armature is None or p.armature.type != "ARMATURE":
            raise ClothError("pick the character's armature")
        if p.collider in ("MESH", "BOTH") and p.body is None:
            raise ClothError("pick the body mesh to collide with (or collide with capsules)")
        if p.body is not None and p.body.type != "MESH":
            raise ClothError(f"'{p.body.name}' is not a mesh")
        check_figure(p.armature, self.scene)

    def steps(self):
        self._check()
        scene, p = self.scene, self.props
        frames = frame_plan(scene, p)
        if self.max_frames:
            frames = frames[:max(2, self.max_frames + 1)]
        fps = scene_fps(scene)
        saved = (scene.frame_current, scene.frame_subframe)
        try:
            scene.frame_set(frames[0])
            depsgraph = bpy.context.evaluated_depsgraph_get()
            positions, tris = garment_data(p.garment, scene)
            pins = pinned_vertices(p.garment, p.pin_group)
            arm = p.armature
            positions, _ = self._carried(positions, pins, frames[0])
            depsgraph = bpy.context.evaluated_depsgraph_get()
            mesh = build_mesh(positions, tris)
            world = bone_world(arm, scene)
            use_mesh = p.collider in ("MESH", "BOTH") or (p.collider == "AUTO" and p.body is not None)
            use_caps = p.collider in ("CAPSULES", "BOTH") or (p.collider == "AUTO" and p.body is None)
            bodies, caps, skin, specs = [], None, None, None
            if use_caps:
                specs = body_capsules(arm, scene, world, p.body, depsgraph)
                caps = CapsuleBody([s.radius for s in specs], [s.name for s in specs])
                caps_prev = capsule_ends(specs, world)
                caps.set_motion(*caps_prev)
                bodies.append(caps)
            if use_mesh:
                verts_prev, body_tris = body_mesh_positions(p.body, depsgraph, scene)
                skin = skinned_collider(p.body, arm, body_tris, verts_prev, world)
                world_prev = world
                skin.set_motion(*self._body_motion(skin, verts_prev, world))
                bodies.append(skin)
            params = params_of(p)
            if bodies:  # a garment made at another pose (or over capsules) may cut this body: out
                positions = positions.copy()  # first, pinned vertices too (their binding is taken after)
                resolve_particles(positions, np.zeros_like(positions), bodies, 1.0, params.thickness,
                                  np.ones(len(positions), dtype=bool), passes=16)
            binding = pin_binding(p.garment, pins, positions, arm, world) if len(pins) else None
            self.sim = sim = ClothSimulation(mesh, params, pins, bodies, p.level, fps / (frames[1] - frames[0]),
                                             positions, p.normal_control, p.edge_control)
            self.mesh, self.frames_all = mesh, frames
            self._record(frames[0])
            yield 1.0 / len(frames)
            t0 = time.perf_counter()
            for chunk in _chunks(list(enumerate(frames[1:], start=1)), self.read_ahead):
                poses = []
                for _, f in chunk:
                    poses.append(self._pose(f, arm, specs, binding, None if skin is None else len(verts_prev)))
                    yield len(self.frames_done) / len(frames)  # (the UI stays responsive while reading)
                for (i, f), (ends, verts, targets, bones) in zip(chunk, poses):
                    dt = (f - frames[i - 1]) / fps
                    if caps is not None:
                        caps.set_motion(*caps_prev, *ends, dt)
                        caps_prev = ends
                    if skin is not None:
                        skin.set_motion(*self._body_motion(skin, verts_prev, world_prev, verts, bones), dt=dt)
                        verts_prev, world_prev = verts, bones
                    sim.step(targets, dt)
                    self._record(f)
                    yield (i + 1) / len(frames)
            self.seconds = time.perf_counter() - t0
        finally:
            scene.frame_set(*saved[:1], subframe=saved[1])

    def _pose(self, frame, arm, specs, binding, vertex_count):
        """What the simulation needs of the scene at `frame`: (capsule ends (None without
        `specs`), skinned body vertices (None without `vertex_count`), pin targets (None without
        `binding`), the bones' world matrices)."""
        scene, p = self.scene, self.props
        scene.frame_set(frame)
        world = bone_world(arm, scene)
        ends = capsule_ends(specs, world) if specs is not None else None
        verts = None
        if vertex_count is not None:
            verts, _ = body_mesh_positions(p.body, bpy.context.evaluated_depsgraph_get(), scene, triangles=False)
            if len(verts) != vertex_count:
                raise ClothError(f"'{p.body.name}' changes its vertex count between frames")
        return ends, verts, pin_targets(binding, world) if binding is not None else None, world

    def _carried(self, positions, pins, frame):
        """The garment at `frame`'s pose: a garment made at another frame's pose (a generated
        skirt records it: FITTED_AT) moves there rigidly with the bone its pinned vertices follow
        most (the pelvis without pins). (positions, whether they moved.) Leaves the scene at
        `frame`."""
        p, scene, arm = self.props, self.scene, self.props.armature
        fitted = p.garment.get(FITTED_AT)
        if fitted is None or int(fitted) == frame:
            return positions, False
        scene.frame_set(int(fitted))
        then = bone_world(arm, scene)
        scene.frame_set(frame)
        now = bone_world(arm, scene)
        if len(pins):
            bones = pin_binding(p.garment, pins, positions, arm, then)[0][:, 0]
            anchor = int(np.bincount(bones).argmax())
        else:
            anchor = arm.data.bones.find(roles_of(arm).bone("pelvis") or arm.data.bones[0].name)
        move = now[anchor] @ np.linalg.inv(then[anchor])
        log.info("garment '%s' made at frame %s: carried to frame %d with bone '%s'", p.garment.name, fitted, frame,
                 arm.data.bones[anchor].name)
        return positions @ move[:3, :3].T + move[:3, 3], True

    @staticmethod
    def _body_motion(skin, v0, bones0, v1=None, bones1=None):
        """set_motion's arguments for the skinned body (its bones' matrices too) or a plain mesh."""
        if isinstance(skin, SkinnedBody):
            return (v0, bones0, v1, bones1)
        return (v0, v1)

    def _record(self, frame):
        sim = self.sim
        self.fine.append(sim.surface().astype(np.float32))
        self.coarse.append(sim.x.astype(np.float32))
        self.frames_done.append(frame)
        if sim.bodies:
            self.depth_max = max(self.depth_max, float(sim.depth_inside().max()))
            if self.measure_surface:  # (every rendered vertex too: a query of them all)
                self.surface_depth_max = max(self.surface_depth_max,
                                             float(sim.depth_inside(self.fine[-1].astype(float)).max()))
        self.stretch.append(sim.stretch())

    # output
    def write(self):
        """New objects with Mesh Cache modifiers reading the PC2 files; the summary."""
        if len(self.frames_done) < 2:
            raise ClothError("no frame was simulated: nothing to write")
        p, scene = self.props, self.scene
        unit = _metres(scene)
        frames = np.array(self.frames_done)
        every = np.arange(frames[0], frames[-1] + 1)
        folder = cache_folder(p)
        base = _safe(p.garment.name)
        fine = resample(np.array(self.fine), frames, every) / unit
        fine_obj = new_mesh_object(f"{p.garment.name}.cloth", fine[0], self.sim.smoother.faces, p.garment, smooth=True)
        fine_path = os.path.join(folder, f"{base}.cloth.pc2")
        write_pc2(fine_path, fine, start=float(every[0]), rate=1.0)
        add_mesh_cache(fine_obj, fine_path, int(every[0]))
        wrote = [fine_path]
        coarse_name = None
        if p.keep_coarse:
            coarse = resample(np.array(self.coarse), frames, every) / unit
            coarse_obj = new_mesh_object(f"{p.garment.name}.cloth_coarse", coarse[0], self.mesh.faces, p.garment,
                                         smooth=False)
            coarse_path = os.path.join(folder, f"{base}.cloth_coarse.pc2")
            write_pc2(coarse_path, coarse, start=float(every[0]), rate=1.0)
            add_mesh_cache(coarse_obj, coarse_path, int(every[0]))
            wrote.append(coarse_path)
            coarse_name = coarse_obj.name
        sim = self.sim
        timing = {k: round(v, 4) for k, v in sim.ms_per_frame().items()}
        return {
            "object": fine_obj.name, "coarse_object": coarse_name, "wrote": wrote,
            "frames": int(len(frames)), "frame_range": [int(frames[0]), int(frames[-1])],
            "complete": bool(frames[-1] == self.frames_all[-1]),
            "frame_step": int(frames[1] - frames[0]) if len(frames) > 1 else 1,
            "particles": int(self.mesh.particle_count), "coarse_faces": int(len(self.mesh.faces)),
            "fine_vertices": int(fine.shape[1]), "fine_faces": int(len(sim.smoother.faces)),
            "pinned": int(len(sim.pins)), "colliders": [type(b).__name__ for b in sim.bodies],
            "substeps": int(sim.substeps), "stiffness_capped": bool(sim.dynamics.capped),
            "max_depth_inside_mm": round(1000.0 * self.depth_max, 3),
            "max_mean_stretch": round(float(np.max(np.abs(self.stretch))), 5),
            "contacts": dict(sim.contacts), "timing_ms_per_frame": timing,
            "simulate_seconds": round(self.seconds, 3),
        }


class ClothPreview:
    """A live preview in the viewport: simulates the first `frames` frames of the range one per
    `tick()` into a temporary mesh object (the smoothed surface), then plays them in a loop.
    `stop()` removes the object and its mesh and puts the scene frame back: nothing of the
    preview stays in the file."""

    def __init__(self, scene, frames=30, props=None):
        self.scene = scene
        self.job = ClothJob(scene, props, max_frames=frames)
        self.steps = self.job.steps()
        self.frame_before = (scene.frame_current, scene.frame_subframe)
        self.obj = None
        self.shown = 0  # index into the job's frames
        self.simulating = True

    def tick(self):
        """One frame more (simulated, or played back once all are): the frame shown."""
        if self.simulating:
            done = len(self.job.frames_done)
            while len(self.job.frames_done) == done:  # (the job also yields after reading a pose)
                next(self.steps)
            if len(self.job.frames_done) == len(self.job.frames_all):  # the last one: let the job end
                next(self.steps, None)  # (which puts the scene frame back)
                self.simulating = False
            if self.obj is None:  # the first step set up the simulation and its fine mesh
                self.obj = new_mesh_object(f"{self.job.props.garment.name}.cloth_preview",
                                           self.job.fine[0] / _metres(self.scene), self.job.sim.smoother.faces,
                                           self.job.props.garment, smooth=True)
                self.obj.hide_render = True
            self.shown = len(self.job.fine) - 1  # the frame just simulated
        else:
            self.shown = (self.shown + 1) % len(self.job.fine)
            self.scene.frame_set(self.job.frames_done[self.shown])  # the body with its cloth
        self._show(self.shown)
        return self.job.frames_done[self.shown]

    def _show(self, i):
        co = (self.job.fine[i] / _metres(self.scene)).astype(np.float32)
        self.obj.data.vertices.foreach_set("co", co.ravel())
        self.obj.data.update()

    def stop(self):
        """Remove the preview object and its mesh; the scene frame as it was."""
        playing = not self.simulating
        self.steps.close()  # a simulating job puts its frame back itself (ClothJob's finally)
        if self.obj is not None:
            mesh = self.obj.data
            bpy.data.objects.remove(self.obj, do_unlink=True)
            if mesh.users == 0:
                bpy.data.meshes.remove(mesh)
            self.obj = None
        if playing:  # the playback moved the frame
            self.scene.frame_set(self.frame_before[0], subframe=self.frame_before[1])

    def message(self):
        t = self.job.sim.ms_per_frame() if self.job.sim is not None else {"total_ms": 0.0}
        return (f"preview of {len(self.job.frames_done) - 1} frames: {t['total_ms']:.1f} ms per frame "
                f"(CPU: simulation, collision, smoothing); nothing was kept")


def run(scene, props=None):
    """The whole job as steps (for batch runs): the summary at the end."""
    job = ClothJob(scene, props)
    yield from job.steps()
    return job.write()


def resample(samples, frames, every):
    """Simulated frames to every scene frame between, linearly."""
    if len(frames) == len(every):
        return samples
    idx = np.clip(np.searchsorted(frames, every, side="right") - 1, 0, len(frames) - 2)
    t = ((every - frames[idx]) / (frames[idx + 1] - frames[idx]))[:, None, None]
    return (1.0 - t) * samples[idx] + t * samples[idx + 1]


def cache_folder(props):
    path = props.cache_dir or "//cloth_cache"
    if path.startswith("//") and not bpy.data.filepath:
        path = os.path.join(tempfile.gettempdir(), "humananim_cloth", path[2:])
    folder = bpy.path.abspath(path)
    os.makedirs(folder, exist_ok=True)
    return folder


def _safe(name):
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name) or "cloth"


def new_mesh_object(name, positions, faces, like, smooth=True):
    """A new mesh object at the world origin (vertices in world space), in `like`'s collections,
    with its materials."""
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(positions.tolist(), [], faces.tolist())
    if smooth:
        mesh.polygons.foreach_set("use_smooth", np.ones(len(mesh.polygons), dtype=bool))
    for mat in getattr(like.data, "materials", ()):
        mesh.materials.append(mat)
    mesh.update()
    obj = bpy.data.objects.new(name, mesh)
    collections = list(like.users_collection) or [bpy.context.scene.collection]
    for c in collections:
        c.objects.link(obj)
    return obj


def add_mesh_cache(obj, path, frame_start):
    mod = obj.modifiers.new("Cloth Cache", "MESH_CACHE")
    mod.cache_format = "PC2"
    mod.filepath = bpy.path.relpath(path) if bpy.data.filepath else path
    mod.frame_start = float(frame_start)
    mod.play_mode = "SCENE"
    return mod


# ---- the skirt generator and a stand-in body --------------------------------------------------

def add_skirt(armature, scene=None, name="Skirt", rings=6, columns=11, length=0.9, flare=1.3, waist=0.25,
              clearance=0.02, pin_group="waist", frame=None, set_settings=True):
    """A procedural skirt (Oshita 2003 §4.5) fitted to `armature` at `frame` (default: the current
    one): `rings` rings of `columns` particles (6 x 11 = the thesis's 66) from `waist` thigh lengths
    above the hip joints to `length` thigh lengths below them, clearing capsules on the bones by
    `clearance` metres, the hem flared by `flare`. Its top ring is in the vertex group `pin_group`
    and, for the attachment, in a group named after the pelvis bone. Needs pelvis and thigh roles
    (any rig HumanAnim recognises). Returns the new object; with `set_settings` it also becomes
    the scene's cloth garment, with this armature and pinned group."""
    scene = scene or bpy.context.scene
    if armature is None or armature.type != "ARMATURE":
        raise ClothError("add_skirt needs an armature")
    check_figure(armature, scene)
    saved = scene.frame_current
    if frame is not None:
        scene.frame_set(frame)
    try:
        world = bone_world(armature, scene)
        specs = body_capsules(armature, scene, world)
    finally:
        if frame is not None:
            scene.frame_set(saved)
    roles = roles_of(armature)
    names = [b.name for b in armature.data.bones]
    thighs = [names.index(roles.bone(f"thigh.{s}")) for s in "LR"]
    heads = world[thighs, :3, 3]
    knees = np.array([world[j, :3, :3] @ [0.0, armature.data.bones[j].length, 0.0] + world[j, :3, 3] for j in thighs])
    caps = CapsuleBody([s.radius for s in specs])
    caps.set_motion(*capsule_ends(specs, world))
    up = np.array([0.0, 0.0, 1.0])
    positions, faces, pinned = fit_skirt(heads, knees, up, [caps], rings, columns, length, waist, flare, clearance)
    obj = new_mesh_object(name, positions / _metres(scene), faces, armature, smooth=True)
    obj.data.materials.clear()
    obj[FITTED_AT] = int(frame if frame is not None else saved)
    for group in (pin_group, roles.bone("pelvis")):
        vg = obj.vertex_groups.new(name=group)
        vg.add([int(i) for i in pinned], 1.0, "REPLACE")
    if set_settings and hasattr(scene, "humananim_cloth"):
        props = scene.humananim_cloth
        props.garment, props.armature, props.pin_group = obj, armature, pin_group
    return obj


def add_capsule_body(armature, scene=None, name="Body", segments=16):
    """A stand-in skinned body: a closed capsule mesh per body part, each in the vertex group of
    its bone, deformed by the armature (an Armature modifier). Returns the new mesh object."""
    scene = scene or bpy.context.scene
    check_figure(armature, scene)
    world = bone_world(armature, scene, rest=True)  # the Armature modifier deforms from the rest pose
    specs = body_capsules(armature, scene, world)
    a, b = capsule_ends(specs, world)
    verts, tris, groups, n = [], [], [], 0
    names = [bn.name for bn in armature.data.bones]
    for spec, ca, cb in zip(specs, a, b):
        v, t = capsule_mesh(ca, cb, spec.radius, segments=segments, spacing=0.025)
        verts.append(v), tris.append(t + n), groups.append((names[spec.owner], np.arange(n, n + len(v))))
        n += len(v)
    obj = new_mesh_object(name, np.vstack(verts) / _metres(scene), np.vstack(tris), armature, smooth=True)
    obj.data.materials.clear()
    for bone, idx in groups:
        vg = obj.vertex_groups.get(bone) or obj.vertex_groups.new(name=bone)
        vg.add([int(i) for i in idx], 1.0, "REPLACE")
    mod = obj.modifiers.new("Armature", "ARMATURE")
    mod.object = armature
    obj.parent = armature
    obj.matrix_parent_inverse = armature.matrix_world.inverted()
    return obj


def _grown_skin(scene, heads, tails, radius, resolution):
    """A closed skin over the bones: a metaball capsule on each bone of some length (radius at
    its head), polygonised by Blender at `resolution` (Blender units). A new mesh datablock."""
    balls = bpy.data.metaballs.new("skin")
    balls.resolution = balls.render_resolution = resolution
    balls.threshold = 0.6
    for head, tail, r in zip(heads, tails, radius):
        axis = tail - head
        length = float(np.linalg.norm(axis))
        if length < 1e-6 or r <= 0.0:
            continue
        e = balls.elements.new(type="CAPSULE")
        e.co = tuple((head + tail) / 2.0)
        e.radius = 1.35 * r  # (the surface of a lone ball sits inside its radius at this threshold)
        e.size_x = length / 2.0
        x = axis / length
        from mathutils import Vector
        e.rotation = Vector((1.0, 0.0, 0.0)).rotation_difference(Vector(tuple(x)))
    grower = bpy.data.objects.new("skin", balls)
    scene.collection.objects.link(grower)
    try:
        return bpy.data.meshes.new_from_object(grower.evaluated_get(bpy.context.evaluated_depsgraph_get()))
    finally:
        bpy.data.objects.remove(grower, do_unlink=True)
        bpy.data.metaballs.remove(balls)
        bpy.context.view_layer.update()  # (no stale base of the removed object for operators)


def _automatic_weights(obj, armature, names):
    """Blender's automatic (bone heat) weights, as Ctrl P > With Automatic Weights; False if
    some vertex got none (the heat solve fails on some meshes)."""
    view_layer = bpy.context.view_layer
    selected = [o for o in view_layer.objects if o.select_get()]
    active = view_layer.objects.active
    try:
        for o in selected:
            o.select_set(False)
        obj.select_set(True)
        armature.select_set(True)
        view_layer.objects.active = armature
        bpy.ops.object.parent_set(type="ARMATURE_AUTO")
    except RuntimeError:
        return False
    finally:
        obj.select_set(False)
        armature.select_set(False)
        for o in selected:
            o.select_set(True)
        view_layer.objects.active = active
    return bool(group_weights(obj, names).sum(axis=1).min() > 0.5)


def add_skin_body(armature, scene=None, name="Body", triangles=20000):
    """A stand-in for the character's skinned mesh, grown over the bones: a metaball capsule
    on each bone (radii by body role: skin_radii), polygonised by Blender at the resolution
    that gives about `triangles` triangles (one closed surface, blended at the joints), skinned
    with Blender's automatic weights (by distance, skinning_weights, where they fail) and
    deformed by an Armature modifier. Returns the new mesh object."""
    scene = scene or bpy.context.scene
    check_figure(armature, scene)
    bones = armature.data.bones
    names = [b.name for b in bones]
    parents = [names.index(b.parent.name) if b.parent else -1 for b in bones]
    world = bone_world(armature, scene, rest=True)
    unit = _metres(scene)
    heads = world[:, :3, 3] / unit
    tails = np.array([world[j, :3, :3] @ [0.0, b.length, 0.0] + world[j, :3, 3] for j, b in enumerate(bones)]) / unit
    scale = float(np.mean(armature.matrix_world.to_scale())) * unit
    radius = skin_radii(names, parents, np.array([b.length for b in bones]), roles_of(armature), scale) / unit
    resolution = 0.02 / unit
    for _ in range(4):  # triangles go as 1 / resolution^2
        mesh = _grown_skin(scene, heads, tails, radius, resolution)
        mesh.calc_loop_triangles()
        count = len(mesh.loop_triangles)
        if abs(count - triangles) < 0.08 * triangles:
            break
        bpy.data.meshes.remove(mesh)
        resolution *= (count / triangles) ** 0.5
    else:
        mesh = _grown_skin(scene, heads, tails, radius, resolution)
    mesh.name = name
    obj = bpy.data.objects.new(name, mesh)
    for c in list(armature.users_collection) or [scene.collection]:
        c.objects.link(obj)
    mesh.polygons.foreach_set("use_smooth", np.ones(len(mesh.polygons), dtype=bool))
    mesh.update()
    if not _automatic_weights(obj, armature, names):
        co = np.empty(len(mesh.vertices) * 3)
        mesh.vertices.foreach_get("co", co)
        weights = skinning_weights(co.reshape(-1, 3) * unit, heads * unit, tails * unit,
                                   [b.use_deform for b in bones])
        obj.vertex_groups.clear()
        levels = np.round(weights * 64.0).astype(int)  # vertex groups take one weight per call
        for j, bone_name in enumerate(names):
            column = levels[:, j]
            if column.any():
                vg = obj.vertex_groups.new(name=bone_name)
                for level in np.unique(column[column > 0]):
                    vg.add(np.flatnonzero(column == level).tolist(), level / 64.0, "REPLACE")
    obj.modifiers.clear()
    mod = obj.modifiers.new("Armature", "ARMATURE")
    mod.object = armature
    obj.parent = armature
    obj.matrix_parent_inverse = armature.matrix_world.inverted()
    return obj
