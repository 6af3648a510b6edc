"""The thesis's scene in Blender (issue 5): a puncher armature whose fist flies into the metarig
standing still is set as the Dynamic Control panel's collider (with the fist's mass); the Motion
Queue bake gives, as the punch gets faster, balance control, a protective step, a fall, in a new
action, with the source action untouched."""

import math

import numpy as np
import pytest

from conftest import fcurve_snapshot

bpy = pytest.importorskip("bpy")

FIST_KG = 6.0
ARM = 0.5  # m, the puncher's arm bone: the fist is its tail


def _still(obj, scene):
    from humananim.humananim_addon import actions
    from humananim.humananim_addon.armature import armature_to_world, skeleton_from_armature
    from humananim.solver.synthesis import keyframed
    from humananim.solver.trajectories import Trajectories
    scene.render.fps, scene.render.fps_base = 30, 1.0
    sk = skeleton_from_armature(obj, scene)
    rest = Trajectories(np.array([1.0]), 30.0, np.tile([1.0, 0, 0, 0], (1, sk.joint_count, 1)),
                        np.zeros((1, sk.joint_count, 3)), armature_to_world(obj, scene))
    still = keyframed.still(sk, rest, seconds=2.0)
    return sk, still, actions.write_action(obj, sk, still.trajectories, "still")


def _puncher(scene, sk, still, speed):
    """An armature with one arm bone pointing at the victim; its object flies the fist (the bone's
    tail) along the solver's punch path (keyframes on every frame, linear)."""
    from humananim.solver.synthesis.punch import punch_collider
    col = punch_collider(sk, still.trajectories, speed, mass=FIST_KG)
    fist = np.asarray(col.positions)[:, 0]
    direction = (fist.max(axis=0) - fist.min(axis=0))
    direction /= np.linalg.norm(direction)
    bpy.ops.object.armature_add(location=(0.0, 0.0, 0.0))
    puncher = bpy.context.active_object
    puncher.name = "Puncher"
    # the bone (head at the origin, tail 1 m up +Z) turned to point along the punch and scaled to the arm
    up = np.array([0.0, 0.0, 1.0])
    axis = np.cross(up, direction)
    angle = math.atan2(np.linalg.norm(axis), up @ direction)
    puncher.rotation_mode = "AXIS_ANGLE"
    puncher.rotation_axis_angle = (angle, *(axis / np.linalg.norm(axis)))
    puncher.scale = (ARM, ARM, ARM)
    for i, f in enumerate(still.trajectories.frames):
        puncher.location = tuple(fist[i] - ARM * direction)
        puncher.keyframe_insert("location", frame=float(f))
    from humananim.humananim_addon.action_api import fcurves_of
    for fc in fcurves_of(puncher.animation_data.action, puncher):
        for k in fc.keyframe_points:
            k.interpolation = "LINEAR"
    return puncher


def _bake(obj, scene, still_action, puncher):
    from humananim.humananim_addon.synthesis import job as synthesis
    from humananim.solver.progress import run_to_end
    props = scene.humananim_control
    props.collider, props.collider_radius, props.collider_mass = puncher, 0.05, FIST_KG
    scene.humananim_synthesis.entries.clear()
    synthesis.add_entry(scene, still_action, "BLEND")
    bpy.context.view_layer.objects.active = obj
    return run_to_end(synthesis.run(obj, scene))


def _root(obj, scene, frame):
    scene.frame_set(int(frame))
    root = [b for b in obj.pose.bones if b.parent is None][0]
    return np.array(obj.matrix_world @ root.head)


def _root_height(obj, scene, frame):
    return _root(obj, scene, frame)[2]


def test_punching_character_gives_balance_then_step_then_fall(metarig):
    obj, scene = metarig, bpy.context.scene
    sk, still, source = _still(obj, scene)
    before = fcurve_snapshot(source, obj)
    kinds, outs = [], []
    standing = _root_height(obj, scene, 1)
    for speed in (1.5, 4.0, 14.0):
        puncher = _puncher(scene, sk, still, speed)
        s = _bake(obj, scene, source, puncher)
        kinds.append(s["reaction"]["kind"])
        outs.append(s)
        bpy.data.objects.remove(puncher)
        out = bpy.data.actions[s["action"]]
        assert out != source and obj.animation_data.action == out
        if s["reaction"]["kind"] == "fall":  # the result action shows the fall: the hips near the ground
            assert _root_height(obj, scene, out.frame_range[1]) < standing - 0.4
        if s["reaction"]["kind"] == "step":
            assert s["reaction"]["retracked"] is True
            moved = _root(obj, scene, out.frame_range[1]) - _root(obj, scene, 1)
            assert np.linalg.norm(moved[:2]) > 0.03  # the body stepped away from the punch (4.9 cm)
            assert s["frames_supported"]["L"] < s["frames"] or s["frames_supported"]["R"] < s["frames"]
        obj.animation_data.action = source
    print("punch sweep in Blender", kinds, [o["reaction"] for o in outs])
    assert kinds == ["none", "step", "fall"]
    after = fcurve_snapshot(source, obj)
    assert before.keys() == after.keys() and all(np.array_equal(before[k], after[k]) for k in before)


def test_synthesize_command_with_a_puncher(metarig, tmp_path):
    """`python -m humananim synthesize` with --collide: the same scene headless."""
    import json
    import subprocess
    import sys
    obj, scene = metarig, bpy.context.scene
    sk, still, source = _still(obj, scene)
    obj.animation_data.action = source
    _puncher(scene, sk, still, 14.0)
    path = tmp_path / "punch.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    r = subprocess.run([sys.executable, "-m", "humananim", "synthesize", str(path), "--armature", obj.name,
                        "--queue", "still", "--collide", "Puncher", "--collide-radius", "0.05",
                        "--collide-mass", str(FIST_KG), "--out", str(tmp_path / "out.blend"), "--json"],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    s = json.loads(r.stdout)
    assert s["reaction"]["kind"] == "fall" and s["reaction"]["retracked"] is True
    assert s["action"] != "still" and "reaction: fall" in s["summary"]
