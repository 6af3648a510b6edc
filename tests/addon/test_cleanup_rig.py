"""Clean Up Capture on rigs with controls (through the rig layer, humananim_addon.rig): a one-frame
flip keyed on a spine control is repaired, the new action keys only the rig's controls, the deform
bones Blender evaluates from it carry the cleaned motion, and the source action is unchanged. On
the procedural control rig of tests/addon/control_rig.py and on a generated Rigify rig."""

import pytest

bpy = pytest.importorskip("bpy")
import numpy as np  # noqa: E402

from control_rig import build_control_rig, key_squat, squat_rigify  # noqa: E402
from humananim.humananim_addon.qa import job as qa  # noqa: E402
from humananim.humananim_addon.rig.bones import classify  # noqa: E402
from humananim.humananim_addon.rig.capability import RigView  # noqa: E402
from humananim.humananim_addon.rig.physical import evaluated_pose  # noqa: E402
from humananim.solver.cleanup import Options, clean_up  # noqa: E402

pytestmark = pytest.mark.slow

FLIP_RAD = 2.0  # 115 deg, for one frame
SHOWN_MM = 2.0  # the deform bones Blender shows against the cleaned motion (hands, feet, pelvis)


def _flip_control(obj, control, frame):
    """Keys the control as it is on the frames around `frame` and turned FLIP_RAD about X on it."""
    scene, pb = bpy.context.scene, obj.pose.bones[control]
    pb.rotation_mode = "XYZ"
    for f in (frame - 1, frame + 1, frame):
        scene.frame_set(f)
        values = tuple(pb.rotation_euler)
        if f == frame:
            values = (values[0] + FLIP_RAD, values[1], values[2])
        pb.rotation_euler = values
        pb.keyframe_insert("rotation_euler", frame=f)


def _keyed_bones(action, obj):
    from humananim.humananim_addon.action_api import fcurves_of
    from humananim.humananim_addon.actions import bone_channel
    return {bone_channel(fc.data_path)[0] for fc in fcurves_of(action, obj) if bone_channel(fc.data_path)}


def _step_deg(world):
    """(F - 1,) per frame step the turn of a bone's world orientation, degrees."""
    r = world[:, :3, :3] / np.linalg.norm(world[:, :3, :3], axis=-2, keepdims=True)
    rel = np.einsum("fki,fkl->fil", r[:-1], r[1:])
    return np.degrees(np.arccos(np.clip((np.trace(rel, axis1=-2, axis2=-1) - 1) / 2, -1, 1)))


def _clean_and_check(obj, control, deform_role, frame):
    scene = bpy.context.scene
    source = obj.animation_data.action
    _flip_control(obj, control, frame)
    digest = qa.action_digest(source)
    view = RigView(obj, scene)
    assert view.control_rig
    skeleton = view.skeleton
    frames = np.arange(frame - 6, frame + 7)
    shown = lambda action: np.array(obj.matrix_world) @ evaluated_pose(obj, scene, skeleton, frames, action)  # noqa: E731
    bone = skeleton.role_index(deform_role)
    assert _step_deg(shown(source)[:, bone]).max() > 60  # the flip, on the deform bone Blender shows
    options = dict(jitter=False, floor=False, skate=False)
    assert bpy.ops.humananim.clean_up_capture(**options) == {"FINISHED"}
    result = obj.animation_data.action
    assert result is not source and result.name == f"{source.name}.clean"
    assert qa.action_digest(source) == digest  # the source untouched
    keyed = _keyed_bones(result, obj)
    assert keyed and keyed <= classify(obj).control, keyed - classify(obj).control
    after = shown(result)
    assert _step_deg(after[:, bone]).max() < 10  # repaired, as Blender evaluates the new action
    # the deform bones Blender shows carry the cleaned motion (the solver's, on the same reading)
    cleaned, _ = clean_up(skeleton, view.read(source), Options(**options))
    expected = cleaned.world_frames(skeleton)[np.searchsorted(cleaned.frames, frames)]
    roles = [skeleton.role_index(r) for r in ("pelvis", "foot.L", "foot.R", "hand.L", "hand.R", deform_role)]
    error_mm = 1000 * np.linalg.norm(after[:, roles, :3, 3] - expected[:, roles, :3, 3], axis=-1) / skeleton.unit_scale
    assert error_mm.max() < SHOWN_MM, error_mm.max(axis=0)
    return result


@pytest.fixture
def puppet(empty_scene):
    obj = build_control_rig()
    key_squat(obj, depth=0.3)
    return obj


def test_cleanup_on_the_procedural_control_rig(puppet):
    _clean_and_check(puppet, "anim_chest", "chest", 25)


@pytest.fixture
def rigify(generated_rigify_file):
    path, name = generated_rigify_file
    bpy.ops.wm.open_mainfile(filepath=path)
    return bpy.data.objects[name]


def test_cleanup_on_a_generated_rigify_rig(rigify):
    """The squat on the torso and IK foot controls, the left arm in FK with its forearm control
    flipped for one frame. (Rigify's chest control spreads a turn over several spine bones: a
    one-frame flip of it is, per bone, within what a joint can turn, so it is not the test.)"""
    squat_rigify(rigify, 0.3)
    rigify.pose.bones["upper_arm_parent.L"]["IK_FK"] = 1.0  # the left arm follows its FK controls
    _clean_and_check(rigify, "forearm_fk.L", "forearm.L", 15)
