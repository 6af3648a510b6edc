"""Capabilities on control rigs: they read the deform bones as Blender evaluates them and write
their result to the controls; the deform bones Blender then shows are the solved pose."""

import pytest

bpy = pytest.importorskip("bpy")
import numpy as np  # noqa: E402

from control_rig import build_control_rig, key_squat, plain_fk_copy  # noqa: E402
from humananim.humananim_addon.rig.bones import classify  # noqa: E402
from humananim.humananim_addon.rig.physical import evaluated_pose, physical_skeleton  # noqa: E402

pytestmark = pytest.mark.slow

FEET_HANDS_MM, JOINT_DEG = 1.0, 0.5  # the write-back's aim


@pytest.fixture
def puppet(empty_scene):
    obj = build_control_rig()
    key_squat(obj, depth=0.3)
    return obj


def _shown(obj, action, roles, frames):
    """World positions (F, len(roles), 3) of the deform role bones as Blender evaluates `action`."""
    scene = bpy.context.scene
    skeleton = physical_skeleton(obj, scene)
    pose = np.array(obj.matrix_world) @ evaluated_pose(obj, scene, skeleton, frames, action)
    return pose[:, [skeleton.role_index(r) for r in roles]][..., :3, 3]


def _simulate(obj, **props):
    settings = bpy.context.scene.humananim_simulation
    for key, value in props.items():
        setattr(settings, key, value)
    source = obj.animation_data.action
    assert bpy.ops.humananim.simulate() == {"FINISHED"}
    result = obj.animation_data.action
    assert result != source
    return source, result


def _keyed_bones(action, obj):
    from humananim.humananim_addon.actions import bone_channel
    from humananim.humananim_addon.action_api import fcurves_of
    return {bone_channel(fc.data_path)[0] for fc in fcurves_of(action, obj) if bone_channel(fc.data_path)}


def test_simulate_on_a_control_rig_keys_its_controls_and_shows_the_solve(puppet):
    """8 kg per hand with weak arms: the hands sink on the rig as much as on a plain FK copy of the
    same motion, every key is on a control, and Blender shows the solved pose within the aim."""
    from humananim.humananim_addon.rig import capability
    frames = np.arange(1, 41)
    roles = ("hand.L", "hand.R", "pelvis", "foot.L")
    settings = dict(load_left=8.0, load_right=8.0, strength_scale=0.6, frame_start=1, frame_end=40)
    reports = []
    summary = capability.RigView.summary
    capability.RigView.summary = lambda self: reports.append(summary(self)) or reports[-1]
    try:
        source, result = _simulate(puppet, **settings)
    finally:
        capability.RigView.summary = summary
    controls = classify(puppet).control
    keyed = _keyed_bones(result, puppet)
    assert keyed and keyed <= controls, keyed - controls
    report = reports[-1]
    assert report["mismatch_mm"] < FEET_HANDS_MM and report["mismatch_deg"] < JOINT_DEG, report
    rig_before, rig_after = (_shown(puppet, a, roles, frames) for a in (source, result))

    copy = plain_fk_copy(puppet, bpy.context.scene, source)
    copy_source, copy_result = _simulate(copy, **settings)
    skeleton = physical_skeleton(copy, bpy.context.scene)
    pose = lambda a: np.array(copy.matrix_world) @ evaluated_pose(copy, bpy.context.scene, skeleton, frames, a)  # noqa: E731
    idx = [skeleton.role_index(r) for r in roles]
    copy_before, copy_after = (pose(a)[:, idx][..., :3, 3] for a in (copy_source, copy_result))
    np.testing.assert_allclose(rig_before, copy_before, atol=1e-4)  # the same motion to start from
    rig_drop = rig_before[:, :2, 2] - rig_after[:, :2, 2]
    copy_drop = copy_before[:, :2, 2] - copy_after[:, :2, 2]
    assert rig_drop.max() > 0.1  # the loads really lower the hands
    np.testing.assert_allclose(rig_drop, copy_drop, atol=0.005)
    np.testing.assert_allclose(rig_after[:, 2:], copy_after[:, 2:], atol=0.005)  # pelvis and foot too
