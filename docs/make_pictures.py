"""The manual's pictures, rendered from real runs of HumanAnim's own commands.

    .venv/bpy50/bin/python docs/make_pictures.py            # every picture into docs/pictures/
    .venv/bpy50/bin/python docs/make_pictures.py grasp walk  # only these

Each picture runs the batch command a user would (`python -m humananim demo`, `grasp`, `walk`,
`simulate`, `compress`, `cleanup`, `retarget`), opens the .blend it wrote and renders the result with Workbench in a
temporary scene (the bpy module renders headless with Workbench only): armatures as sticks
along their deform bones, meshes (capsule bodies, garments, props) as Blender evaluates them at
each frame. The dynamic-control picture is the demo's own (humananim_addon/motion_control/overlay.py).
The Motion QA panel's picture is the rows its draw() lays out for a real `control` run, drawn as
HTML in the sidebar's colours and shot with headless Chromium (not a screenshot of Blender); the
add-on preferences' picture is their own draw() drawn the same way.
Pictures are posterised before saving so each stays small enough to check in (< 150 KB)."""

import argparse
import contextlib
import io
import json
import os
import shutil
import subprocess
import sys
import tempfile
import types
from html import escape

os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="humananim-pictures-"))

import bpy  # noqa: E402
import numpy as np  # noqa: E402
from mathutils import Matrix, Vector  # noqa: E402

from humananim.humananim_addon import cli  # noqa: E402
from humananim.humananim_addon.motion_control import overlay  # noqa: E402
from humananim.humananim_addon.motion_control.overlay import text_object, tube_object  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
PICTURES = os.path.join(HERE, "pictures")
CLIP = os.path.join(HERE, "..", "humananim_addon", "data", "mocap", "cmu_131_01.bvh")
RESOLUTION = (1000, 420)
MAX_BYTES = 150_000

BONES = (0.2, 0.2, 0.22, 1.0)
GHOST = (0.72, 0.72, 0.72, 1.0)
BODY = (0.86, 0.72, 0.62, 1.0)
CLOTH = (0.25, 0.45, 0.95, 1.0)
PROP = (0.95, 0.55, 0.1, 1.0)
PATH = (0.1, 0.75, 0.75, 1.0)
PUSH = (0.95, 0.2, 0.05, 1.0)
INK = (0.1, 0.1, 0.1, 1.0)


# ---- running the commands ------------------------------------------------------------------------

def command(*argv):
    """Run `python -m humananim <argv> --json` in this process; its JSON summary."""
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        status = cli.main([*argv, "--json"])
    if status != 0:
        raise SystemExit(f"humananim {' '.join(argv)} failed with status {status}")
    return json.loads(out.getvalue())


def open_blend(path):
    with contextlib.redirect_stdout(io.StringIO()):
        bpy.ops.wm.open_mainfile(filepath=path)
    return bpy.context.scene


# ---- drawing what a scene shows at a frame -----------------------------------------------------------

def stick_segments(arm, skip=()):
    """World (head, tail) of every deform bone of `arm` as Blender evaluates it now, leaving out
    bones under any of `skip` (e.g. the metarig's face)."""
    world = np.array(arm.matrix_world)
    segments = []
    for pb in arm.pose.bones:
        if not pb.bone.use_deform or any(p.name in skip for p in [pb.bone, *pb.bone.parent_recursive]):
            continue
        ends = np.array([[*pb.head, 1.0], [*pb.tail, 1.0]]) @ world.T
        segments.append(ends[:, :3])
    return np.array(segments)


def mesh_copy(picture, obj, offset, colour):
    """A copy of the evaluated mesh of `obj` in `picture`, and its world points."""
    copy = overlay.mesh_copy(picture, obj, offset, colour, f"picture {obj.name}")
    return copy, np.array([v.co for v in copy.data.vertices]) + offset


def snapshot(picture, scene, frame, offset, meshes=(), sticks=(), radius=0.012):
    """Copy what `scene` shows at `frame` into `picture`, moved by `offset`: meshes as
    (object, colour), armatures as (object, colour, skip). The world points drawn."""
    scene.frame_set(int(frame))
    offset = np.asarray(offset, float)
    points = []
    for obj, colour in meshes:
        _, pts = mesh_copy(picture, obj, offset, colour)
        points.append(pts)
    for arm, colour, skip in sticks:
        segments = stick_segments(arm, skip) + offset
        tube_object(picture, f"{arm.name} {frame}", segments, colour, radius)
        points.append(segments.reshape(-1, 3))
    return np.concatenate(points) if points else np.zeros((0, 3))


def render(picture, points, path, direction, title=None, labels=(), resolution=RESOLUTION, margin=1.12,
           up=(0.0, 0.0, 1.0)):
    """Frame every point with an orthographic camera looking along `direction`, add the title
    and the (text, world location) labels, render with Workbench, save small."""
    points = np.asarray(points, float)
    points = points[np.isfinite(points).all(axis=1)]
    direction = Vector(direction).normalized()
    rotation = direction.to_track_quat("-Z", "Y")
    right, upward = rotation @ Vector((1, 0, 0)), rotation @ Vector((0, 1, 0))
    xs, ys = points @ np.array(right), points @ np.array(upward)
    aspect = resolution[0] / resolution[1]
    top_room = 0.12 if title else 0.0
    height = (np.ptp(ys) + 0.15) * (1 + top_room)
    width = max(np.ptp(xs) + 0.2, height * aspect) * margin
    centre = np.array(right) * (xs.min() + xs.max()) / 2 + np.array(upward) * (
        (ys.min() + ys.max()) / 2 + top_room * height / 2)
    depth = points @ np.array(direction)
    eye = Vector(centre) + direction * (depth.min() - 20.0)
    camera = bpy.data.objects.new("picture camera", bpy.data.cameras.new("picture camera"))
    camera.data.type, camera.data.ortho_scale, camera.data.clip_end = "ORTHO", width, 200.0
    camera.matrix_world = Matrix.Translation(eye) @ rotation.to_matrix().to_4x4()
    picture.collection.objects.link(camera)
    picture.camera = camera
    size = width * 0.022
    if title:
        corner = Vector(centre) + upward * (width / aspect / 2 - 1.6 * size) - right * (width / 2 - size)
        obj = text_object(picture, title, camera, corner, INK, size)
        obj.data.align_x = "LEFT"
    for text, location in labels:
        text_object(picture, text, camera, location, INK, size * 0.8)
    picture.world = bpy.data.worlds.new("picture world")
    picture.world.color = (1.0, 1.0, 1.0)
    picture.view_settings.view_transform = "Standard"
    picture.render.engine = "BLENDER_WORKBENCH"
    picture.render.resolution_x, picture.render.resolution_y = resolution
    picture.render.resolution_percentage = 100
    picture.display.shading.light, picture.display.shading.color_type = "STUDIO", "OBJECT"
    picture.render.image_settings.file_format = "PNG"
    picture.render.image_settings.color_mode = "RGB"
    raw = os.path.join(tempfile.mkdtemp(prefix="humananim-picture-"), "raw.png")
    picture.render.filepath = raw
    with contextlib.redirect_stdout(io.StringIO()):
        bpy.ops.render.render(write_still=True, scene=picture.name)
    save_small(raw, path)


def save_small(source, path, levels=24):
    """`source` posterised to `levels` per channel (deflate then packs it well), as PNG at `path`;
    fewer levels while it is over MAX_BYTES."""
    image = bpy.data.images.load(source)
    w, h = image.size
    pixels = np.empty(w * h * 4, np.float32)
    image.pixels.foreach_get(pixels)
    scene = bpy.data.scenes.new("picture save")
    scene.view_settings.view_transform = "Standard"
    settings = scene.render.image_settings
    settings.file_format, settings.color_mode, settings.compression = "PNG", "RGB", 100
    try:
        while True:
            out = bpy.data.images.new("picture small", w, h)
            out.pixels.foreach_set(np.round(pixels * (levels - 1)) / (levels - 1))
            out.save_render(path, scene=scene)
            bpy.data.images.remove(out)
            if os.path.getsize(path) <= MAX_BYTES or levels <= 8:
                break
            levels -= 4
    finally:
        bpy.data.images.remove(image)
        bpy.data.scenes.remove(scene)
    print(f"wrote {os.path.relpath(path)} ({os.path.getsize(path) // 1000} KB)")


def ball(picture, name, centre, radius, colour):
    import bmesh
    mesh = bpy.data.meshes.new(name)
    shape = bmesh.new()
    bmesh.ops.create_uvsphere(shape, u_segments=24, v_segments=12, radius=radius)
    shape.to_mesh(mesh)
    shape.free()
    for polygon in mesh.polygons:
        polygon.use_smooth = True
    obj = bpy.data.objects.new(name, mesh)
    obj.location, obj.color = centre, colour
    picture.collection.objects.link(obj)
    return obj


def new_picture():
    return bpy.data.scenes.new("HumanAnim picture")


def ground(picture, points, colour=(0.9, 0.9, 0.88, 1.0), height=0.0, margin=0.6):
    lo, hi = points[:, :2].min(axis=0) - margin, points[:, :2].max(axis=0) + margin
    mesh = bpy.data.meshes.new("picture ground")
    mesh.from_pydata([(lo[0], lo[1], height), (hi[0], lo[1], height), (hi[0], hi[1], height), (lo[0], hi[1], height)],
                     [], [(0, 1, 2, 3)])
    obj = bpy.data.objects.new("picture ground", mesh)
    obj.color = colour
    picture.collection.objects.link(obj)


# ---- the pictures ---------------------------------------------------------------------------------

def picture_control(work):
    """The demo: dynamic control of the CMU walk with 5 kg per hand and a push, over its input, with the skirt."""
    out = os.path.join(work, "demo.blend")
    summary = command("demo", "--out", out)
    save_small(summary["picture"], os.path.join(PICTURES, "control.png"))
    return out


def picture_skirt(work, demo_blend=None):
    """The demo's skirts on their capsule bodies: the walk and the hop, side by side at three frames."""
    demo_blend = demo_blend or picture_control(work)
    scene = open_blend(demo_blend)
    picture = new_picture()
    points, labels = [], []
    frames = (1, 100, 200)
    for row, name in enumerate(("cmu_131_01", "cmu_131_03")):
        arm = bpy.data.objects[name]
        body, skirt = bpy.data.objects[f"{name}.body"], bpy.data.objects[f"{name}.skirt.cloth"]
        for k, frame in enumerate(frames):
            scene.frame_set(frame)
            root = np.array(arm.matrix_world @ arm.pose.bones[0].head)
            offset = np.array([0.9 * (k + 3 * row), 0.0, 0.0]) - [root[0], root[1], 0.0]
            pts = snapshot(picture, scene, frame, offset, meshes=[(body, BODY), (skirt, CLOTH)])
            points.append(pts)
            labels.append((f"{'walk' if row == 0 else 'hop'}, frame {frame}",
                           (0.9 * (k + 3 * row), 0.0, pts[:, 2].min() - 0.12)))
    points = np.concatenate(points)
    ground(picture, points, height=float(points[:, 2].min()) - 0.005)
    render(picture, np.vstack([points, [[p[0], p[1], p[2] - 0.1] for _, p in labels]]),
           os.path.join(PICTURES, "skirt.png"), (0.0, 1.0, 0.0),
           title="Cloth: the generated skirt on the walk and on the hop, each on a skinned capsule body",
           labels=labels)


def picture_grasp(work):
    """A grasp on Rigify's human metarig, close on the hand: reach, close, hold (the sticks are the
    deform bones of the upper body on the object's side)."""
    import addon_utils
    with contextlib.redirect_stdout(io.StringIO()):
        bpy.ops.wm.read_homefile(use_empty=True)
    addon_utils.enable("rigify", default_set=True)
    bpy.ops.object.armature_human_metarig_add()
    bpy.ops.object.mode_set(mode="OBJECT")
    bpy.ops.mesh.primitive_cylinder_add(radius=0.035, depth=0.12, location=(-0.25, -0.35, 1.15), vertices=48)
    bpy.context.active_object.name = "Mug"
    scene_path, out = os.path.join(work, "grasp_scene.blend"), os.path.join(work, "grasp.blend")
    bpy.ops.wm.save_as_mainfile(filepath=scene_path)
    summary = command("grasp", scene_path, "--object", "Mug", "--out", out)
    scene = open_blend(out)
    arm = next(o for o in bpy.data.objects if o.type == "ARMATURE")
    mug = bpy.data.objects["Mug"]
    start, grasped = int(summary["frames"][0]), int(summary["grasped_frame"])
    frames = (start, (start + grasped) // 2, grasped)
    picture = new_picture()
    points, labels = [], []
    for k, frame in enumerate(frames):
        offset = np.array([1.05 * k, 0.0, 0.0])
        scene.frame_set(frame)
        centre = np.array(mug.matrix_world.translation)
        segments = stick_segments(arm, ("face",))
        heads = segments[:, 0]
        near = (segments[:, :, 2].min(axis=1) > 1.0) & (heads[:, 0] * np.sign(centre[0]) > -0.05)  # the object's side, above the hips
        tube_object(picture, f"arm {frame}", segments[near] + offset, BONES, 0.006)
        _, mug_points = mesh_copy(picture, mug, offset, PROP)
        points += [segments[near].reshape(-1, 3) + offset, mug_points]
        labels.append((f"frame {frame}", centre + offset - [0.0, 0.0, 0.2]))
    render(picture, np.vstack(points + [np.array([p for _, p in labels])]), os.path.join(PICTURES, "grasp.png"),
           (0.0, 1.0, -0.3), title=f"Hands: a {summary['type'].lower()} grasp of a 7 cm cylinder on Rigify's "
                                   "metarig (reach, close, hold)", labels=labels)


def picture_walk(work):
    """Walk Along Path: the CMU rig walking an 8 m S curve, every second of the walk, seen from above."""
    out = os.path.join(work, "walk.blend")
    summary = command("walk", CLIP, "--s-curve", "8", "--speed", "1.3", "--style", "neutral", "--out", out)
    scene = open_blend(out)
    arm = bpy.data.objects[summary["armature"]]
    strips = [strip for track in arm.animation_data.nla_tracks for strip in track.strips]
    start, end = int(min(s.frame_start for s in strips)), int(max(s.frame_end for s in strips))
    picture = new_picture()
    frames = _evenly_along(scene, arm, start, end, 6)
    points = [snapshot(picture, scene, f, (0, 0, 0), sticks=[(arm, BONES, ())], radius=0.015) for f in frames]
    for obj in [o for o in scene.objects if o.type == "CURVE"]:  # the path
        depsgraph = bpy.context.evaluated_depsgraph_get()
        mesh = bpy.data.meshes.new_from_object(obj.evaluated_get(depsgraph))
        line = np.array([obj.matrix_world @ v.co for v in mesh.vertices])
        tube_object(picture, "path", np.stack((line[:-1], line[1:]), axis=1), PATH, 0.02)
        points.append(line)
    points = np.concatenate(points)
    ground(picture, points, height=float(points[:, 2].min()) - 0.005)
    labels = [(f"frame {f}", tuple(p)) for f, p in zip(frames, _roots(scene, arm, frames, lift=-0.0, side=0.45))]
    render(picture, np.vstack([points, [p for _, p in labels]]), os.path.join(PICTURES, "walk.png"),
           (0.35, 0.9, -0.75), title="Walking: a neutral walk along an 8 m S curve at "
                                       "1.3 m/s (the CMU rig), at equal distances along the way", labels=labels)


def picture_mass_model(work):
    """The mass model of the bundled CMU rig from de Leva's tables: a ball at each segment's
    centre of mass, its volume the segment's mass."""
    import humananim
    from humananim.humananim_addon.armature import skeleton_from_armature
    from humananim.humananim_addon.bvh_import import import_bvh
    with contextlib.redirect_stdout(io.StringIO()):
        bpy.ops.wm.read_homefile(use_empty=True)
    humananim.register()
    try:
        with contextlib.redirect_stdout(io.StringIO()):
            arm, _, _ = import_bvh(CLIP)
        scene = bpy.context.scene
        scene.frame_set(1)
        skeleton = skeleton_from_armature(arm, scene, 70.0)
        unit = scene.unit_settings.scale_length
        picture = new_picture()
        sticks = stick_segments(arm)
        tube_object(picture, "bones", sticks, BONES, 0.008)
        world = np.array(arm.matrix_world)
        balls = []
        for j, name in enumerate(skeleton.names):
            if skeleton.mass[j] <= 0:
                continue
            pb = arm.pose.bones[name]
            centre = world @ np.array(pb.matrix) @ np.append(skeleton.com[j] / unit, 1.0)
            radius = 0.05 * (skeleton.mass[j] / 10.0) ** (1 / 3)
            ball(picture, f"mass {name}", centre[:3], radius, PROP)
            balls.append(centre[:3])
        points = np.vstack([sticks.reshape(-1, 3), balls])
        render(picture, points, os.path.join(PICTURES, "mass_model.png"), (0.0, 1.0, 0.0), resolution=(700, 700),
               title=f"Mass model: {skeleton.mass.sum():.0f} kg in {int((skeleton.mass > 0).sum())} segments "
                     "(de Leva's tables)")
    finally:
        humananim.unregister()


def picture_simulate(work):
    """Simulate: the CMU walk followed physically with 8 kg in each hand and a 300 N push on the
    chest, the result (dark) over its input (grey)."""
    out = os.path.join(work, "simulate.blend")
    summary = command("simulate", CLIP, "--frames", "1", "240", "--load-left", "8", "--load-right", "8",
                      "--push", "120:Chest:0,300,0:0.1", "--out", out)
    scene = open_blend(out)
    arm = bpy.data.objects[summary["armature"]]
    source, result = bpy.data.actions[summary["source_action"]], bpy.data.actions[summary["action"]]
    _strip_of_two_actions(scene, arm, source, result, np.linspace(1, 240, 5).round().astype(int),
                          os.path.join(PICTURES, "simulate.png"),
                          "Simulation: the CMU walk, 8 kg per hand, 300 N on the chest at frame 120 (dark; input grey)")


def picture_synthesis(work):
    """The Motion Queue: two sections of the CMU walk joined by a connective step."""
    out = os.path.join(work, "synthesis.blend")
    summary = command("synthesize", CLIP, "--queue", "cmu_131_01@1-300", "--queue", "cmu_131_01@500-800:connect",
                      "--out", out)
    scene = open_blend(out)
    arm = next(o for o in scene.objects if o.type == "ARMATURE")
    action = bpy.data.actions[summary["action"]]
    arm.animation_data.action = action
    if hasattr(arm.animation_data, "action_slot") and action.slots:
        arm.animation_data.action_slot = action.slots[0]
    f0, f1 = (int(v) for v in action.frame_range)
    frames = np.linspace(f0, f1, 7).round().astype(int)
    _strip(scene, [(arm, BONES)], frames, os.path.join(PICTURES, "synthesis.png"),
           "Motion Queue: CMU 131_01 frames 1-300, then a connective step into frames 500-800")


def _strip_of_two_actions(scene, arm, ghost_action, action, frames, path, title):
    """Snapshots side by side of `arm` playing `ghost_action` (grey) and `action` (dark)."""
    picture = new_picture()
    points, labels = [], []
    ad = arm.animation_data
    for k, frame in enumerate(frames):
        scene.frame_set(int(frame))
        root = np.array(arm.matrix_world @ arm.pose.bones[0].head)
        offset = np.array([1.0 * k - root[0], -root[1], 0.0])
        for act, colour in ((ghost_action, GHOST), (action, BONES)):
            ad.action = act
            if hasattr(ad, "action_slot") and act.slots:
                ad.action_slot = act.slots[0]
            for track in ad.nla_tracks:
                track.mute = True
            pts = snapshot(picture, scene, frame, offset, sticks=[(arm, colour, ())], radius=0.012)
            points.append(pts)
        labels.append((f"frame {frame}", (1.0 * k, 0.0, float(pts[:, 2].min()) - 0.12)))
    points = np.concatenate(points)
    render(picture, np.vstack([points, [p for _, p in labels]]), path, (0.0, 1.0, 0.0), title=title, labels=labels)


def _strip(scene, sticks, frames, path, title, spacing=1.0, meshes=(), direction=(0.0, 1.0, 0.0)):
    """Snapshots side by side (moved back to x = k * spacing) of armatures as sticks and meshes."""
    picture = new_picture()
    points, labels = [], []
    anchor = sticks[0][0] if sticks else meshes[0][0]
    for k, frame in enumerate(frames):
        scene.frame_set(int(frame))
        centre = (np.array(anchor.matrix_world @ anchor.pose.bones[0].head) if anchor.type == "ARMATURE"
                  else np.array(anchor.matrix_world.translation))
        offset = np.array([spacing * k - centre[0], -centre[1], 0.0])
        pts = snapshot(picture, scene, frame, offset, meshes=meshes, sticks=[(a, c, ()) for a, c in sticks])
        points.append(pts)
        labels.append((f"frame {frame}", (spacing * k, 0.0, float(pts[:, 2].min()) - 0.12)))
    points = np.concatenate(points)
    render(picture, np.vstack([points, [p for _, p in labels]]), path, direction, title=title, labels=labels)


def picture_flexible(work):
    """The thesis's table (a lattice character) simulated by `flexible simulate --demo`."""
    out = os.path.join(work, "flexible.blend")
    command("flexible", "simulate", "--demo", "--out", out)
    scene = open_blend(out)
    mesh = next(o for o in scene.objects if o.type == "MESH" and any(m.type == "LATTICE" for m in o.modifiers))
    frames = np.linspace(scene.frame_start, scene.frame_end, 6).round().astype(int)
    size = max(mesh.dimensions)
    _strip(scene, [], frames, os.path.join(PICTURES, "flexible.png"),
           "Flexible Character: the thesis's table, a lattice character, under its PD controller",
           spacing=1.6 * size, meshes=[(mesh, BODY)], direction=(0.0, 1.0, -0.2))


def picture_sequence(work):
    """Compress Keys on the CMU walk: the left hip's X rotation sampled on every frame (grey), the
    Bezier keys that replace it (orange) and the curve they make (blue)."""
    from humananim.humananim_addon.action_api import fcurves_of
    out = os.path.join(work, "compressed.blend")
    summary = command("compress", CLIP, "--degrees", "1", "--cm", "1", "--out", out)
    scene = open_blend(out)
    arm = next(o for o in scene.objects if o.type == "ARMATURE")
    source, result = bpy.data.actions[summary["source_action"]], bpy.data.actions[summary["action"]]
    path = 'pose.bones["LeftHip"].rotation_euler'
    before = next(f for f in fcurves_of(source, arm) if f.data_path == path and f.array_index == 0)
    after = next(f for f in fcurves_of(result, arm) if f.data_path == path and f.array_index == 0)
    f0, f1 = 1, 400
    frames = np.arange(f0, f1 + 1)
    sx, sz = 8.0 / (f1 - f0), 1.5  # metres per frame and per radian in the picture
    def line(values, y=0.0):  # y < 0: in front
        pts = np.column_stack((frames * sx, np.full(len(frames), y), np.asarray(values) * sz))
        return np.stack((pts[:-1], pts[1:]), axis=1)
    picture = new_picture()
    raw = line([before.evaluate(f) for f in frames])
    tube_object(picture, "source", raw, GHOST, 0.03)
    tube_object(picture, "compressed", line([after.evaluate(f) for f in frames], -0.2), CLOTH, 0.012)
    keys = np.array([k.co for k in after.keyframe_points if f0 <= k.co[0] <= f1])
    for t, v in keys:
        ball(picture, f"key {t}", (t * sx, -0.3, v * sz), 0.05, PROP)
    total_before = sum(len(f.keyframe_points) for f in fcurves_of(source, arm))
    total_after = sum(len(f.keyframe_points) for f in fcurves_of(result, arm))
    render(picture, np.vstack([raw.reshape(-1, 3), [(4.0, 0.0, raw[:, :, 2].min() - 0.35)]]),
           os.path.join(PICTURES, "sequence.png"), (0.0, 1.0, 0.0),
           title=f"Compress Keys, 1 deg / 1 cm: left hip X rotation, frames {f0}-{f1} (grey), {len(keys)} keys (orange)",
           labels=[(f"the whole clip: {total_before:,} keys -> {total_after:,}", (4.0, 0.0, raw[:, :, 2].min() - 0.3))])


def picture_capture(work):
    """Live Capture: a take recorded from a replayed BVH device, as the rig followed it."""
    out = os.path.join(work, "capture.blend")
    summary = command("capture", CLIP, "--replay", CLIP, "--seconds", "3", "--out", out)
    scene = open_blend(out)
    arm = bpy.data.objects[summary["armature"]] if summary.get("armature") in bpy.data.objects else next(
        o for o in scene.objects if o.type == "ARMATURE")
    action = arm.animation_data.action
    f0, f1 = (int(v) for v in action.frame_range)
    _strip(scene, [(arm, BONES)], np.linspace(f0, f1, 6).round().astype(int), os.path.join(PICTURES, "capture.png"),
           f"Live Capture: a 3 s take recorded from a replayed BVH device ('{action.name}')")



def picture_cleanup(work):
    """Clean Up Capture on the CMU walk: each toe's lowest point over the frames, the capture (grey)
    and the cleaned action (blue; left above, right below), height drawn 6 times its scale, the
    floor (black) and the contacts the clean-up found (orange)."""
    out = os.path.join(work, "cleanup.blend")
    summary = command("cleanup", CLIP, "--out", out)
    scene = open_blend(out)
    arm = bpy.data.objects[summary["armature"]]
    source, result = bpy.data.actions[summary["source_action"]], bpy.data.actions[summary["action"]]
    repairs = {r["repair"]: r for r in summary["report"]["repairs"]}
    f0, f1 = 1, 600
    frames = np.arange(f0, f1 + 1, 2)
    sx, sz = 9.0 / (f1 - f0), 6.0  # metres per frame; the height drawn 6 times
    ground_m = float(summary["report"].get("ground_m", 0.0))
    rows = {"L": ("LeftToe", 2.0), "R": ("RightToe", 0.0)}  # each foot's row, lifted by its offset
    lows = {}
    ad = arm.animation_data
    for act in (source, result):
        ad.action = act
        if hasattr(ad, "action_slot") and act.slots:
            ad.action_slot = act.slots[0]
        for side in rows:
            lows[act.name, side] = []
        for f in frames:
            scene.frame_set(int(f))
            for side, (bone, _) in rows.items():
                pb = arm.pose.bones[bone]
                lows[act.name, side].append(min((arm.matrix_world @ pb.head).z, (arm.matrix_world @ pb.tail).z))
    picture = new_picture()
    points, labels = [], []
    def line(values, lift, y):
        pts = np.column_stack((frames * sx, np.full(len(frames), y), (np.asarray(values) - ground_m) * sz + lift))
        return np.stack((pts[:-1], pts[1:]), axis=1)
    for side, (bone, lift) in rows.items():
        before = line(lows[source.name, side], lift, 0.0)
        tube_object(picture, f"capture {side}", before, GHOST, 0.03)
        tube_object(picture, f"clean {side}", line(lows[result.name, side], lift, -0.2), CLOTH, 0.015)
        floor = np.array([[[f0 * sx, -0.3, lift], [f1 * sx, -0.3, lift]]])
        tube_object(picture, f"floor {side}", floor, INK, 0.006)
        for a, b in repairs["skate"]["contacts"][side]:
            a, b = max(a, f0), min(b, f1)
            if a < b:
                tube_object(picture, f"contact {side} {a}", np.array([[[a * sx, -0.4, lift - 0.12],
                                                                         [b * sx, -0.4, lift - 0.12]]]), PROP, 0.025)
        points += [before.reshape(-1, 3), floor.reshape(-1, 3)]
        labels.append((f"{bone}", (f0 * sx - 0.55, 0.0, lift + 0.3)))
    labels.append((f"frame {f0}", (f0 * sx, 0.0, -0.35)))
    labels.append((f"frame {f1}", (f1 * sx, 0.0, -0.35)))
    lowest = [0.0 + round(100 * (min(min(lows[a.name, side]) for side in rows) - ground_m), 1) for a in (source, result)]
    labels.append((f"lowest toe point {lowest[0]:+.1f} cm in the capture, {lowest[1]:+.1f} cm cleaned",
                   ((f0 + f1) / 2 * sx, 0.0, -0.35)))
    render(picture, np.vstack(points + [np.array([p for _, p in labels])]), os.path.join(PICTURES, "cleanup.png"),
           (0.0, 1.0, 0.0),
           title=f"Clean Up Capture, CMU 131_01: toe heights x{sz:.0f}, capture grey, cleaned blue, "
                 "contacts found orange",
           labels=labels)


def picture_retarget(work):
    """Retarget Motion: the CMU walk (grey, the source as imported) put on the tests' procedural
    control rig 'Puppet' (dark: its deform bones as the rig evaluates its keyed controls), side by
    side at five frames."""
    sys.path.insert(0, os.path.join(HERE, "..", "tests", "addon"))
    from control_rig import build_control_rig
    with contextlib.redirect_stdout(io.StringIO()):
        bpy.ops.wm.read_homefile(use_empty=True)
    build_control_rig()
    scene_path, out = os.path.join(work, "rig.blend"), os.path.join(work, "retarget.blend")
    bpy.ops.wm.save_as_mainfile(filepath=scene_path)
    f0, f1 = 1, 240
    summary = command("retarget", CLIP, "--to", scene_path, "--armature", "Puppet", "--frames", str(f0), str(f1),
                      "--out", out)
    scene = open_blend(out)
    source, target = bpy.data.objects[summary["source"]], bpy.data.objects[summary["armature"]]
    frames = np.linspace(f0, f1, 5).round().astype(int)
    picture = new_picture()
    points, labels = [], []
    for k, frame in enumerate(frames):
        scene.frame_set(int(frame))
        for arm, colour, x in ((source, GHOST, 2.0 * k), (target, BONES, 2.0 * k + 0.8)):
            root = np.array(arm.matrix_world @ next(pb for pb in arm.pose.bones if pb.bone.use_deform).head)
            pts = snapshot(picture, scene, frame, np.array([x - root[0], -root[1], 0.0]), sticks=[(arm, colour, ())])
            points.append(pts)
        labels.append((f"frame {frame}", (2.0 * k + 0.4, 0.0, float(pts[:, 2].min()) - 0.12)))
    points = np.concatenate(points)
    render(picture, np.vstack([points, [p for _, p in labels]]), os.path.join(PICTURES, "retarget.png"),
           (0.6, 1.0, -0.1), labels=labels,
           title=f"Retarget Motion: the CMU walk (grey) on a procedural control rig (dark), "
                 f"{summary['roles_mapped']} roles, {summary['controls_keyed']} controls keyed")


def _evenly_along(scene, arm, start, end, count):
    """`count` frames at equal distances along the root's way (standing still counts once)."""
    sampled = np.arange(start, end + 1, 5)
    roots = np.array(_roots(scene, arm, sampled, side=0.0))[:, :2]
    way = np.concatenate(([0.0], np.cumsum(np.linalg.norm(np.diff(roots, axis=0), axis=1))))
    targets = np.linspace(0.0, way[-1], count)
    return [int(sampled[min(np.searchsorted(way, t), len(sampled) - 1)]) for t in targets]


def _roots(scene, arm, frames, lift=0.0, side=0.4):
    out = []
    for f in frames:
        scene.frame_set(int(f))
        head = arm.matrix_world @ arm.pose.bones[0].head
        out.append((head.x, head.y - side, lift))
    return out


# ---- the Motion QA panel, drawn from its own draw() ---------------------------------------------

ICONS = {"INFO": "&#9432;", "ACTION": "&#9656;", "ERROR": "&#9888;", "CHECKMARK": "&#10003;", "TIME": "&#9719;"}


class PanelRows:
    """Stands in for Blender's UILayout while a panel's draw() runs: records each row's labels and
    buttons and whether the row is drawn red (`alert`), in the order draw() lays them out."""

    def __init__(self, rows, single=False):
        self.rows, self.items, self.alert = rows, [], False
        if single:
            rows.append(self)

    def column(self, **_):
        return PanelRows(self.rows)

    def row(self, **_):
        return PanelRows(self.rows, single=True)

    def label(self, text="", icon="NONE", **_):
        target = self if self in self.rows else self.row()
        target.items.append(("label", text, icon))

    def prop(self, data, name, text=None, **_):
        """A property as Blender draws it in a row: its name, then its value (an enum's item name)."""
        target = self if self in self.rows else self.row()
        rna = data.bl_rna.properties[name]
        value = getattr(data, name)
        shown = rna.enum_items[value].name if rna.type == "ENUM" else str(value)
        target.items.append(("label", rna.name if text is None else text, "NONE"))
        target.items.append(("button", f"{shown} \u25be" if rna.type == "ENUM" else shown, "NONE"))

    def operator(self, idname, text="", icon="NONE", **_):
        target = self if self in self.rows else self.row()
        target.items.append(("button", text, icon))
        return None  # the panel sets no property on a recorded button


def panel_html(title, rows, width=500):
    """The recorded rows as a small page in Blender's sidebar colours (dark theme)."""
    lines = []
    for r in rows:
        cells = []
        for kind, text, icon in r.items:
            glyph = f'<span class="icon">{ICONS.get(icon, "")}</span>' if icon in ICONS else ""
            cls = "button" if kind == "button" else "label"
            cells.append(f'<span class="{cls}">{glyph}{escape(text)}</span>')
        lines.append(f'<div class="row{" alert" if r.alert else ""}">{"".join(cells)}</div>')
    height = 34 + 25 * len(rows) + 12
    page = f"""<!doctype html><html><head><meta charset="utf-8"><style>
body {{ margin: 0; background: #1d1d1d; font: 12px "DejaVu Sans", sans-serif; color: #e6e6e6; }}
.panel {{ width: {width - 12}px; margin: 6px; background: #303030; border-radius: 4px; overflow: hidden; }}
.header {{ background: #3d3d3d; padding: 7px 10px; font-weight: bold; }}
.body {{ padding: 6px 8px 8px; }}
.row {{ display: flex; align-items: center; height: 21px; margin: 2px 0; padding: 0 4px; border-radius: 3px; }}
.row.alert {{ background: #6e2a2a; }}
.label {{ flex: 1; white-space: nowrap; overflow: hidden; text-overflow: ellipsis; }}
.button {{ background: #545454; border-radius: 3px; padding: 2px 8px; margin-left: 6px; }}
.alert .button {{ background: #a03a3a; }}
.icon {{ display: inline-block; width: 16px; color: #bdbdbd; }}
</style></head><body><div class="panel"><div class="header">&#9662; {escape(title)}</div>
<div class="body">{"".join(lines)}</div></div></body></html>"""
    return page, (width, height)


def picture_qa(work):
    """The Motion QA panel after Dynamic Control of the CMU walk with 5 kg in each hand and a push
    on the chest at frame 120 (a run whose QA fails: the push jerks the collar): the rows the panel's own draw() lays out for the report stored on the armature,
    drawn as HTML in the sidebar's colours and shot with headless Chromium. Not a screenshot of
    Blender: the bpy module cannot draw its UI headless."""
    from humananim.panels.qa import VIEW3D_PT_humananim_qa
    out = os.path.join(work, "qa.blend")
    summary = command("control", CLIP, "--frames", "1", "240", "--load-left", "5", "--load-right", "5",
                      "--impulse", "120:Chest:0,60,0", "--out", out)
    open_blend(out)
    arm = bpy.data.objects[summary["armature"]]
    rows = []
    panel = types.SimpleNamespace(layout=PanelRows(rows))
    VIEW3D_PT_humananim_qa.draw(panel, types.SimpleNamespace(active_object=arm))
    shoot_panel(work, "qa", VIEW3D_PT_humananim_qa.bl_label, rows)


def shoot_panel(work, name, title, rows, width=500):
    """The recorded `rows` drawn by panel_html, shot with headless Chromium, saved small as
    docs/pictures/<name>.png."""
    page, (w, h) = panel_html(title, rows, width)
    html_path, raw = os.path.join(work, f"{name}.html"), os.path.join(work, f"{name}-raw.png")
    with open(html_path, "w", encoding="utf-8") as f:
        f.write(page)
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        raise SystemExit("a panel's picture needs chromium (Debian's package, as the batch report's test)")
    subprocess.run([chromium, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
                    f"--user-data-dir={os.path.join(work, 'chromium')}", f"--screenshot={raw}",
                    f"--window-size={w},{h}", "file://" + html_path],
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=120, check=True)
    save_small(raw, os.path.join(PICTURES, f"{name}.png"))


def picture_preferences(work):
    """HumanAnim's add-on preferences as the add-on's own draw() lays them out, with the add-on
    enabled in a fresh session (its defaults), drawn like the QA panel (HTML, headless Chromium)."""
    import addon_utils
    module = addon_utils.enable("humananim", default_set=True)
    if module is None:
        raise SystemExit("could not enable the humananim add-on")
    prefs = bpy.context.preferences.addons["humananim"].preferences
    rows = []
    layout = PanelRows(rows)
    type(prefs).draw(types.SimpleNamespace(layout=layout, log_level=prefs.log_level, bl_rna=prefs.bl_rna),
                     bpy.context)
    shoot_panel(work, "preferences", "HumanAnim (Preferences > Add-ons)", rows)


PICTURES_MADE = {"control": picture_control, "skirt": picture_skirt, "grasp": picture_grasp, "walk": picture_walk,
                 "mass_model": picture_mass_model, "simulate": picture_simulate, "sequence": picture_sequence,
                 "flexible": picture_flexible, "synthesis": picture_synthesis, "capture": picture_capture,
                 "qa": picture_qa, "preferences": picture_preferences,
                 "cleanup": picture_cleanup, "retarget": picture_retarget}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("names", nargs="*", help=f"pictures to make: {', '.join(PICTURES_MADE)} (default: all)")
    parser.add_argument("--keep", metavar="DIR", help="keep the runs' .blend files in DIR")
    args = parser.parse_args(argv)
    unknown = set(args.names) - set(PICTURES_MADE)
    if unknown:
        parser.error(f"no picture named {', '.join(sorted(unknown))}")
    os.makedirs(PICTURES, exist_ok=True)
    work = args.keep or tempfile.mkdtemp(prefix="humananim-pictures-")
    os.makedirs(work, exist_ok=True)
    try:
        names = args.names or list(PICTURES_MADE)
        demo = None
        for name in names:
            if name == "control":
                demo = picture_control(work)
            elif name == "skirt":
                picture_skirt(work, demo)
            else:
                PICTURES_MADE[name](work)
    finally:
        if not args.keep:
            shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    status = main()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(status)  # the bpy module can hang in its teardown after these scenes; nothing is left to save
