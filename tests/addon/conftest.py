"""Headless bpy sessions for the add-on tests; skipped where the bpy module is missing."""

import os
import tempfile

import numpy as np
import pytest

# before bpy is imported: never touch the developer's own Blender configuration
os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="humananim-user-"))

try:
    import bpy
except ImportError:  # the no-bpy checks in this folder still run; bpy tests skip per module
    bpy = None

MOCAP = os.path.join(os.path.dirname(__file__), "..", "..", "..", "shared", "data", "mocap")
if not os.path.isdir(MOCAP):
    MOCAP = "/work/shared/data/mocap"
CMU_CLIPS = [os.path.join(MOCAP, f) for f in ("cmu_131_01.bvh", "cmu_131_03.bvh")]


@pytest.fixture(scope="session", autouse=True)
def humananim_registered():
    if bpy is None:
        yield
        return
    import addon_utils
    import humananim
    humananim.register()
    yield
    # classes left registered at exit crash the bpy 4.2 module
    addon_utils.disable("rigify", default_set=True)
    humananim.unregister()


@pytest.fixture
def empty_scene():
    bpy.ops.wm.read_homefile(use_empty=True)
    return bpy.context.scene


@pytest.fixture
def metarig(empty_scene):
    import addon_utils
    addon_utils.enable("rigify", default_set=True)
    bpy.ops.object.armature_human_metarig_add()
    return bpy.context.active_object


def import_cmu(path=CMU_CLIPS[0]):
    from humananim.humananim_addon.bvh_import import import_bvh
    obj, _, _ = import_bvh(path)
    bpy.context.view_layer.objects.active = obj
    return obj


@pytest.fixture
def cmu_rig(empty_scene):
    return import_cmu()


def world_pose(obj, scene, frames):
    """Every bone's world matrix on every frame, as Blender evaluates it: (F, J, 4, 4)."""
    n = len(obj.pose.bones)
    out = np.empty((len(frames), n * 16))
    for i, f in enumerate(frames):
        scene.frame_set(int(f))
        obj.pose.bones.foreach_get("matrix", out[i])
    m = out.reshape(len(frames), n, 4, 4).transpose(0, 1, 3, 2)
    return np.array(obj.matrix_world) @ m


def assert_same_pose(a, b, pos_tol=1e-5, rot_tol=1e-4):
    """World transforms agree within pos_tol metres and rot_tol radians on every frame and bone."""
    pos = np.linalg.norm(a[..., :3, 3] - b[..., :3, 3], axis=-1)
    ra = a[..., :3, :3] / np.linalg.norm(a[..., :3, :3], axis=-2, keepdims=True)
    rb = b[..., :3, :3] / np.linalg.norm(b[..., :3, :3], axis=-2, keepdims=True)
    cos = (np.trace(np.swapaxes(ra, -1, -2) @ rb, axis1=-2, axis2=-1) - 1.0) / 2.0
    ang = np.arccos(np.clip(cos, -1.0, 1.0))
    assert pos.max() < pos_tol, f"position error {pos.max():.3g} m"
    assert ang.max() < rot_tol, f"rotation error {ang.max():.3g} rad"
    return pos.max(), ang.max()


def fcurve_snapshot(action, obj):
    from humananim.humananim_addon.action_api import fcurves_of
    snap = {}
    for fc in fcurves_of(action, obj):
        co = np.empty(len(fc.keyframe_points) * 2)
        fc.keyframe_points.foreach_get("co", co)
        snap[(fc.data_path, fc.array_index)] = co
    return snap


@pytest.fixture(scope="session")
def generated_rigify_file(tmp_path_factory):
    """A Rigify rig generated from the human metarig, once per session (about 30 s), with a
    keyed FK arm and leg, saved so each test can open a fresh copy."""
    import addon_utils
    addon_utils.enable("rigify", default_set=True)
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.object.armature_human_metarig_add()
    bpy.ops.pose.rigify_generate()
    rig = bpy.context.active_object
    bpy.ops.object.mode_set(mode="POSE")
    for frame, angle in ((1, 0.0), (12, 0.7), (24, -0.3)):
        for name in ("upper_arm_fk.L", "forearm_fk.L", "thigh_fk.R", "chest", "head"):
            pb = rig.pose.bones[name]
            pb.rotation_mode = "XYZ"
            pb.rotation_euler = (angle, 0.4 * angle, -0.2 * angle)
            pb.keyframe_insert("rotation_euler", frame=frame)
    bpy.ops.object.mode_set(mode="OBJECT")
    path = tmp_path_factory.mktemp("rigify") / "generated.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    return str(path), rig.name
