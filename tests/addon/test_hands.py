"""Hands in Blender on the Rigify human metarig: grasp a cylinder, a sphere and a box (fingers
touch the surface, none inside beyond 1 mm, keys in a new action, Child Of keyed, the source
untouched), release, follow, hold, self-collisions, and the grasp command."""

import json
import os

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from conftest import fcurve_snapshot  # noqa: E402
from humananim.humananim_addon import action_api  # noqa: E402
from humananim.humananim_addon.hands import job as hands  # noqa: E402
from humananim.humananim_addon.armature import armature_to_world, skeleton_from_armature  # noqa: E402
from humananim.solver.hands.sensors import default_hand_sensors, sensor_centres  # noqa: E402


def add_object(kind, location, size):
    if kind == "CYLINDER":
        bpy.ops.mesh.primitive_cylinder_add(radius=size / 2, depth=size * 2.5, location=location, vertices=48)
    elif kind == "SPHERE":
        bpy.ops.mesh.primitive_uv_sphere_add(radius=size / 2, location=location, segments=48, ring_count=24)
    else:
        bpy.ops.mesh.primitive_cube_add(size=1.0, location=location)
        bpy.context.active_object.scale = (size / 2, size * 0.75, size)
        bpy.ops.object.transform_apply(location=False, rotation=False, scale=True)
    return bpy.context.active_object


def select(rig, target):
    bpy.ops.object.select_all(action="DESELECT")
    target.select_set(True)
    rig.select_set(True)
    bpy.context.view_layer.objects.active = rig


def finger_distances(rig, scene, target, side, frame):
    """Blender's own evaluated pose at `frame`: each hand sensor's gap to the object's mesh
    primitive (negative inside)."""
    scene.frame_set(frame)
    bpy.context.view_layer.update()
    sk = skeleton_from_armature(rig, scene)
    basis = hands.pose_frames(rig, scene, sk, [frame])[0]
    world = sk.world_frames(basis, armature_to_world(rig, scene))
    con = target.constraints.get(hands.CONSTRAINT)
    con.mute = True
    shape = hands.object_shape(target, scene)
    con.mute = False
    sens = default_hand_sensors(sk, side)
    gap = shape.distance(sensor_centres(sens, world, sk)) - np.array([s.radius for s in sens])
    return {s.name: float(g) for s, g in zip(sens, gap)}


@pytest.mark.parametrize("kind,size", [("CYLINDER", 0.05), ("SPHERE", 0.08), ("BOX", 0.04)])
def test_grasp_selected_object(metarig, kind, size):
    scene = bpy.context.scene
    rig = metarig
    target = add_object(kind, (-0.25, -0.35, 1.15), size)
    before_objects = set(bpy.data.actions)
    select(rig, target)
    scene.humananim_hands.release_frame = 60
    assert bpy.ops.humananim.grasp() == {"FINISHED"}
    new = set(bpy.data.actions) - before_objects
    action = rig.animation_data.action
    assert action in new and action.name.startswith(target.name)
    assert len(action_api.fcurves_of(action, rig)) > 0
    con = target.constraints[hands.CONSTRAINT]
    assert con.type == "CHILD_OF" and con.target == rig and con.subtarget in ("hand.L", "hand.R")
    side = con.subtarget[-1]
    fc = [f for f in action_api.fcurves_of(target.animation_data.action, target)
          if f.data_path.endswith("influence")][0]
    keys = sorted((k.co[0], k.co[1]) for k in fc.keyframe_points)
    grasped = [f for f, v in keys if v == 1.0][0]
    assert fc.evaluate(grasped - 1) == 0.0 and fc.evaluate(grasped) == 1.0 and fc.evaluate(59) == 1.0
    assert fc.evaluate(60) == 0.0
    # the fingers touch the mesh's primitive at the grasp frame, none inside beyond 1 mm
    gaps = finger_distances(rig, scene, target, side, int(grasped))
    assert min(gaps.values()) > -0.001
    touching = {k.split(".")[0] for k, g in gaps.items() if g < 0.002}
    assert "thumb" in touching and touching & {"index", "middle"}
    # held: the object moves with the hand after the grasp (its world place follows the bone)
    scene.frame_set(int(grasped))
    m0 = np.array(target.matrix_world)
    assert np.allclose(m0[:3, 3], (-0.25, -0.35, 1.15), atol=0.002)  # did not jump when taken


def test_pattern_from_a_pose_action(metarig):
    """A hand pattern from the animator's pose library (an action; its first frame is the pose):
    during the closing each finger bone of the grasping hand turns from where the reach left it
    toward the pattern's rotation (a share of the way, stopped at a touch), not toward the
    built-in pattern's; the pattern action is left as it was."""
    from mathutils import Quaternion
    scene = bpy.context.scene
    rig = metarig
    fingers = [b for b in rig.pose.bones if b.name.startswith(("thumb.", "f_")) and b.name.endswith(".R")]
    start = {b.name: b.matrix_basis.to_quaternion() for b in fingers}
    for b in fingers:  # the pose: every finger bone curled 70 deg about its X axis
        b.rotation_mode = "QUATERNION"
        b.rotation_quaternion = Quaternion((1.0, 0.0, 0.0), np.radians(70.0))
        b.keyframe_insert("rotation_quaternion", frame=1)
    pose = rig.animation_data.action
    pose.name = "Curled"
    pattern = {b.name: b.rotation_quaternion.copy() for b in fingers}
    snap = fcurve_snapshot(pose, rig)
    rig.animation_data.action = None
    for b in fingers:
        b.rotation_quaternion = start[b.name]
    target = add_object("CYLINDER", (-0.25, -0.35, 1.15), 0.05)
    select(rig, target)
    scene.humananim_hands.side = "R"
    scene.humananim_hands.pattern = pose
    assert bpy.ops.humananim.grasp() == {"FINISHED"}
    props = scene.humananim_hands
    reached = props.start_frame + int(round(props.duration * scene.render.fps))
    scene.frame_set(reached)
    start = {b.name: b.matrix_basis.to_quaternion() for b in fingers}  # the closing starts here
    scene.frame_set(reached + int(round(props.close_duration * scene.render.fps)))
    closed = 0
    for b in fingers:
        final = b.matrix_basis.to_quaternion()
        way = start[b.name].rotation_difference(pattern[b.name]).angle
        done, left = start[b.name].rotation_difference(final).angle, final.rotation_difference(pattern[b.name]).angle
        assert done + left == pytest.approx(way, abs=2e-3), b.name  # on its way to the pattern
        closed += done > 0.5 * way
    assert closed >= 3  # fingers that touch nothing go (more than half) toward the pattern
    after = fcurve_snapshot(pose, rig)
    assert after.keys() == snap.keys() and all(np.array_equal(after[k], snap[k]) for k in snap)


def test_source_action_untouched_and_new_action(metarig):
    rig = metarig
    # a source action: a small keyed pose
    rig.pose.bones["spine.003"].rotation_mode = "QUATERNION"
    rig.pose.bones["spine.003"].keyframe_insert("rotation_quaternion", frame=1)
    rig.pose.bones["spine.003"].keyframe_insert("rotation_quaternion", frame=40)
    src = rig.animation_data.action
    snap = fcurve_snapshot(src, rig)
    target = add_object("CYLINDER", (-0.25, -0.35, 1.15), 0.05)
    select(rig, target)
    assert bpy.ops.humananim.grasp() == {"FINISHED"}
    assert rig.animation_data.action != src
    after = fcurve_snapshot(src, rig)
    assert after.keys() == snap.keys() and all(np.array_equal(after[k], snap[k]) for k in snap)
    assert src.use_fake_user


def test_release_follow_hold_and_self_collisions(metarig):
    scene = bpy.context.scene
    rig = metarig
    target = add_object("CYLINDER", (-0.25, -0.35, 1.15), 0.04)
    select(rig, target)
    props = scene.humananim_hands
    props.grasp_type = "WRAP"
    assert bpy.ops.humananim.grasp() == {"FINISHED"}
    grasp_action = rig.animation_data.action
    # the object leads: keyed motion of its own
    target.location = (-0.25, -0.35, 1.15)
    target.keyframe_insert("location", frame=40)
    target.location = (-0.2, -0.4, 1.25)
    target.keyframe_insert("location", frame=60)
    props.frame_start, props.frame_end = 40, 60
    assert bpy.ops.humananim.follow_object() == {"FINISHED"}
    assert rig.animation_data.action != grasp_action
    # release
    bpy.context.view_layer.objects.active = target
    scene.frame_set(70)
    assert bpy.ops.humananim.release() == {"FINISHED"}
    # remove self-collisions over a range
    bpy.context.view_layer.objects.active = rig
    props.frame_start, props.frame_end = 1, 5
    assert bpy.ops.humananim.remove_self_collisions() == {"FINISHED"}
    assert rig.animation_data.action.name.endswith("no_self_collision")


def test_hold_another_character(metarig):
    scene = bpy.context.scene
    rig = metarig
    bpy.ops.object.armature_human_metarig_add()
    other = bpy.context.active_object
    other.location = (-0.98, -0.37, 0.0)
    other.rotation_euler = (0, 0, np.pi)
    bpy.context.view_layer.objects.active = rig
    props = scene.humananim_hands
    props.other, props.other_bone, props.side = other, "hand.R", "R"
    props.frame_end = 50
    assert bpy.ops.humananim.hold() == {"FINISHED"}
    assert rig.animation_data.action.name.startswith(rig.name + ".hold")


def test_grasp_command(metarig, tmp_path):
    from humananim.humananim_addon import cli
    target = add_object("SPHERE", (-0.25, -0.35, 1.15), 0.06)
    target.name = "Ball"
    path = tmp_path / "scene.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    out = tmp_path / "out.blend"
    import contextlib
    import io
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        code = cli.main(["grasp", str(path), "--object", "Ball", "--out", str(out), "--json"])
    assert code == 0
    s = json.loads(buf.getvalue().strip().splitlines()[-1] if buf.getvalue().strip().startswith("{") is False
                   else buf.getvalue())
    assert s["command"] == "grasp" and s["object"] == "Ball" and out.exists()
    assert s["max_penetration_mm"] <= 1.0 and s["max_finger_gap_mm"] <= 2.0
    assert s["type"] in ("TRIPOD", "WRAP")
    bpy.ops.wm.open_mainfile(filepath=str(out))
    assert bpy.data.objects["Ball"].constraints.get(hands.CONSTRAINT) is not None


def add_hand_skin(rig, radius=0.008):
    """A skin of rings around the right hand's bones, weighted to them, deformed by the rig."""
    verts, groups = [], []
    names = [b.name for b in rig.data.bones if b.name.endswith(".R") and
             (b.name.startswith(("f_", "thumb")) or b.name == "hand.R")]
    for name in names:
        b = rig.data.bones[name]
        m = np.array(rig.matrix_world @ b.matrix_local)
        for t in np.linspace(0, 1, 6):
            for a in np.linspace(0, 2 * np.pi, 10, endpoint=False):
                p = np.array([radius * np.cos(a), t * b.length, radius * np.sin(a), 1.0])
                verts.append((m @ p)[:3])
                groups.append(name)
    mesh = bpy.data.meshes.new("skin")
    mesh.from_pydata([tuple(v) for v in verts], [], [])
    skin = bpy.data.objects.new("skin", mesh)
    bpy.context.scene.collection.objects.link(skin)
    for k, name in enumerate(groups):
        g = skin.vertex_groups.get(name) or skin.vertex_groups.new(name=name)
        g.add([k], 1.0, "REPLACE")
    mod = skin.modifiers.new("Armature", "ARMATURE")
    mod.object = rig
    return skin


def test_sensors_sized_from_the_skin(metarig):
    from humananim.solver.progress import run_to_end
    scene = bpy.context.scene
    rig = metarig
    add_hand_skin(rig)
    target = add_object("CYLINDER", (-0.25, -0.35, 1.15), 0.05)
    scene.humananim_hands.side = "R"
    s = run_to_end(hands.run_grasp(rig, scene, target))
    assert s["sensors_from"] == "skin"
    assert s["max_penetration_mm"] <= 1.0 and s["max_finger_gap_mm"] <= 2.0
    sk = hands.hand_skeleton(rig, scene)
    world = sk.world_frames(hands.pose_frames(rig, scene, sk, [1])[0], armature_to_world(rig, scene))
    sized = hands.hand_sensors_from_skin(rig, scene, sk, world)["R"]
    assert all(abs(x.radius - 0.008) < 1e-4 for x in sized if x.finger != "palm")



def test_remove_self_collisions_corrects_crossed_legs_as_blender_shows_them(metarig):
    """Keyed crossed legs on the metarig: the left knee goes through the right thigh in Blender's
    evaluation; Remove Self-Collisions leaves no leg sensor inside on any frame, the feet where they
    were, the source action untouched."""
    import sys
    sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "solver"))
    from hands_cases import crossed_legs
    from humananim.humananim_addon.armature import armature_to_world
    from humananim.solver.hands.body import body_sensors, body_volumes, collisions
    from humananim.solver.progress import run_to_end
    scene, rig = bpy.context.scene, metarig
    sk = hands.hand_skeleton(rig, scene)
    frames = np.arange(1, 31)
    base = hands.pose_frames(rig, scene, sk, frames[:1])
    keyed = crossed_legs(sk, base[0], frames=len(frames))
    source = hands.write_result(rig, scene, sk, None, frames, np.repeat(base, len(frames), 0), keyed, "crossing")
    a2w = armature_to_world(rig, scene)

    def legs(frame_numbers):
        worlds = [sk.world_frames(b, a2w) for b in hands.pose_frames(rig, scene, sk, frame_numbers)]
        sens = [s for s in body_sensors(sk, worlds[0]) if s.limb == "leg"]
        depth = [max([d for *_, d, _ in collisions(sk, sens, w, [v for v in body_volumes(sk, w) if v.name != "head"])],
                     default=0.0) for w in worlds]
        feet = np.array([[w[sk.role_index(f"foot.{s}")][:3, 3] for s in "LR"] for w in worlds])
        return np.array(depth), feet

    before, feet_before = legs(frames)
    assert before.max() > 0.05
    snapshot = fcurve_snapshot(source, rig)
    props = scene.humananim_hands
    props.frame_start, props.frame_end = int(frames[0]), int(frames[-1])
    summary = run_to_end(hands.run_self_collisions(rig, scene))
    assert rig.animation_data.action is not source and summary["leg_frames_corrected"] > 0
    after, feet_after = legs(frames)
    assert after.max() < 0.001, f"{after.max() * 1000:.1f} mm inside"
    assert np.abs(feet_after - feet_before).max() < 0.002 and summary["max_foot_error_mm"] < 2.0
    now = fcurve_snapshot(source, rig)
    assert now.keys() == snapshot.keys() and all(np.array_equal(now[k], snapshot[k]) for k in now)
