"""The rig layer: bone classes (deform, control, mechanism) by structure, and the physical skeleton
taken from the deform bones as Blender evaluates them, hung in the body's hierarchy."""

import pytest

bpy = pytest.importorskip("bpy")
import numpy as np  # noqa: E402

from conftest import import_cmu  # noqa: E402
from control_rig import build_control_rig, key_squat, squat_rigify  # noqa: E402
from humananim.humananim_addon.rig.bones import classify  # noqa: E402
from humananim.humananim_addon.rig.physical import (  # noqa: E402
    evaluated_basis, evaluated_pose, physical_skeleton, physical_trajectories)
from humananim.solver.body_roles import SIDES, sided  # noqa: E402
from humananim.solver.rig.hierarchy import PARENT_ROLES  # noqa: E402

BODY = ("pelvis", "spine", "chest", "neck", "head") + tuple(
    sided(r, s) for s in SIDES for r in ("thigh", "shin", "foot", "clavicle", "upper_arm", "forearm", "hand"))


@pytest.fixture
def rigify(generated_rigify_file):
    path, name = generated_rigify_file
    bpy.ops.wm.open_mainfile(filepath=path)
    return bpy.data.objects[name]


@pytest.fixture
def puppet(empty_scene):
    return build_control_rig()


# --- bone classes ------------------------------------------------------------------------------
def test_generated_rigify_classes(rigify):
    """DEF- deform, ORG-/MCH- mechanism, the controls an animator keys (FK, IK targets and poles,
    torso, root, the IK/FK switch holders' controls) found by structure."""
    c = classify(rigify)
    names = {b.name for b in rigify.data.bones}
    assert c.deform == {n for n in names if n.startswith("DEF-")}
    assert not c.deform & c.control
    assert not any(n.startswith(("ORG-", "MCH-", "DEF-")) for n in c.control)
    assert {n for n in names if n.startswith(("ORG-", "MCH-"))} <= c.mechanism
    for s in "LR":
        assert {f"foot_ik.{s}", f"thigh_fk.{s}", f"shin_fk.{s}", f"foot_fk.{s}", f"upper_arm_fk.{s}",
                f"forearm_fk.{s}", f"hand_fk.{s}", f"hand_ik.{s}", f"shoulder.{s}"} <= c.control
    assert {"root", "torso", "chest", "hips", "neck", "head"} <= c.control
    assert c.of("DEF-thigh.L") == "deform" and c.of("MCH-thigh_ik.L") == "mechanism"
    assert c.deform | c.control | c.mechanism == names


def test_plain_fk_rigs_are_all_deform_and_control(metarig):
    c = classify(metarig)
    names = {b.name for b in metarig.data.bones}
    assert c.deform == c.control == names and not c.mechanism
    bpy.ops.wm.read_homefile(use_empty=True)
    cmu = import_cmu()
    c = classify(cmu)
    names = {b.name for b in cmu.data.bones}
    assert c.deform == c.control == names and not c.mechanism
    assert c.of(cmu.data.bones[-1].name) == "deform+control"


def test_procedural_control_rig_classes(puppet):
    """No known naming: IK legs with poles, FK arms, root and torso, deform bones on constraints."""
    c = classify(puppet)
    by_prefix = {p: {b.name for b in puppet.data.bones if b.name.startswith(p + "_")}
                 for p in ("bind", "anim", "helper")}
    assert c.deform == by_prefix["bind"]
    assert c.control == by_prefix["anim"]  # knee poles and the root included
    assert c.mechanism == by_prefix["helper"]  # the IK chain: moved by IK though unconstrained above the owner


def test_an_unkeyable_or_hidden_bone_is_no_control(puppet):
    pb = puppet.pose.bones["anim_toe_l"]
    pb.lock_rotation = pb.lock_location = pb.lock_scale = (True, True, True)
    pb.lock_rotation_w = True
    puppet.data.bones["anim_knee_r"].hide = True
    c = classify(puppet)
    assert "anim_toe_l" in c.mechanism and "anim_knee_r" in c.mechanism
    assert "anim_toe_r" in c.control


# --- the physical skeleton ---------------------------------------------------------------------
def _parent_name(skeleton, name):
    p = skeleton.parents[skeleton.index(name)]
    return None if p < 0 else skeleton.names[p]


def _assert_body_hierarchy(skeleton):
    """Every body role hangs (through its own role's segments only) from the role above it."""
    roles = skeleton.roles
    for role in BODY:
        bone = roles.bone(role)
        assert bone is not None, role
        up = next((r for r in PARENT_ROLES.get(role, ()) if roles.bone(r)), None)
        if up is None:
            continue
        j = skeleton.index(bone)
        parent = skeleton.parents[j]
        target = skeleton.index(roles.chain(up)[-1] if up == "spine" else roles.bone(up))
        ancestors = skeleton.ancestors(j)
        assert target in ancestors, (role, bone, _parent_name(skeleton, bone))
        between = ancestors[:ancestors.index(target)]
        assert all(roles.role_of(skeleton.names[k]) is None for k in between), (
            role, [skeleton.names[k] for k in between])
        assert parent >= 0


def test_rigify_physical_skeleton_hangs_limbs_from_the_body(rigify):
    skeleton = physical_skeleton(rigify, bpy.context.scene)
    assert all(rigify.data.bones[n].use_deform for n in skeleton.names)
    assert skeleton.joint_count == sum(b.use_deform for b in rigify.data.bones)
    assert rigify.data.bones["DEF-thigh.L"].parent.name.startswith(("ORG-", "MCH-"))
    assert _parent_name(skeleton, "DEF-thigh.L") == _parent_name(skeleton, "DEF-thigh.R") == "DEF-spine"
    assert _parent_name(skeleton, "DEF-upper_arm.L") == "DEF-shoulder.L"
    assert _parent_name(skeleton, "DEF-shin.L") == "DEF-thigh.L.001"  # twist segment kept: the rig's own
    assert _parent_name(skeleton, "DEF-f_index.01.L") == "DEF-hand.L"
    assert [skeleton.names[j] for j in np.flatnonzero(skeleton.parents < 0)] == ["DEF-spine"]
    _assert_body_hierarchy(skeleton)
    assert skeleton.total_mass == pytest.approx(70.0)


def test_procedural_physical_skeleton_hangs_limbs_from_the_body(puppet):
    skeleton = physical_skeleton(puppet, bpy.context.scene)
    assert set(skeleton.names) == {b.name for b in puppet.data.bones if b.use_deform}
    for s in "lr":
        assert puppet.data.bones[f"bind_thigh_{s}"].parent.name == "helper_bind_root"
        assert _parent_name(skeleton, f"bind_thigh_{s}") == "bind_hips"
        assert _parent_name(skeleton, f"bind_upperarm_{s}") == f"bind_collar_{s}"
        assert _parent_name(skeleton, f"bind_foot_{s}") == f"bind_shin_{s}"
    _assert_body_hierarchy(skeleton)
    assert not skeleton.connected[skeleton.index("bind_thigh_l")]


def _assert_matches_blender(obj, skeleton, action, frames):
    scene = bpy.context.scene
    basis = evaluated_basis(obj, scene, skeleton, frames, action)
    solved = skeleton.world_frames(basis, np.array(obj.matrix_world))
    blender = np.array(obj.matrix_world) @ evaluated_pose(obj, scene, skeleton, frames, action)
    err = np.linalg.norm(solved[..., :3, 3] - blender[..., :3, 3], axis=-1)
    assert err.max() < 1e-3, f"{err.max() * 1000:.3f} mm at {skeleton.names[np.argmax(err.max(axis=0))]}"
    # the y axes (along the bones) agree too: the tails match
    along = blender[..., :3, 1] / np.linalg.norm(blender[..., :3, 1], axis=-1, keepdims=True)
    ang = np.arccos(np.clip(np.einsum("...i,...i", solved[..., :3, 1], along), -1, 1))
    assert np.degrees(ang.max()) < 0.05
    return solved


@pytest.mark.slow
def test_rigify_squat_on_controls_is_the_skeleton_the_solver_gets(rigify):
    action = squat_rigify(rigify)
    skeleton = physical_skeleton(rigify, bpy.context.scene)
    frames = np.arange(1, 31, dtype=float)
    solved = _assert_matches_blender(rigify, skeleton, action, frames)
    pelvis, foot = skeleton.role_index("pelvis"), skeleton.role_index("foot.L")
    drop = solved[0, pelvis, 2, 3] - solved[:, pelvis, 2, 3]
    assert drop.max() == pytest.approx(0.3, abs=0.02)  # the squat really moved the body
    assert np.ptp(solved[:, foot, :3, 3], axis=0).max() < 1e-3  # on planted IK feet
    knee = skeleton.role_index("shin.L")
    assert np.ptp(solved[:, knee, 1, 3]) > 0.05


def test_procedural_squat_on_controls_is_the_skeleton_the_solver_gets(puppet):
    key_squat(puppet, depth=0.3)
    skeleton = physical_skeleton(puppet, bpy.context.scene)
    frames = np.arange(1, 41, dtype=float)
    solved = _assert_matches_blender(puppet, skeleton, puppet.animation_data.action, frames)
    pelvis, foot, shin = (skeleton.role_index(r) for r in ("pelvis", "foot.L", "shin.R"))
    drop = solved[0, pelvis, 2, 3] - solved[:, pelvis, 2, 3]
    assert drop.max() == pytest.approx(0.3, abs=0.01)
    assert np.ptp(solved[:, foot, :3, 3], axis=0).max() < 1e-3
    assert np.ptp(solved[:, shin, 1, 3]) > 0.05  # the knee comes forward
    # a rigid rig: the joints hung anew (thighs on the hips, upper arms on the collars) keep their
    # rest offsets from their new parents, the skeleton the solver gets is one rigid body tree
    basis = evaluated_basis(puppet, bpy.context.scene, skeleton, frames)
    body = [skeleton.role_index(r) for r in BODY[1:]]  # the pelvis, the root, moves freely
    assert np.linalg.norm(basis[:, body, :3, 3], axis=-1).max() < 1e-4
    # what a capability reads: Trajectories over the squat's keys, the same pose
    traj = physical_trajectories(puppet, bpy.context.scene, skeleton)
    np.testing.assert_array_equal(traj.frames, frames)
    np.testing.assert_allclose(traj.world_frames(skeleton)[..., :3, 3], solved[..., :3, 3], atol=1e-6)


@pytest.mark.parametrize("rig", ["metarig", "cmu"])
def test_on_plain_fk_rigs_the_physical_skeleton_is_the_armature(rig, empty_scene, request):
    """Every bone deforms and hangs from its body parent already: the same joints, parents and
    (on the BVH's action) the same motion as the armature's own skeleton."""
    from humananim.humananim_addon import actions
    from humananim.humananim_addon.armature import skeleton_from_armature
    obj = request.getfixturevalue("metarig") if rig == "metarig" else import_cmu()
    scene = bpy.context.scene
    plain, physical = skeleton_from_armature(obj, scene), physical_skeleton(obj, scene)
    assert physical.names == plain.names
    np.testing.assert_array_equal(physical.parents, plain.parents)
    np.testing.assert_array_equal(physical.connected, plain.connected)
    np.testing.assert_allclose(physical.mass, plain.mass)
    if rig == "cmu":
        frames = (1, 120)
        a = actions.read_action(obj, scene, plain, frame_range=frames).world_frames(plain)
        b = physical_trajectories(obj, scene, physical, frame_range=frames).world_frames(physical)
        assert np.abs(a[..., :3, 3] - b[..., :3, 3]).max() < 1e-5
