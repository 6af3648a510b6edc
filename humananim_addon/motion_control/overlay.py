"""The dynamic control overlay in the 3D viewport, like Oshita's figures: the input motion as a
grey ghost, the result's bones coloured by the control acting on them (blue comfort, green
balance, yellow passive), stressed joints red, and the ZMP and support polygon on the ground.

Drawn with the `gpu` module from data kept in memory (motion_control.CACHE): nothing is added
to the scene. `frame_geometry` is pure numpy (tested headless); only `_draw` touches the GPU.
`render_picture` turns the same geometry into a still (Workbench) in a temporary scene."""

import logging
from dataclasses import dataclass

import bpy
import numpy as np

from ..view_overlay import ViewOverlay
from . import job as motion_control

log = logging.getLogger(__name__)

GHOST = (0.55, 0.55, 0.55, 0.45)
FREE = (0.92, 0.92, 0.92, 1.0)  # no control acting
KIND_COLOURS = {1: (1.0, 0.85, 0.1, 1.0), 2: (0.15, 0.45, 1.0, 1.0), 3: (0.1, 0.8, 0.2, 1.0)}  # passive, comfort, balance
STRESS = (1.0, 0.1, 0.1, 1.0)
POLYGON = (0.1, 0.85, 0.85, 1.0)
ZMP = (1.0, 0.45, 0.0, 1.0)
ZMP_FALLING = (1.0, 0.0, 0.6, 1.0)
CROSS = 0.05  # half size of the ZMP cross (Blender units, ~m)


def frame_index(data, frame):
    """Index of the sampled frame nearest `frame`, or None outside the range."""
    frames = data.frames
    if len(frames) == 0 or frame < frames[0] - 0.5 or frame > frames[-1] + 0.5:
        return None
    return int(np.argmin(np.abs(frames - frame)))


def frame_geometry(data, frame, ghost=True):
    """What to draw at `frame`: a list of (segments (n, 2, 3), colour rgba, width in pixels).
    Empty outside the result's frames."""
    i = frame_index(data, frame)
    if i is None:
        return []
    out = []
    if ghost:
        out.append((data.ghost[i], GHOST, 2.0))
    kinds = np.asarray(data.control[i])
    stressed = np.asarray(data.stress[i]) > 1e-6
    free = (kinds == 0) & ~stressed
    if free.any():
        out.append((data.bones[i][free], FREE, 3.0))
    uncontrolled_stress = (kinds == 0) & stressed
    if uncontrolled_stress.any():
        out.append((data.bones[i][uncontrolled_stress], STRESS, 4.0))
    for code, colour in KIND_COLOURS.items():
        sel = kinds == code
        if sel.any():
            out.append((data.bones[i][sel], colour, 4.0))
    if stressed.any():  # a red cross on every stressed joint, whatever control acts on it
        out.append((_crosses(data.bones[i][stressed, 0], 0.03), STRESS, 3.0))
    h = data.ground
    polygon = np.asarray(data.polygons[i], float).reshape(-1, 2) if i < len(data.polygons) else np.zeros((0, 2))
    if len(polygon) >= 2:
        ring = np.column_stack((polygon, np.full(len(polygon), h)))
        out.append((np.stack((ring, np.roll(ring, -1, axis=0)), axis=1), POLYGON, 2.0))
    zmp = np.asarray(data.zmp[i], float)
    if np.isfinite(zmp).all():
        colour = ZMP_FALLING if bool(data.falling[i]) else ZMP
        out.append((_crosses(np.array([[zmp[0], zmp[1], h]]), CROSS, flat=True), colour, 3.0))
    return out


def _crosses(points, size, flat=False):
    axes = np.eye(3)[:2 if flat else 3] * size
    segs = [np.stack((p - a, p + a)) for p in np.asarray(points, float) for a in axes]
    return np.array(segs).reshape(-1, 2, 3)


def _draw():
    try:
        context = bpy.context
        scene = context.scene
        if not motion_control.CACHE or scene is None:
            return
        frame = scene.frame_current + scene.frame_subframe
        groups = []
        for obj in scene.objects:
            if obj.type == "ARMATURE" and obj.visible_get():
                data = motion_control.overlay_data(obj)
                if data is not None:
                    groups.extend(frame_geometry(data, frame))
        if groups:
            _draw_lines(groups)
    except Exception:  # a broken overlay must never break the viewport
        log.exception("dynamic control overlay")


def _draw_lines(groups):
    import gpu
    from gpu_extras.batch import batch_for_shader
    shader = gpu.shader.from_builtin("POLYLINE_UNIFORM_COLOR")
    gpu.state.blend_set("ALPHA")
    gpu.state.depth_test_set("NONE")
    viewport = gpu.state.viewport_get()
    shader.bind()
    shader.uniform_float("viewportSize", (viewport[2], viewport[3]))
    for segments, colour, width in groups:
        coords = np.asarray(segments, np.float32).reshape(-1, 3)
        batch = batch_for_shader(shader, "LINES", {"pos": coords})
        shader.uniform_float("lineWidth", width)
        shader.uniform_float("color", colour)
        batch.draw(shader)
    gpu.state.blend_set("NONE")


# ---- a still of the result -------------------------------------------------------------------------

PICTURE_COLOURS = {GHOST: (0.72, 0.72, 0.72, 1.0), FREE: (0.2, 0.2, 0.22, 1.0)}  # on a light ground
LOAD = (0.45, 0.25, 0.1, 1.0)
PUSH = (0.95, 0.2, 0.05, 1.0)
GARMENT = (0.25, 0.45, 1.0, 0.4)  # see-through: the bones inside stay readable
LABEL = (0.1, 0.1, 0.1, 1.0)
SPACING = 0.9  # metres at least between two snapshots, whatever the labels need


@dataclass
class Load:
    """A load drawn hanging from a hand: the hand's bone index, kg, the first frame it is carried."""
    bone: int
    kg: float
    frame: float


@dataclass
class Push:
    """An impulse or force drawn as an arrow into `point` (world, at `frame`) along `direction`."""
    bone: int
    frame: float
    point: np.ndarray  # offset from the bone's head at that frame (m, world axes)
    direction: np.ndarray  # unit, world
    text: str  # "15 N s" or "300 N for 0.1 s"


def snapshot_frames(data, count=5, include=()):
    """`count` frames spread over the result, with each frame of `include` (the pushes) replacing
    the nearest of them, so the picture shows the moment of each push."""
    frames = [float(f) for f in data.frames[np.linspace(0, len(data.frames) - 1, count).round().astype(int)]]
    for f in include:
        i = frame_index(data, f)
        if i is None:
            continue
        f = float(data.frames[i])
        if f not in frames:
            k = min(range(1, len(frames) - 1) or range(len(frames)), key=lambda k: abs(frames[k] - f))
            frames[k] = f
    return sorted(set(frames))


def label_width(text, size):
    """Width of a line of text in Blender's default font, generously: most glyphs are narrower."""
    return 0.62 * size * len(text)


def strip_shift(travel, label_widths, spacing=SPACING):
    """Offsets along the picture axis that make snapshots at positions `travel` (m, in frame order)
    stand at least `spacing` apart and their labels (widths, centred under each) clear of each
    other: none when they already are, else a film strip in frame order."""
    travel = np.asarray(travel, float)
    if len(travel) < 2:
        return np.zeros(len(travel))
    widths = np.asarray(label_widths, float)
    need = np.maximum(spacing, (widths[:-1] + widths[1:]) / 2 * 1.15)
    order = np.argsort(travel, kind="stable")
    gaps = np.diff(travel[order])
    if (gaps >= need[:len(gaps)].max()).all():  # labels with the widest gap clear in any order
        return np.zeros(len(travel))
    step = max(spacing, need.max())
    return step * np.arange(len(travel)) - (travel - travel[0])


def render_result(obj, scene, action, path, title=None, garments=(), count=5):
    """The still of a dynamic-control result (`action`, made by motion_control.run on `obj`): the
    loads hanging from the hands, each push as an arrow at its frame, and `garments` (mesh
    objects, e.g. a simulated skirt) as they stand at each snapshot. Returns the frames shown."""
    from ..armature import skeleton_from_armature
    data = motion_control.CACHE[(obj.name, action)]
    props = scene.humananim_control
    skeleton = skeleton_from_armature(obj, scene)
    names = list(skeleton.names)
    loads = []
    for side, kg in zip(("L", "R"), (props.load_left, props.load_right)):
        hand = skeleton.roles.bone(f"hand.{side}")
        if kg > 0 and hand in names:
            loads.append(Load(names.index(hand), kg, float(props.load_frame or data.frames[0])))
    pushes = []
    saved = scene.frame_current
    try:
        for item in props.impulses:
            if item.empty is None or item.magnitude <= 0 or item.bone not in names:
                continue
            i = frame_index(data, item.frame)
            if i is None:
                continue
            scene.frame_set(int(round(data.frames[i])))
            m = np.array(item.empty.matrix_world)
            j = names.index(item.bone)
            text = (f"{item.magnitude:g} N s" if item.duration <= 0
                    else f"{item.magnitude:g} N for {item.duration:g} s")
            pushes.append(Push(j, float(data.frames[i]), m[:3, 3] - data.ghost[i, j, 0],
                               m[:3, 2] / np.linalg.norm(m[:3, 2]), text))
    finally:
        scene.frame_set(saved)
    frames = snapshot_frames(data, count, include=[p.frame for p in pushes])
    return render_picture(data, path, frames, title=title, loads=loads, pushes=pushes,
                          garments=[(scene, g) for g in garments])


def render_picture(data, path, frames=None, resolution=(1280, 540), title=None, loads=(), pushes=(),
                   garments=()):
    """A PNG of the result at a few frames, seen from the side, in a temporary scene rendered by
    Workbench (works headless): ghost, coloured bones, stressed joints, support polygons, ZMP,
    and when given the loads (Load), pushes (Push) and garments ((scene, mesh object) pairs,
    evaluated at each frame). Snapshots whose bodies or labels would overlap are spread out
    like a film strip. Returns the frames shown."""
    frames = snapshot_frames(data) if frames is None else list(frames)
    index = [frame_index(data, f) for f in frames]
    roots = data.bones[:, 0, 0]
    along, view = _picture_axes(data, roots)
    travel = np.array([roots[i, :2] @ along for i in index])
    aspect = resolution[0] / resolution[1]
    texts = [f"frame {f:g}" for f in frames]
    size = _label_size(data, travel, aspect)
    shift = strip_shift(travel, [label_width(t, size) for t in texts])
    if shift.any():
        size = _label_size(data, travel + shift, aspect)
    scene = bpy.data.scenes.new("HumanAnim Picture")
    made = []
    try:
        points = []
        for frame, dx, i in zip(frames, shift, index):
            offset = np.array([along[0], along[1], 0.0]) * dx
            for k, (segments, colour, width) in enumerate(frame_geometry(data, frame)):
                segments = np.asarray(segments, float) + offset
                points.append(segments.reshape(-1, 3))
                made.append(tube_object(scene, f"f{frame:g}.{k}", segments, PICTURE_COLOURS.get(colour, colour),
                                         0.004 * width))
            made.extend(_loads_drawn(scene, data, loads, frame, i, offset))
            made.extend(_pushes_drawn(scene, data, pushes, frame, i, offset, points))
            made.extend(_garments_drawn(scene, garments, frame, offset))
        zmp = np.asarray(data.zmp, float)
        ok = np.isfinite(zmp).all(axis=1)
        if ok.sum() >= 2 and not shift.any():
            trace = np.column_stack((zmp[ok], np.full(ok.sum(), data.ground)))
            made.append(tube_object(scene, "zmp", np.stack((trace[:-1], trace[1:]), axis=1), ZMP, 0.006))
        points = np.concatenate(points) if points else np.zeros((1, 3))
        points = points[np.isfinite(points).all(axis=1)]
        extra = [(f"load: {' + '.join(f'{d.kg:g} kg' for d in loads)} (from frame {loads[0].frame:g})", LOAD)] \
            if loads else []
        extra += [(f"push: {p.text} at frame {p.frame:g}", PUSH) for p in pushes]
        extra += [("garment (simulated cloth)", GARMENT[:3] + (1.0,))] if garments else []
        staged = _stage(scene, data, points, along, view, resolution, title, extra)
        made.extend(staged)
        camera = staged[1]
        for text, dx, i in zip(texts, shift, index):  # "frame N" under each snapshot
            root = data.bones[i, 0, 0] + np.array([along[0], along[1], 0.0]) * dx
            root[:2] -= 1.3 * view + (root[:2] - points[:, :2].mean(axis=0)) @ view * view  # before the ground
            made.append(text_object(scene, text, camera, (root[0], root[1], data.ground - 0.1), LABEL, size))
        scene.world = world = bpy.data.worlds.new("HumanAnim picture")
        world.color = (1.0, 1.0, 1.0)
        scene.view_settings.view_transform = "Standard"  # colours as given, a white background
        scene.render.engine = "BLENDER_WORKBENCH"
        scene.render.resolution_x, scene.render.resolution_y = resolution
        scene.render.resolution_percentage = 100
        scene.render.image_settings.file_format = "PNG"
        scene.render.image_settings.color_mode = "RGB"
        scene.render.filepath = path
        shading = scene.display.shading
        shading.light, shading.color_type = "STUDIO", "OBJECT"
        scene.render.film_transparent = False
        bpy.ops.render.render(write_still=True, scene=scene.name)
    finally:
        for obj in made:
            datablock, kind = obj.data, {"CURVE": bpy.data.curves, "FONT": bpy.data.curves,
                                         "MESH": bpy.data.meshes, "CAMERA": bpy.data.cameras}.get(obj.type)
            bpy.data.objects.remove(obj)
            if datablock is not None and kind is not None and datablock.users == 0:
                kind.remove(datablock)
        if scene.world is not None:
            bpy.data.worlds.remove(scene.world)
        bpy.data.scenes.remove(scene)
    return frames


def _label_size(data, xs, aspect):
    """The frame labels' text size: a fixed share of the picture's width, as _stage sizes it."""
    height = np.nanmax(data.bones[..., 2]) - data.ground
    return 0.016 * _picture_width(np.ptp(xs) + 0.6, height, aspect)


def _picture_width(span, height, aspect):
    return max(span * 1.45 + 0.4, (height + 0.5) * aspect)


def _loads_drawn(scene, data, loads, frame, i, offset):
    """A weight hanging 12 cm below each loaded hand, from the frame it is picked up."""
    made = []
    for load in loads:
        if frame < load.frame:
            continue
        wrist = data.bones[i, load.bone, 1] + offset
        weight = wrist - np.array([0.0, 0.0, 0.12])
        made.append(tube_object(scene, f"load{load.bone}.{frame:g}", [(wrist, weight)], LOAD, 0.006))
        radius = 0.035 * (load.kg / 5.0) ** (1 / 3)
        made.append(tube_object(scene, f"weight{load.bone}.{frame:g}",
                                 [(weight - [0, 0, radius], weight + [0, 0, radius])], LOAD, radius))
    return made


def _pushes_drawn(scene, data, pushes, frame, i, offset, points):
    """An arrow 40 cm long ending where each push acts, on the snapshot of its frame."""
    made = []
    for push in pushes:
        if push.frame != frame:
            continue
        tip = data.bones[i, push.bone, 0] + push.point + offset
        tail = tip - 0.4 * push.direction
        side = np.cross(push.direction, [0.0, 0.0, 1.0])
        side = side / np.linalg.norm(side) if np.linalg.norm(side) > 1e-6 else np.array([1.0, 0.0, 0.0])
        up = np.cross(side, push.direction)
        head = [(tip, tip - 0.08 * push.direction + 0.04 * s) for s in (side, -side, up, -up)]
        made.append(tube_object(scene, f"push{push.bone}.{frame:g}", [(tail, tip)] + head, PUSH, 0.012))
        points.append(np.array([tail]))
    return made


def _garments_drawn(scene, garments, frame, offset):
    """A copy of each garment's evaluated mesh at `frame` (its Mesh Cache played), moved by `offset`."""
    made = []
    for source_scene, obj in garments:
        source_scene.frame_set(int(round(frame)))
        made.append(mesh_copy(scene, obj, offset, GARMENT, f"HumanAnim garment {frame:g}"))
    return made


def mesh_copy(scene, obj, offset, colour, name):
    """A new object in `scene` with the mesh of `obj` as Blender evaluates it now (modifiers, Mesh
    Cache), in world space, moved by `offset`."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    mesh = bpy.data.meshes.new_from_object(obj.evaluated_get(depsgraph))
    mesh.transform(obj.matrix_world)
    copy = bpy.data.objects.new(name, mesh)
    copy.location = offset
    copy.color = colour
    scene.collection.objects.link(copy)
    return copy


def _picture_axes(data, roots):
    """Horizontal unit vectors: `along` the picture (the travel, or the widest spread of the
    body), and the `view` direction (the camera looks along it, from the figure's side)."""
    travel = roots[-1, :2] - roots[0, :2]
    if np.linalg.norm(travel) < 0.3 and getattr(data, "forward", None) is not None:
        travel = np.asarray(data.forward, float)  # in place: from the side, facing right
    elif np.linalg.norm(travel) < 0.3:  # in place: the widest horizontal spread of the bones
        pts = data.bones[:, :, :, :2].reshape(-1, 2)
        pts = pts[np.isfinite(pts).all(axis=1)]
        travel = np.linalg.svd(pts - pts.mean(axis=0), full_matrices=False)[2][0] if len(pts) > 2 else np.ones(2)
    travel = travel / np.linalg.norm(travel)
    return travel, np.array([-travel[1], travel[0]])  # camera on the right of the travel, looking left


def text_object(scene, text, camera, location, colour, size):
    """A line of text at `location`, facing the camera."""
    from mathutils import Matrix, Vector
    curve = bpy.data.curves.new(f"HumanAnim {text}", type="FONT")
    curve.body, curve.size, curve.align_x = text, size, "CENTER"
    obj = bpy.data.objects.new(f"HumanAnim {text}", curve)
    obj.color = colour
    obj.matrix_world = Matrix.Translation(Vector(location)) @ camera.matrix_world.to_3x3().normalized().to_4x4()
    scene.collection.objects.link(obj)
    return obj


def tube_object(scene, name, segments, colour, radius):
    """A curve object of round tubes along `segments` ((n, 2, 3) world points)."""
    curve = bpy.data.curves.new(f"HumanAnim {name}", type="CURVE")
    curve.dimensions = "3D"
    curve.bevel_depth = radius
    curve.bevel_resolution = 2
    for a, b in np.asarray(segments, float):
        spline = curve.splines.new("POLY")
        spline.points.add(1)
        spline.points[0].co = (*a, 1.0)
        spline.points[1].co = (*b, 1.0)
    obj = bpy.data.objects.new(f"HumanAnim {name}", curve)
    obj.color = colour
    scene.collection.objects.link(obj)
    return obj


def _stage(scene, data, points, along, view, resolution, title, extra=()):
    """Ground, an orthographic camera from the side, a legend."""
    from mathutils import Matrix, Vector
    made = []
    lo, hi = points.min(axis=0), points.max(axis=0)
    centre = (lo + hi) / 2
    xs = points[:, :2] @ along
    aspect = resolution[0] / resolution[1]
    width = _picture_width(np.ptp(xs), hi[2] - data.ground, aspect)
    mesh = bpy.data.meshes.new("HumanAnim ground")
    h = data.ground - 0.003
    a, v = np.array([*along, 0.0]) * width, np.array([*view, 0.0]) * 1.0  # a band under the figures
    corners = [centre + sa * a + sv * v for sa, sv in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
    mesh.from_pydata([(c[0], c[1], h) for c in corners], [], [(0, 1, 2, 3)])
    ground = bpy.data.objects.new("HumanAnim ground", mesh)
    ground.color = (0.93, 0.93, 0.9, 1.0)
    scene.collection.objects.link(ground)
    made.append(ground)
    camera = bpy.data.objects.new("HumanAnim camera", bpy.data.cameras.new("HumanAnim camera"))
    camera.data.type = "ORTHO"
    camera.data.ortho_scale = width
    camera.data.clip_end = 200.0
    height = data.ground + width / aspect * 0.36
    # shift the figures right of the legend
    target = Vector((centre[0], centre[1], height)) - Vector((along[0], along[1], 0.0)) * (0.16 * width)
    eye = target - Vector((view[0], view[1], 0.0)) * 20.0 + Vector((0.0, 0.0, 3.0))
    rotation = (target - eye).to_track_quat("-Z", "Y")
    camera.matrix_world = Matrix.Translation(eye) @ rotation.to_matrix().to_4x4()
    scene.collection.objects.link(camera)
    scene.camera = camera
    made.append(camera)
    up, right = rotation @ Vector((0, 1, 0)), rotation @ Vector((1, 0, 0))
    top_left = target + up * (width / aspect / 2 * 0.86) - right * (width / 2 * 0.97)
    entries = [(title, (0.1, 0.1, 0.1, 1.0))] if title else []
    entries += [("input motion (ghost)", PICTURE_COLOURS[GHOST]), ("no control", PICTURE_COLOURS[FREE]),
                ("stressed joint", STRESS), ("comfort control", KIND_COLOURS[2]),
                ("balance control", KIND_COLOURS[3]), ("passive control", KIND_COLOURS[1]),
                ("support polygon", POLYGON), ("ZMP (magenta: falling)", ZMP), *extra]
    line = width * 0.02
    for k, (text, colour) in enumerate(entries):
        curve = bpy.data.curves.new(f"HumanAnim legend {k}", type="FONT")
        curve.body = text
        curve.size = line
        obj = bpy.data.objects.new(f"HumanAnim legend {k}", curve)
        obj.color = colour
        obj.matrix_world = (Matrix.Translation(top_left - up * line * 1.35 * k - eye.normalized() * 0.0)
                            @ rotation.to_matrix().to_4x4())
        scene.collection.objects.link(obj)
        made.append(obj)
    return made


# ---- the draw handler ----------------------------------------------------------------------------

_OVERLAY = ViewOverlay(_draw)
is_enabled, enable, disable = _OVERLAY.is_enabled, _OVERLAY.enable, _OVERLAY.disable
register, unregister = enable, disable
