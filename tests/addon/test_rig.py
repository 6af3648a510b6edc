"""Rigs into skeletons: roles, refusals, mass models, registration, on real rigs."""

import pytest

bpy = pytest.importorskip("bpy")
import numpy as np  # noqa: E402

from conftest import import_cmu
from humananim.humananim_addon import mass_model
from humananim.humananim_addon.armature import skeleton_from_armature
from humananim.solver.anthropometry import DE_LEVA, segment_fraction_range
from humananim.solver.body_roles import REQUIRED_ROLES


def _segment_fractions(skeleton):
    """Body-mass fraction of each de Leva segment (both sides summed where sided)."""
    roles = skeleton.roles
    frac = {}
    for j, name in enumerate(skeleton.names):
        role = roles.role_of(name)
        if role and skeleton.mass[j] > 0:
            kind = role.split(".")[0]
            frac[kind] = frac.get(kind, 0.0) + skeleton.mass[j] / skeleton.total_mass
    return frac


@pytest.mark.parametrize("rig", ["metarig", "cmu"])
def test_anthropometric_masses_are_plausible(rig, empty_scene, request):
    obj = request.getfixturevalue("metarig") if rig == "metarig" else import_cmu()
    skeleton = skeleton_from_armature(obj, bpy.context.scene, total_mass=82.0)
    assert skeleton.total_mass == pytest.approx(82.0, rel=1e-9)
    assert not skeleton.roles.missing()
    frac = _segment_fractions(skeleton)
    for kind, segment in [("thigh", "thigh"), ("shin", "shank"), ("upper_arm", "upper_arm"),
                          ("forearm", "forearm")]:
        lo, hi = segment_fraction_range(segment)
        assert 2 * lo <= frac[kind] <= 2 * hi, (kind, frac[kind])
    assert 0.05 < frac["head"] + frac.get("neck", 0) < 0.09
    assert 0.35 < frac["pelvis"] + frac.get("spine", 0) + frac.get("chest", 0) < 0.5
    # every massive segment has a positive definite inertia and a centre near its bone
    for j in np.flatnonzero(skeleton.mass > 0):
        assert np.all(np.linalg.eigvalsh(skeleton.inertia[j]) > 0), skeleton.names[j]
        assert np.linalg.norm(skeleton.com[j]) < 1.5 * skeleton.lengths[j] + 0.15


def test_rig_without_legs_is_refused_naming_what_is_missing(metarig):
    bpy.ops.object.mode_set(mode="EDIT")
    for name in [b.name for b in metarig.data.edit_bones]:
        if any(k in name for k in ("thigh", "shin", "foot", "toe", "heel")):
            metarig.data.edit_bones.remove(metarig.data.edit_bones[name])
    bpy.ops.object.mode_set(mode="OBJECT")
    with pytest.raises(RuntimeError) as info:
        bpy.ops.humananim.detect_roles()
    message = str(info.value)
    assert "thigh" in message and "foot" in message
    assert metarig.data.humananim.missing_roles


def test_detect_roles_operator_stores_roles(metarig):
    assert bpy.ops.humananim.detect_roles() == {"FINISHED"}
    settings = metarig.data.humananim
    detected = {i.role: i.bones for i in settings.detected_roles}
    assert all(r in detected for r in REQUIRED_ROLES)
    assert settings.detected_convention
    assert settings.missing_roles == ""


def test_role_override_is_used_and_checked(cmu_rig, empty_scene):
    settings = cmu_rig.data.humananim
    settings.roles.head = "Neck"
    skeleton = skeleton_from_armature(cmu_rig, empty_scene)
    assert skeleton.roles.bone("head") == "Neck"
    settings.roles.head = "NoSuchBone"
    with pytest.raises(Exception, match="NoSuchBone"):
        skeleton_from_armature(cmu_rig, empty_scene)


def test_stored_mass_model_is_editable(cmu_rig, empty_scene):
    assert bpy.ops.humananim.compute_mass_model() == {"FINISHED"}
    settings = cmu_rig.data.humananim
    assert sum(s.mass for s in settings.segments) == pytest.approx(70.0, rel=1e-5)
    thigh = next(s for s in settings.segments if s.bone == "LeftHip")
    thigh.mass = 20.0  # the animator edits one segment
    skeleton = skeleton_from_armature(cmu_rig, empty_scene)
    assert skeleton.mass[skeleton.index("LeftHip")] == pytest.approx(20.0)


def _box_body(armature, scene, density):
    """A skin of one box per role bone, each weighted fully to its bone: exact known volumes."""
    skeleton = skeleton_from_armature(armature, scene)
    verts, faces, groups, volume = [], [], [], {}
    owners = mass_model.segment_owner(skeleton)
    for j in np.flatnonzero(owners == np.arange(len(owners))):
        name, length = skeleton.names[j], max(skeleton.lengths[j], 0.02)
        size = np.array([0.06, length, 0.05])
        corners = np.array([[x, y, z] for x in (-.5, .5) for y in (0, 1) for z in (-.5, .5)]) * size
        world = (skeleton.rest[j] @ np.c_[corners, np.ones(8)].T).T[:, :3]
        base = len(verts)
        verts.extend(world.tolist())
        for q in [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]:
            faces.append(tuple(base + i for i in q))
        groups.append((name, range(base, base + 8)))
        volume[name] = float(np.prod(size))
    mesh = bpy.data.meshes.new("boxes")
    mesh.from_pydata(verts, [], faces)
    body = bpy.data.objects.new("body", mesh)
    scene.collection.objects.link(body)
    for name, idx in groups:
        body.vertex_groups.new(name=name).add(list(idx), 1.0, "REPLACE")
    body.modifiers.new("Armature", "ARMATURE").object = armature
    return {k: v * density for k, v in volume.items()}


def test_mesh_mass_model_integrates_the_bound_skin(cmu_rig, empty_scene):
    expected = _box_body(cmu_rig, empty_scene, 1000.0)
    settings = cmu_rig.data.humananim
    assert settings.mass_source == "AUTO"  # a bound mesh is used without asking
    settings.density = 1000.0
    skeleton = skeleton_from_armature(cmu_rig, empty_scene)
    for name, m in expected.items():
        assert skeleton.mass[skeleton.index(name)] == pytest.approx(m, rel=1e-6), name
    j = skeleton.index("LeftKnee")  # the box's centre sits half way along the bone
    assert np.allclose(skeleton.com[j], [0, max(skeleton.lengths[j], 0.02) / 2, 0], atol=1e-6)
    settings.mass_source = "ANTHROPOMETRIC"  # the animator can still choose the tables
    assert skeleton_from_armature(cmu_rig, empty_scene).total_mass == pytest.approx(70.0)


def test_register_unregister_register_cycle():
    import humananim
    humananim.unregister()
    assert not hasattr(bpy.types.Armature, "humananim")
    with pytest.raises(KeyError):
        bpy.ops.humananim.detect_roles.get_rna_type()
    humananim.register()
    assert bpy.ops.humananim.detect_roles.get_rna_type()
    assert hasattr(bpy.types.Armature, "humananim")


def test_cmu_hand_centre_lies_towards_the_fingers_on_every_blender(empty_scene):
    """The CMU wrists' tails are the importer's guess (Blender 4.2 and 5.0 differ by 29 cm); the
    hand's centre of mass, where a carried load sits, comes from the wrist and the fingers."""
    skeleton = skeleton_from_armature(import_cmu(), bpy.context.scene, total_mass=70.0)
    for side in "LR":
        j = skeleton.index(skeleton.roles.bone(f"hand.{side}"))
        wrist = skeleton.rest[j, :3, 3]
        fingers = skeleton.rest[skeleton.index(f"{side}Fingers"), :3, 3]
        centre = skeleton.rest[j, :3, :3] @ skeleton.com[j] + wrist
        reach = fingers - wrist
        assert (centre - wrist) @ reach / (reach @ reach) == pytest.approx(
            DE_LEVA["male"]["hand"][1] / 100.0, rel=1e-6)
        assert np.linalg.norm(np.cross(centre - wrist, reach)) < 1e-6
