"""Hands on a generated Rigify rig: keys go on its FK controls (found through the constraints),
the IK/FK switch is keyed to FK, and Blender's own evaluation of the DEF- bones shows what the
solver solved: the hand where the solver put it, the grasp type's finger tips on the surface,
nothing inside; the source action untouched; Follow Object keeps the grip; a constrained rig
whose controls can't be found is still refused."""

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from conftest import fcurve_snapshot  # noqa: E402
from humananim.humananim_addon import action_api, hands  # noqa: E402
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


@pytest.mark.parametrize("kind,size", [("SPHERE", 0.08), ("BOX", 0.04)])
def test_grasp_writes_the_fk_controls(rig, kind, size):
    scene = bpy.context.scene
    src = rig.animation_data.action
    snap = fcurve_snapshot(src, rig)
    target = add_object(kind, (-0.25, -0.35, 1.15), size)
    select(rig, target)
    scene.humananim_hands.start_frame = START
    s = run_to_end(hands.run_grasp(rig, scene, target))
    side = s["hands"][0]
    # the FK controls carry the arm and the fingers
    assert {f"upper_arm_fk.{side}", f"forearm_fk.{side}", f"hand_fk.{side}", f"f_index.01.{side}",
            f"f_index.03.{side}", f"thumb.01.{side}"} <= set(s["controls"])
    assert s["switches"] == {f"upper_arm_parent.{side}:IK_FK": 1.0}
    action = rig.animation_data.action
    assert action != src and action.name.startswith(target.name)
    curves = {(f.data_path, f.array_index): f for f in action_api.fcurves_of(action, rig)}
    switch = curves[(f'pose.bones["upper_arm_parent.{side}"]["IK_FK"]', 0)]
    end = s["grasped_frame"]
    assert switch.evaluate(s["frames"][0]) == 1.0 and switch.evaluate(end) == 1.0
    assert switch.evaluate(s["frames"][0] - 1) == 0.0  # the IK arm before the grasp stays IK
    assert (f'pose.bones["f_index.02.{side}"].rotation_quaternion', 0) in curves
    # Blender's DEF- bones at the grasp frame show the solver's grasp
    solved = hands.last_grasp
    sk, result, shape = solved["skeleton"], solved["result"], solved["shape"]
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
