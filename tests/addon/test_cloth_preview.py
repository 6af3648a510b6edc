"""The cloth's live viewport preview (issue 7): a few frames simulated into a temporary mesh,
timer-driven, played in a loop; Esc stops it and nothing of it stays in the file."""

from types import SimpleNamespace

import numpy as np
import pytest

from conftest import CMU_CLIPS, import_cmu

bpy = pytest.importorskip("bpy")

from humananim.humananim_addon.cloth import job as cloth  # noqa: E402
from humananim.operators.cloth import HUMANANIM_OT_cloth_preview  # noqa: E402


def scene_with_skirt():
    bpy.ops.wm.read_homefile(use_empty=True)
    arm = import_cmu(CMU_CLIPS[0])
    scene = bpy.context.scene
    skirt = cloth.add_skirt(arm, scene)
    props = scene.humananim_cloth
    props.collider, props.frame_start, props.frame_end = "CAPSULES", 1, 241
    scene.frame_set(7)
    return scene, skirt


def inventory():
    return (set(bpy.data.objects.keys()), set(bpy.data.meshes.keys()), set(bpy.data.actions.keys()))


def garment_state(skirt):
    co = np.empty(len(skirt.data.vertices) * 3)
    skirt.data.vertices.foreach_get("co", co)
    return co


def test_preview_shows_the_simulated_frames_and_leaves_nothing():
    scene, skirt = scene_with_skirt()
    before, co_before = inventory(), garment_state(skirt)
    preview = cloth.ClothPreview(scene, frames=4)
    shown = [preview.tick() for _ in range(5)]  # frame 1 (the start), then 4 simulated
    assert shown == [1, 5, 9, 13, 17] and not preview.simulating  # 120 fps clip, every 4th frame
    assert len(preview.job.frames_done) == 5
    obj = preview.obj
    assert obj.name == skirt.name + ".cloth_preview" and obj.name in bpy.data.objects
    assert len(obj.data.polygons) == len(preview.job.sim.smoother.faces)
    co = np.empty(len(obj.data.vertices) * 3)
    obj.data.vertices.foreach_get("co", co)
    assert np.allclose(co.reshape(-1, 3), preview.job.fine[-1], atol=1e-5)  # the last simulated frame
    assert not np.allclose(preview.job.fine[-1], preview.job.fine[0], atol=1e-3)  # the cloth moved
    assert scene.frame_current == 7  # the simulation put the frame back
    assert preview.tick() == 1 and scene.frame_current == 1  # playback: the body with its cloth
    co_first = np.empty(len(obj.data.vertices) * 3)
    obj.data.vertices.foreach_get("co", co_first)
    assert np.allclose(co_first.reshape(-1, 3), preview.job.fine[0], atol=1e-5)
    mesh_name = obj.data.name
    preview.stop()
    assert inventory() == before and mesh_name not in bpy.data.meshes
    assert scene.frame_current == 7 and np.array_equal(garment_state(skirt), co_before)


def test_esc_stops_the_modal_preview_and_removes_it():
    scene, skirt = scene_with_skirt()
    before = inventory()
    reports = []
    op = SimpleNamespace(report=lambda kind, msg: reports.append((kind, msg)), _timer=None,
                         _preview=cloth.ClothPreview(scene, frames=30))
    op._stop = lambda context, report=True: HUMANANIM_OT_cloth_preview._stop(op, context, report)
    for _ in range(3):
        assert HUMANANIM_OT_cloth_preview.modal(op, bpy.context, SimpleNamespace(type="TIMER")) == {"RUNNING_MODAL"}
    assert HUMANANIM_OT_cloth_preview.modal(op, bpy.context, SimpleNamespace(type="MOUSEMOVE")) == {"PASS_THROUGH"}
    assert skirt.name + ".cloth_preview" in bpy.data.objects and scene.frame_current == 9  # mid-simulation
    assert HUMANANIM_OT_cloth_preview.modal(op, bpy.context, SimpleNamespace(type="ESC")) == {"CANCELLED"}
    assert inventory() == before and scene.frame_current == 7
    assert "2 frames" in reports[-1][1] and "nothing was kept" in reports[-1][1]


def test_preview_operator_headless_and_its_errors():
    scene, skirt = scene_with_skirt()
    before = inventory()
    assert bpy.ops.humananim.cloth_preview(frames=3) == {"FINISHED"}
    assert inventory() == before and scene.frame_current == 7
    scene.humananim_cloth.collider = "MESH"  # no body mesh: a user error, and still nothing left
    with pytest.raises(RuntimeError, match="body mesh"):
        bpy.ops.humananim.cloth_preview(frames=3)
    assert inventory() == before
