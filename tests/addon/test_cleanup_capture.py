"""Clean Up Capture in Blender: the operator on the bundled CMU walk (its right wrist turns 55 deg
in one frame near frame 236 and its right thumb flips 180 deg: both repaired, as Blender evaluates
the new action), the contacts as Motion Queue pose markers, the source untouched, the panel's
report; and `python -m humananim cleanup` as a user runs it."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from conftest import CMU_CLIPS, world_pose

bpy = pytest.importorskip("bpy")

from humananim.humananim_addon import cleanup  # noqa: E402
from humananim.humananim_addon.qa import job as qa  # noqa: E402


def _turn_deg(m):
    """Per frame step the rotation angle of each bone's local (parent-relative) orientation."""
    r = m[..., :3, :3] / np.linalg.norm(m[..., :3, :3], axis=-2, keepdims=True)
    rel = np.einsum("fjki,fjkl->fjil", r[:-1], r[1:])
    return np.degrees(np.arccos(np.clip((np.trace(rel, axis1=-2, axis2=-1) - 1) / 2, -1, 1)))


def _local(obj, scene, frames):
    world = world_pose(obj, scene, frames)
    names = [pb.name for pb in obj.pose.bones]
    parents = [names.index(pb.parent.name) if pb.parent else -1 for pb in obj.pose.bones]
    local = world.copy()
    for j, p in enumerate(parents):
        if p >= 0:
            local[:, j] = np.linalg.inv(world[:, p]) @ world[:, j]
    return local, names


def test_operator_repairs_the_wrist_and_thumb_and_writes_markers(cmu_rig):
    scene = bpy.context.scene
    source = cmu_rig.animation_data.action
    digest = qa.action_digest(source)
    frames = list(range(225, 250))
    before, names = _local(cmu_rig, scene, frames)
    assert bpy.ops.humananim.clean_up_capture() == {"FINISHED"}
    result = cmu_rig.animation_data.action
    assert result is not source and result.name == f"{source.name}.clean"
    assert qa.action_digest(source) == digest  # the source untouched
    after, _ = _local(cmu_rig, scene, frames)
    wrist, thumb = names.index("RightWrist"), names.index("RThumb")
    assert _turn_deg(before)[:, wrist].max() > 50 and _turn_deg(before)[:, thumb].max() > 170
    assert _turn_deg(after)[:, wrist].max() < 20 and _turn_deg(after)[:, thumb].max() < 30
    markers = {m.name for m in result.pose_markers}
    assert {"foot.L=supporting", "foot.R=supporting", "foot.L=angular", "foot.R=angular"} <= markers
    from humananim.humananim_addon.synthesis.job import marker_overrides
    overrides = marker_overrides(result, [float(f) for f in range(1, 996)])
    assert any(limb == "foot.L" and cons == "supporting" for limb, _, _, cons in overrides)
    report = cleanup.stored(cmu_rig)
    glitches = report["repairs"][0]
    assert {"RightWrist", "RThumb"} <= {e["bone"] for e in glitches["events"]}
    assert glitches["qa_after"]["pop_velocity"]["value"] < glitches["qa_before"]["pop_velocity"]["value"] / 5
    stored = qa.stored(cmu_rig)
    assert stored["action"] == result.name and stored["measures"]["source_untouched"]["value"] is True
    from test_panels import RecordingLayout
    from humananim.panels.cleanup import VIEW3D_PT_humananim_cleanup
    log = []
    VIEW3D_PT_humananim_cleanup.draw(type("P", (), {"layout": RecordingLayout(log)})(), bpy.context)
    labels = [entry[1] for entry in log if entry[0] == "label"]
    assert len(labels) == 5 and labels[0].startswith("glitches: ") and "glitches;" in labels[0]
    assert [text.split(":")[0] for text in labels] == ["glitches", "jitter", "floor", "skate", "physics"]
    assert labels[4] == "physics: off"


def test_operator_with_every_repair_off_but_glitches(cmu_rig):
    assert bpy.ops.humananim.clean_up_capture(jitter=False, floor=False, skate=False) == {"FINISHED"}
    report = cleanup.stored(cmu_rig)
    assert [r["enabled"] for r in report["repairs"]] == [True, False, False, False, False]
    assert len(cmu_rig.animation_data.action.pose_markers) == 0  # no contacts without the skate repair


def run(*args):
    return subprocess.run([sys.executable, "-m", "humananim", *args], capture_output=True, text=True,
                          timeout=300, env=dict(os.environ))


@pytest.mark.slow
def test_cleanup_command_json(tmp_path):
    out = tmp_path / "clean.blend"
    r = run("cleanup", CMU_CLIPS[0], "--no-jitter", "--jitter-hz", "8", "--out", str(out), "--json")
    assert r.returncode == 0, r.stderr
    s = json.loads(r.stdout)
    assert s["command"] == "cleanup" and s["action"] == "cmu_131_01.clean" and out.exists()
    assert [x["repair"] for x in s["report"]["repairs"]] == ["glitches", "jitter", "floor", "skate", "physics"]
    assert s["report"]["repairs"][1] == {"repair": "jitter", "enabled": False}
    assert s["qa"]["measures"]["source_untouched"]["value"] is True
    assert s["qa"]["measures"]["penetration"]["value"] < 1.0  # cm: no foot through the floor
    bones = {e["bone"] for e in s["report"]["repairs"][0]["events"]}
    assert {"RightWrist", "RThumb"} <= bones and s["markers"] > 0


def test_cleanup_command_refuses_bad_options(tmp_path):
    r = run("cleanup", CMU_CLIPS[0], "--jitter-hz", "nan", "--out", str(tmp_path / "x.blend"))
    assert r.returncode == 2 and "Traceback" not in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "x.blend").exists()


def _ramp(x, y):
    return 0.1 + 0.03 * x  # a ramp rising 3 cm a metre, 10 cm up at x = 0


def _ramp_mesh(half=6.0, n=12):
    """A ramp as a grid of quads, (vertices, faces)."""
    xs = np.linspace(-half, half, n + 1)
    verts = [(x, y, _ramp(x, y)) for y in xs for x in xs]
    faces = [(j * (n + 1) + i, j * (n + 1) + i + 1, (j + 1) * (n + 1) + i + 1, (j + 1) * (n + 1) + i)
             for j in range(n) for i in range(n)]
    return verts, faces


def test_operator_puts_the_feet_on_a_ground_mesh(cmu_rig):
    scene = bpy.context.scene
    verts, faces = _ramp_mesh()
    mesh = bpy.data.meshes.new("Ramp")
    mesh.from_pydata(verts, [], faces)
    ground = bpy.data.objects.new("Ramp", mesh)
    scene.collection.objects.link(ground)
    bpy.context.view_layer.objects.active = cmu_rig
    source = cmu_rig.animation_data.action
    names = [pb.name for pb in cmu_rig.pose.bones]
    feet_bones = [names.index(n) for n in ("LeftAnkle", "RightAnkle", "LeftToe", "RightToe")]
    lengths = np.array([cmu_rig.data.bones[names[j]].length for j in feet_bones])

    def heights(surface):
        """Per frame the lowest foot point above `surface`, as Blender evaluates the action."""
        m = world_pose(cmu_rig, scene, list(range(1, 996, 3)))[:, feet_bones]
        tails = m[..., :3, 3] + m[..., :3, 1] / np.linalg.norm(m[..., :3, 1], axis=-1, keepdims=True) * lengths[:, None]
        return (tails[..., 2] - surface(tails[..., 0], tails[..., 1])).min(axis=1)

    assert bpy.ops.humananim.clean_up_capture(jitter=False, ground_object="Ramp") == {"FINISHED"}
    floor = cleanup.stored(cmu_rig)["repairs"][2]
    assert floor["ground"]["kind"] == "mesh" and floor["lowest_foot_cm"] > -0.1
    on_ramp = heights(_ramp)
    assert on_ramp.min() > -0.002  # no foot through the ramp
    cleanup.assign(cmu_rig, source)  # the same clean-up onto a flat floor 10 cm up
    assert bpy.ops.humananim.clean_up_capture(jitter=False, ground=0.1) == {"FINISHED"}
    on_floor = heights(lambda x, y: 0.1 + 0 * x)
    # standing on the ramp as on the flat floor (CMU 131_01's feet keep their own level above it)
    assert np.percentile(on_ramp, 10) < np.percentile(on_floor, 10) + 0.005


def test_cleanup_command_on_a_ground_obj(tmp_path):
    verts, faces = _ramp_mesh()
    obj = tmp_path / "ramp.obj"  # written Y up, as Blender's OBJ exporter does
    obj.write_text("\n".join([f"v {x} {z} {-y}" for x, y, z in verts] +
                             ["f " + " ".join(str(i + 1) for i in f) for f in faces]))
    out = tmp_path / "clean.blend"
    r = run("cleanup", CMU_CLIPS[0], "--no-jitter", "--ground-mesh", str(obj), "--out", str(out), "--json")
    assert r.returncode == 0, r.stderr
    floor = json.loads(r.stdout)["report"]["repairs"][2]
    assert floor["ground"]["kind"] == "mesh" and floor["lowest_foot_cm"] > -0.1
    bad = tmp_path / "bad.obj"
    bad.write_text("v 0 0 0\nv 1 0 0\n")
    r = run("cleanup", CMU_CLIPS[0], "--ground-mesh", str(bad), "--out", str(tmp_path / "x.blend"))
    assert r.returncode == 2 and "Traceback" not in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "x.blend").exists()


def test_operator_physical_pass_reports_balance(cmu_rig):
    source = cmu_rig.animation_data.action
    assert bpy.ops.humananim.clean_up_capture(jitter=False, physics=True) == {"FINISHED"}
    assert cmu_rig.animation_data.action is not source
    physics = cleanup.stored(cmu_rig)["repairs"][4]
    assert physics["enabled"] and physics["balance_error_max_cm"] >= 0.0
    from test_panels import RecordingLayout
    from humananim.panels.cleanup import VIEW3D_PT_humananim_cleanup
    log = []
    VIEW3D_PT_humananim_cleanup.draw(type("P", (), {"layout": RecordingLayout(log)})(), bpy.context)
    line = [entry[1] for entry in log if entry[0] == "label"][4]
    assert line.startswith("physics: ") and "balance" in line
