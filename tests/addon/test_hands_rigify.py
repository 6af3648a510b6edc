"""Hands on a generated Rigify rig: keys go on its FK controls (found through the constraints),
the IK/FK switch is keyed to FK, and Blender's own evaluation of the DEF- bones shows what the
solver solved: the hand where the solver put it, the grasp type's finger tips on the surface,
nothing inside; the source action untouched; Follow Object keeps the grip; a constrained rig
whose controls can't be found is still refused."""

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from conftest import fcurve_snapshot  # noqa: E402
from humananim.humananim_addon import action_api  # noqa: E402
from humananim.humananim_addon.hands import job as hands  # noqa: E402
from humananim.humananim_addon.armature import armature_to_world  # noqa: E402
from humananim.solver.hands.grasp import TYPE_FINGERS  # noqa: E402
from humananim.solver.hands.sensors import sensor_centres  # noqa: E402
from humananim.solver.progress import run_to_end  # noqa: E402
from test_hands import add_object, select  # noqa: E402

pytestmark = pytest.mark.slow
START = 24  # the fixture's keys end here: the body stands still while the hand reaches (the solver plans
# the reach on the start pose)


@pytest.fixture
def rig(generated_rigify_file):
    path, name = generated_rigify_file
    bpy.ops.wm.open_mainfile(filepath=path)
    return bpy.data.objects[name]


def blender_world(rig, scene, skeleton, frame):
    """Every bone's world frame (metres) as Blender evaluates the rig at `frame`."""
    scene.frame_set(frame)
    basis = hands.pose_frames(rig, scene, skeleton, [frame])[0]
    return skeleton.world_frames(basis, armature_to_world(rig, scene))


def angle(a, b):
    return float(np.degrees(np.arccos(np.clip((np.trace(a[:3, :3].T @ b[:3, :3]) - 1) / 2, -1, 1))))


@pytest.mark.parametrize("kind,size,spine", [("SPHERE", 0.08, False), ("BOX", 0.04, False), ("SPHERE", 0.08, True)])
def test_grasp_writes_the_fk_controls(rig, kind, size, spine):
    scene = bpy.context.scene
    src = rig.animation_data.action
    snap = fcurve_snapshot(src, rig)
    target = add_object(kind, (-0.25, -0.35, 1.15), size)
    select(rig, target)
    scene.humananim_hands.start_frame = START
    scene.humananim_hands.with_spine = spine
    solved = {}
    s = run_to_end(hands.run_grasp(rig, scene, target, solved=solved))
    side = s["hands"][0]
    # the FK controls carry the arm and the fingers
    assert {f"upper_arm_fk.{side}", f"forearm_fk.{side}", f"hand_fk.{side}", f"f_index.01.{side}",
            f"f_index.03.{side}", f"thumb.01.{side}"} <= set(s["controls"])
    assert s["switches"] == {f"upper_arm_parent.{side}:IK_FK": 1.0}
    # with the spine, its FK controls bend; what moves the pelvis (the torso control) never does
    assert ({"spine_fk.003"} <= set(s["controls"])) == spine and "torso" not in s["controls"]
    action = rig.animation_data.action
    assert action != src and action.name.startswith(target.name)
    curves = {(f.data_path, f.array_index): f for f in action_api.fcurves_of(action, rig)}
    switch = curves[(f'pose.bones["upper_arm_parent.{side}"]["IK_FK"]', 0)]
    end = s["grasped_frame"]
    assert switch.evaluate(s["frames"][0]) == 1.0 and switch.evaluate(end) == 1.0
    assert switch.evaluate(s["frames"][0] - 1) == 0.0  # the IK arm before the grasp stays IK
    assert (f'pose.bones["f_index.02.{side}"].rotation_quaternion', 0) in curves
    # Blender's DEF- bones at the grasp frame show the solver's grasp
    sk, result = solved["skeleton"], solved["result"]
    world = blender_world(rig, scene, sk, end)
    scene.frame_set(end)
    assert rig.pose.bones[f"upper_arm_parent.{side}"]["IK_FK"] == 1.0
    hand = sk.role_index(f"hand.{side}")
    assert sk.names[hand] == f"DEF-hand.{side}"
    assert np.linalg.norm(world[hand][:3, 3] - result.world[hand][:3, 3]) < 0.001
    assert angle(world[hand], result.world[hand]) < 0.5
    sensors = result.hands[0].sensors
    con = target.constraints[hands.CONSTRAINT]
    con.mute = True
    shape_now = hands.object_shape(target, scene)
    con.mute = False
    gap = shape_now.distance(sensor_centres(sensors, world, sk)) - np.array([x.radius for x in sensors])
    assert gap.min() > -0.001, f"a sensor {-gap.min() * 1000:.2f} mm inside"
    for finger in TYPE_FINGERS[s["type"]]:
        assert min(g for x, g in zip(sensors, gap) if x.finger == finger) < 0.002, finger
    assert s["max_penetration_mm"] <= 1.0 and s["max_finger_gap_mm"] <= 2.0
    # and no sensor goes into the object on any frame of the reach and the closing, as Blender shows it
    frames = np.arange(s["frames"][0], end + 1)
    a2w = armature_to_world(rig, scene)
    radii = np.array([x.radius for x in sensors])
    for basis in hands.pose_frames(rig, scene, sk, frames):
        w = sk.world_frames(basis, a2w)
        assert (shape_now.distance(sensor_centres(sensors, w, sk)) - radii).min() > -0.001
    # the animator's action is as it was
    after = fcurve_snapshot(src, rig)
    assert after.keys() == snap.keys() and all(np.array_equal(after[k], snap[k]) for k in snap)


def test_follow_keeps_the_grip(rig):
    scene = bpy.context.scene
    target = add_object("CYLINDER", (-0.25, -0.35, 1.15), 0.04)
    select(rig, target)
    props = scene.humananim_hands
    props.grasp_type = "WRAP"
    props.start_frame = START
    s = run_to_end(hands.run_grasp(rig, scene, target))
    target.location = (-0.25, -0.35, 1.15)
    target.keyframe_insert("location", frame=70)
    target.location = (-0.2, -0.4, 1.22)
    target.keyframe_insert("location", frame=80)
    props.frame_start, props.frame_end = 70, 80
    f = run_to_end(hands.run_follow(rig, scene, target))
    assert f["max_grip_error_mm"] < 1.0
    hand = f"DEF-hand.{s['hands'][0]}"
    grips = []
    for frame in range(70, 81):
        scene.frame_set(frame)
        h = np.array(rig.matrix_world @ rig.pose.bones[hand].matrix)
        h[:3, :3] /= np.linalg.norm(h[:3, :3], axis=0)
        grips.append(np.linalg.inv(h) @ np.array(target.matrix_world))
    grips = np.array(grips)
    assert np.linalg.norm(grips[:, :3, 3] - grips[0, :3, 3], axis=1).max() < 0.001
    assert max(angle(g, grips[0]) for g in grips) < 0.5


def test_unmappable_constrained_rig_is_refused(metarig):
    """Arm and finger bones turned by an empty: no control of the rig moves them."""
    rig = metarig
    bpy.ops.object.empty_add(location=(0, 0, 0))
    empty = bpy.context.active_object
    for name in ("forearm.L", "hand.L", "forearm.R", "hand.R"):
        c = rig.pose.bones[name].constraints.new("COPY_ROTATION")
        c.target = empty
    target = add_object("SPHERE", (-0.25, -0.35, 1.15), 0.06)
    select(rig, target)
    n_actions = len(bpy.data.actions)
    with pytest.raises(RuntimeError, match="no control of the rig turns them"):
        bpy.ops.humananim.grasp()
    assert len(bpy.data.actions) == n_actions and not target.constraints


def arm_depths(rig, scene, skeleton, frames, side="R"):
    """Per frame, the deepest arm sensor inside the trunk or head, as Blender shows the rig."""
    from humananim.solver.hands.body import body_sensors, body_volumes, collisions
    a2w = armature_to_world(rig, scene)
    worlds = [blender_world(rig, scene, skeleton, int(f)) for f in frames]
    vols = [v for v in body_volumes(skeleton, worlds[0]) if v.name in ("trunk", "head")]
    sens = [s for s in body_sensors(skeleton, worlds[0]) if s.limb == "arm" and s.chain_side == side]
    del a2w
    return np.array([max([d for *_, d, _ in collisions(skeleton, sens, w, vols)], default=0.0) for w in worlds])


def test_remove_self_collisions_on_the_fk_controls(rig):
    """A reach across the chest keyed on the FK controls goes through the torso; the correction,
    keyed on the same controls, leaves no arm sensor inside the body in Blender's evaluation
    while the hand keeps its path."""
    from humananim.solver.hands import ik
    scene = bpy.context.scene
    sk = hands.hand_skeleton(rig, scene)
    crig = hands.control_rig(rig, sk, ("R",))
    solver_sk = crig.solver_skeleton(sk)
    frames = np.arange(30, 50)
    base = crig.rigid(hands.pose_frames(rig, scene, sk, frames))
    a2w = armature_to_world(rig, scene)
    hand = sk.role_index("hand.R")
    p0, p1 = sk.world_frames(base[0], a2w)[hand][:3, 3], np.array([0.16, -0.16, 1.38])
    chain = ik.Chain.arm(solver_sk, "R")
    out, cur = base.copy(), base[0].copy()
    for k in range(len(frames)):
        goal = p0 + (p1 - p0) * k / (len(frames) - 1)
        cur = ik.solve(chain, cur, ik.chain_base(chain, solver_sk.world_frames(cur, a2w)), goal, iterations=50).basis
        out[k, chain.joints] = cur[chain.joints]
    crossing = hands.write_result(rig, scene, sk, crig, frames, base, out, "crossing")
    before = arm_depths(rig, scene, sk, frames)
    assert before.max() > 0.01  # Blender shows the FK arm through the torso
    hands_before = np.array([blender_world(rig, scene, sk, int(f))[hand][:3, 3] for f in frames])
    props = scene.humananim_hands
    props.frame_start, props.frame_end = int(frames[0]), int(frames[-1])
    r = run_to_end(hands.run_self_collisions(rig, scene))
    assert rig.animation_data.action != crossing and r["frames_corrected"] > 0
    after = arm_depths(rig, scene, sk, frames)
    assert after.max() < 0.002, f"{after.max() * 1000:.1f} mm inside"
    hands_after = np.array([blender_world(rig, scene, sk, int(f))[hand][:3, 3] for f in frames])
    assert np.linalg.norm(hands_after - hands_before, axis=1).max() < 0.01


def test_hold_another_character_on_the_fk_controls(rig):
    """The generated rig holds a metarig's moving hand: Blender's DEF- hand keeps the same
    transform to the held hand on every frame of the follow."""
    import addon_utils
    addon_utils.enable("rigify", default_set=True)
    scene = bpy.context.scene
    bpy.ops.object.armature_human_metarig_add()
    other = bpy.context.active_object
    other.location = (-0.98, -0.37, 0.0)
    other.rotation_euler = (0, 0, np.pi)
    pb = other.pose.bones["upper_arm.R"]
    pb.rotation_mode = "XYZ"
    for frame, a in ((62, 0.0), (75, 0.25)):  # after the grasp (reach 1 s, close 0.5 s)
        pb.rotation_euler = (a, 0.0, 0.0)
        pb.keyframe_insert("rotation_euler", frame=frame)
    bpy.context.view_layer.objects.active = rig
    props = scene.humananim_hands
    props.other, props.other_bone, props.side = other, "hand.R", "R"
    props.start_frame, props.frame_end = START, 80
    h = run_to_end(hands.run_hold(rig, scene))
    assert h["max_grip_error_mm"] < 1.0
    grips = []
    for frame in range(60, 81):
        scene.frame_set(frame)
        mine = np.array(rig.matrix_world @ rig.pose.bones["DEF-hand.R"].matrix)
        held = np.array(other.matrix_world @ other.pose.bones["hand.R"].matrix)
        grips.append(np.linalg.inv(mine) @ held)
    grips = np.array(grips)
    assert np.linalg.norm(grips[:, :3, 3] - grips[0, :3, 3], axis=1).max() < 0.001
    assert max(angle(g, grips[0]) for g in grips) < 0.5


def test_grasp_command_on_the_generated_rig(rig, tmp_path):
    import contextlib
    import io
    import json
    from humananim.humananim_addon import cli
    name = rig.name
    target = add_object("SPHERE", (-0.25, -0.35, 1.15), 0.06)
    target.name = "Ball"
    path, out = tmp_path / "scene.blend", tmp_path / "out.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        code = cli.main(["grasp", str(path), "--object", "Ball", "--armature", name, "--side", "R",
                         "--start", str(START), "--out", str(out), "--json"])
    assert code == 0
    s = json.loads(buf.getvalue()[buf.getvalue().index("{"):])
    assert "hand_fk.R" in s["controls"] and s["switches"] == {"upper_arm_parent.R:IK_FK": 1.0}
    assert s["max_penetration_mm"] <= 1.0 and s["max_finger_gap_mm"] <= 2.0
    bpy.ops.wm.open_mainfile(filepath=str(out))
    saved = bpy.data.objects[name]
    paths = {f.data_path for f in action_api.fcurves_of(saved.animation_data.action, saved)}
    assert 'pose.bones["upper_arm_parent.R"]["IK_FK"]' in paths
    assert 'pose.bones["hand_fk.R"].rotation_quaternion' in paths
