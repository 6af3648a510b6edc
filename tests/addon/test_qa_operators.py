"""The motion QA in Blender: the bridge's arrays are the pose Blender evaluates, every operator
reports the QA (a WARNING naming bone and frame past a threshold) and stores it for the QA panel,
whose button goes to the frame; operators refuse frame ranges and impulses outside the clip."""

import numpy as np
import pytest

from conftest import world_pose

bpy = pytest.importorskip("bpy")

from humananim.humananim_addon.qa import job as qa  # noqa: E402
from humananim.operators.common import with_qa  # noqa: E402


def test_the_qa_arrays_are_the_pose_blender_evaluates(cmu_rig):
    scene = bpy.context.scene
    action = cmu_rig.animation_data.action
    motion, skeleton = qa.motion_from_action(cmu_rig, scene, action, (1, 40))
    assert motion.heads.shape == (40, 31, 3) and motion.rotations.shape == (40, 31, 4)
    assert list(motion.frames) == list(range(1, 41)) and motion.fps == pytest.approx(120.0, rel=1e-4)
    frames = [1, 17, 40]
    blender = world_pose(cmu_rig, scene, frames)
    index = [skeleton.names.index(b.name) for b in cmu_rig.pose.bones]
    heads = motion.heads[[f - 1 for f in frames]][:, index]
    np.testing.assert_allclose(heads, blender[..., :3, 3], atol=1e-5)
    scene.frame_set(40)
    tails = np.array([cmu_rig.matrix_world @ pb.tail for pb in cmu_rig.pose.bones])
    np.testing.assert_allclose(motion.tails[39][index], tails, atol=1e-5)


def test_an_operator_reports_and_stores_the_qa_and_the_panel_shows_it(cmu_rig):
    from test_panels import RecordingLayout
    from humananim.panels.qa import VIEW3D_PT_humananim_qa
    log = []
    VIEW3D_PT_humananim_qa.draw(type("P", (), {"layout": RecordingLayout(log)})(), bpy.context)
    assert ("label", "No result measured yet: run a HumanAnim tool") in log
    source = cmu_rig.animation_data.action
    assert bpy.ops.humananim.compress_keys() == {"FINISHED"}
    report = qa.stored(cmu_rig)
    assert report["sources"] == [source.name] and report["action"] != source.name
    assert report["measures"]["source_untouched"]["passed"] is True
    assert report["measures"]["pop_velocity"]["passed"] is True  # compressing within 0.5 deg adds no pop
    log = []
    VIEW3D_PT_humananim_qa.draw(type("P", (), {"layout": RecordingLayout(log)})(), bpy.context)
    labels = [text for kind, text in log if kind == "label"]
    assert any(t.startswith("Foot slide:") for t in labels) and any(t.startswith("Pop (velocity):") for t in labels)
    assert ("operator", "humananim.qa_jump") in log


def test_a_squeezed_warp_is_a_warning_naming_bone_and_frame(cmu_rig):
    scene = bpy.context.scene
    bpy.ops.humananim.time_warp(constraints="MAP", warp_map="100:100, 300:102")
    report = qa.stored(cmu_rig)
    pop = report["measures"]["pop_velocity"]
    assert report["passed"] is False and pop["passed"] is False and pop["bone"]
    assert 100 <= pop["frames"][0] <= 103
    assert any(f"'{pop['bone']}'" in w for w in report["warnings"])
    # the message an operator gives: a WARNING with the worst measure
    summary = {"action": report["action"], "source_action": report["sources"][0], "armature": cmu_rig.name,
               "constraints": [[102, 300]]}
    message = with_qa(type("Op", (), {})(), bpy.context, cmu_rig, summary, "warped")
    assert message.level == "WARNING" and "WARNING(S)" in message and report["warnings"][0] in message
    bpy.ops.humananim.qa_jump(frame=int(pop["frames"][0]))
    assert scene.frame_current == int(pop["frames"][0])


def test_operators_refuse_ranges_and_impulses_outside_the_clip(cmu_rig):
    scene = bpy.context.scene
    props = scene.humananim_simulation
    props.frame_start, props.frame_end = 1, 5000
    with pytest.raises(RuntimeError, match="outside 'cmu_131_01' \\(frames 1-995\\)"):
        bpy.ops.humananim.simulate()
    control = scene.humananim_control
    control.frame_start, control.frame_end = 1, 30
    from humananim.humananim_addon.motion_control import job as motion_control
    motion_control.add_impulse(cmu_rig, scene, "Chest", 60, None, 30.0)
    with pytest.raises(RuntimeError, match="impulse on 'Chest' at frame 60 is outside the frame range 1-30"):
        bpy.ops.humananim.dynamic_control()
    assert not [a for a in bpy.data.actions if a.name.endswith((".sim", ".control"))]
