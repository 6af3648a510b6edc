"""A generated Rigify rig: DEF- bones carry the roles, constraints move them, so poses are read
through the depsgraph."""

import pytest

bpy = pytest.importorskip("bpy")
import numpy as np  # noqa: E402

from conftest import assert_same_pose, world_pose  # noqa: E402
from control_rig import squat_rigify  # noqa: E402
from humananim.humananim_addon import actions  # noqa: E402
from humananim.humananim_addon.armature import skeleton_from_armature  # noqa: E402

pytestmark = pytest.mark.slow

BODY = ("pelvis", "spine", "chest", "neck", "head") + tuple(
    f"{r}.{s}" for s in "LR" for r in ("thigh", "shin", "foot", "clavicle", "upper_arm", "forearm", "hand"))


@pytest.fixture
def rig(generated_rigify_file):
    path, name = generated_rigify_file
    bpy.ops.wm.open_mainfile(filepath=path)
    return bpy.data.objects[name]


def test_roles_and_masses_on_deform_bones(rig):
    skeleton = skeleton_from_armature(rig, bpy.context.scene)
    roles = skeleton.roles
    assert roles.bone("pelvis") == "DEF-spine"
    assert [roles.bone(r) for r in ("thigh.L", "shin.L", "foot.L", "upper_arm.R", "hand.R")] == [
        "DEF-thigh.L", "DEF-shin.L", "DEF-foot.L", "DEF-upper_arm.R", "DEF-hand.R"]
    assert skeleton.total_mass == pytest.approx(70.0)
    massive = [skeleton.names[j] for j in np.flatnonzero(skeleton.mass > 0)]
    assert all(name.startswith("DEF-") for name in massive)


def test_constrained_pose_is_read_exactly(rig):
    scene = bpy.context.scene
    skeleton = skeleton_from_armature(rig, scene)
    assert actions.needs_evaluation(rig)
    traj = actions.read_action(rig, scene, skeleton)
    blender = world_pose(rig, scene, traj.frames)
    assert_same_pose(traj.world_frames(skeleton), blender)
    # the keyed controls (chest, head, FK leg) really moved deform bones
    deform = [j for j, n in enumerate(skeleton.names) if n.startswith("DEF-")]
    moved = np.linalg.norm(blender[11, deform, :3, 3] - blender[0, deform, :3, 3], axis=-1)
    assert (moved > 0.05).sum() >= 10


def _keyed_bones(action, obj):
    from humananim.humananim_addon.action_api import fcurves_of
    return {actions.bone_channel(fc.data_path)[0] for fc in fcurves_of(action, obj)
            if actions.bone_channel(fc.data_path)}


def _deform_pose(rig, action, frames):
    from humananim.humananim_addon.rig.physical import evaluated_pose, physical_skeleton
    skeleton = physical_skeleton(rig, bpy.context.scene)
    return skeleton, evaluated_pose(rig, bpy.context.scene, skeleton, frames, action)


def test_simulating_a_control_rig_keys_its_controls(rig):
    """Formerly refused ("not children of the pelvis"): Simulate reads the deform bones as Blender
    evaluates them and keys the controls (torso, IK feet and hands, FK spine): 8 kg per hand on a
    squat; every body joint Blender shows is the solve's within 1 mm and 0.5 deg."""
    from humananim.humananim_addon.rig import capability
    from humananim.humananim_addon.rig.bones import classify
    source = squat_rigify(rig, 0.3)
    settings = bpy.context.scene.humananim_simulation
    settings.frame_start, settings.frame_end = 1, 30
    settings.load_left = settings.load_right = 8.0
    reports = []
    summary = capability.RigView.summary
    capability.RigView.summary = lambda self: reports.append(summary(self)) or reports[-1]
    try:
        assert bpy.ops.humananim.simulate() == {"FINISHED"}
    finally:
        capability.RigView.summary = summary
    result = rig.animation_data.action
    assert result != source
    assert _keyed_bones(result, rig) <= classify(rig).control
    mismatch = reports[-1]["mismatch_per_role"]
    for role in BODY:
        assert mismatch[role][0] < 1.0 and mismatch[role][1] < 0.5, (role, mismatch[role])
    assert reports[-1]["limbs"] == {"thigh.L": "IK", "thigh.R": "IK", "upper_arm.L": "IK", "upper_arm.R": "IK"}


def test_walk_along_a_path_moves_the_rigify_rig(rig):
    """A 4 m walk keyed on the controls (torso, IK feet and hands, the IK chains' tops): the pelvis,
    both feet and both hands Blender shows travel 4 m along the line; every body joint within 1 mm
    of the solve, and within 0.5 deg but the spine (docs/rigs.md)."""
    from humananim.humananim_addon.walking import job as walking
    from humananim.humananim_addon.rig import capability
    from humananim.humananim_addon.walking.cli import line_object
    from humananim.solver.progress import run_to_end
    scene = bpy.context.scene
    props = scene.humananim_walk
    props.armature, props.path = rig, line_object(scene, 4.0)
    props.speed, props.speed_mode, props.path_mode = 1.2, "CONSTANT", "CURVE"
    reports = []
    write = capability.RigView.iter_write

    def iter_write(self, *a, **k):
        out = yield from write(self, *a, **k)
        reports.append(self.summary())
        return out
    capability.RigView.iter_write = iter_write
    try:
        summary = run_to_end(walking.run(rig, scene))
    finally:
        capability.RigView.iter_write = write
    mismatch = reports[-1]["mismatch_per_role"]
    for role in BODY:
        assert mismatch[role][0] < 1.0, (role, mismatch[role])
        assert role == "spine" or mismatch[role][1] < 0.5, (role, mismatch[role])
    result = walking.CACHE[(rig.name, summary["action"])]
    rig.animation_data.action = None  # what the walk's NLA strip shows
    skeleton, pose = _deform_pose(rig, None, result.frames[[0, -1]])
    pose = np.array(rig.matrix_world) @ pose
    for role in ("pelvis", "foot.L", "foot.R", "hand.L", "hand.R"):
        j = skeleton.role_index(role)
        assert pose[-1, j, 0, 3] - pose[0, j, 0, 3] == pytest.approx(4.0, abs=0.1), role


def test_bake_keys_only_the_controls_and_shows_the_same_pose(rig):
    """Bake to New Action on a control rig keys its controls, never a constraint-driven bone, and
    Blender shows the deform bones as the source did."""
    from humananim.humananim_addon.rig.bones import classify
    source = rig.animation_data.action
    assert bpy.ops.humananim.bake_action() == {"FINISHED"}
    baked = rig.animation_data.action
    assert baked != source
    keyed = _keyed_bones(baked, rig)
    assert keyed and keyed <= classify(rig).control
    frames = np.arange(1, 25)
    _, before = _deform_pose(rig, source, frames)
    _, after = _deform_pose(rig, baked, frames)
    assert np.abs(after[..., :3, 3] - before[..., :3, 3]).max() < 1e-4
    assert np.abs(after[..., :3, :3] - before[..., :3, :3]).max() < 1e-4


def test_deform_bone_to_its_fk_control_by_following_constraints(rig):
    """The rig layer's discovery: DEF-forearm.L follows ORG- and MCH- bones through constraints;
    the control found turns it (with the IK/FK switch it names), the rig's switches are left as
    they were, and a control maps to itself."""
    from humananim.humananim_addon.rig import controls
    pbs = rig.pose.bones
    drivers = controls.switch_drivers(rig)
    before = {k: pbs[k[0]][k[1]] for k in controls.switches_of(drivers, set(pbs.keys()))}
    assert controls.driven(pbs["DEF-forearm.L"]) and not controls.is_control(rig, "DEF-forearm.L")
    found = controls.fk_control(rig, "DEF-forearm.L")
    assert found is not None and found.name == "forearm_fk.L"
    assert controls.is_control(rig, found.name) and found.switches
    assert {k: pbs[k[0]][k[1]] for k in before} == before
    for (bone, prop), value in found.switches.items():
        pbs[bone][prop] = value
    assert controls.carries(rig, "DEF-forearm.L", found.name)
    rest = np.array(rig.data.bones["DEF-forearm.L"].matrix_local)
    control_rest = np.array(rig.data.bones[found.name].matrix_local)
    np.testing.assert_allclose(rest @ found.offset, control_rest, atol=1e-5)
    same = controls.fk_control(rig, "forearm_fk.L")
    assert same.name == "forearm_fk.L" and not same.switches
    np.testing.assert_allclose(same.offset, np.eye(4))
