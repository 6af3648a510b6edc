"""The list operators the panels share: add a push or an impulse on the active bone, remove the
selected one, remove a capture device."""

import pytest

bpy = pytest.importorskip("bpy")

from test_panels import draw_all  # noqa: E402


@pytest.mark.parametrize("add, remove, settings, items, index", [
    ("add_push", "remove_push", "humananim_simulation", "pushes", "push_index"),
    ("add_impulse", "remove_impulse", "humananim_control", "impulses", "impulse_index"),
])
def test_add_on_the_active_bone_then_remove_the_selected(metarig, add, remove, settings, items, index):
    scene, obj = bpy.context.scene, metarig
    props = getattr(scene, settings)
    obj.data.bones.active = None
    assert not getattr(bpy.ops.humananim, add).poll()  # no active bone
    obj.data.bones.active = obj.data.bones["spine.003"]
    scene.frame_set(12)
    empties = {o.name for o in bpy.data.objects if o.type == "EMPTY"}
    assert "FINISHED" in getattr(bpy.ops.humananim, add)()
    assert "FINISHED" in getattr(bpy.ops.humananim, add)()
    listed = getattr(props, items)
    assert len(listed) == 2 and listed[0].bone == "spine.003" and listed[0].frame == 12
    arrows = {o.name for o in bpy.data.objects if o.type == "EMPTY"} - empties
    assert len(arrows) == 2
    drawn = draw_all(bpy.context)  # the panel lists them and shows the selected one's settings
    assert ("prop", items) in drawn and ("prop", "magnitude") in drawn and ("prop", "empty") in drawn
    setattr(props, index, 1)
    assert "FINISHED" in getattr(bpy.ops.humananim, remove)()
    assert len(listed) == 1 and getattr(props, index) == 0
    assert "FINISHED" in getattr(bpy.ops.humananim, remove)()
    assert len(listed) == 0 and not getattr(bpy.ops.humananim, remove).poll()
    assert arrows <= {o.name for o in bpy.data.objects}  # the arrows stay in the scene


def test_remove_device(empty_scene):
    from humananim.humananim_addon.capture import job as capture
    s = empty_scene.humananim_capture
    for kind in ("FLOCK", "CYBERGLOVE"):
        capture.add_device(empty_scene, kind)
    n = len(s.devices)
    s.device_index = n - 1
    assert "FINISHED" in bpy.ops.humananim.capture_remove_device()
    assert len(s.devices) == n - 1 and s.device_index == n - 2
