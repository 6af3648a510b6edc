"""`python -m humananim walk ...`: on a .blend with a curve, and on a BVH skeleton along a
generated line or S curve, with a bumpy ground and generator strips; mistakes are one line."""

import json
import os
import subprocess
import sys

import pytest

bpy = pytest.importorskip("bpy")

from conftest import CMU_CLIPS  # noqa: E402

pytestmark = pytest.mark.slow


def run(*args):
    return subprocess.run([sys.executable, "-m", "humananim", *args], capture_output=True, text=True, timeout=600,
                          env=dict(os.environ))


def test_walk_a_curve_in_a_blend(metarig, tmp_path):
    from humananim.humananim_addon.walking.cli import s_curve_object
    s_curve_object(bpy.context.scene, 5.0, 0.7)
    src = tmp_path / "rig.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(src))
    out = tmp_path / "walk.blend"
    r = run("walk", str(src), "--path", "WalkS", "--speed", "1.1", "--style", "brisk", "--set", "torso_lean=6",
            "--out", str(out), "--json")
    assert r.returncode == 0, r.stderr
    s = json.loads(r.stdout)
    assert s["command"] == "walk" and s["wrote"] == [str(out)] and out.exists()
    assert s["armature"] == "metarig" and s["path"] == "WalkS" and s["action"].startswith("metarig.walk")
    assert s["style"]["stride"] == pytest.approx(1.1) and s["style"]["torso_lean"] == pytest.approx(6.0)
    assert s["max_foot_slip_mm"] < 2.0 and s["max_root_deviation_cm"] < 3.0
    assert s["cycle_length_error_max"] < 0.05 and s["supports"] >= 6
    assert s["stack"][0]["action"] == s["action"]
    r = run("info", str(out), "--json")
    assert r.returncode == 0


def test_walk_a_bvh_skeleton_without_a_blend(tmp_path):
    out = tmp_path / "bvh_walk.blend"
    r = run("walk", CMU_CLIPS[0], "--s-curve", "4", "--speed-keys", "0:0.6,4:1.4", "--bumps", "0.04",
            "--generator", "cmu_131_01:arm.R:100:weighted:0.5", "--out", str(out))
    assert r.returncode == 0, r.stderr
    text = r.stdout
    assert text.startswith("walk: 'cmu_131_01' walked 'WalkS'")
    assert "feet slide" in text and f"wrote {out}" in text
    assert "strip 'cmu_131_01.gen.cmu_131_01.arm.R'" in text and "influence 0.50" in text


def test_walk_a_bvh_whose_rest_pose_lies_along_x(tmp_path):
    """Issue 23: Bandai Namco's skeleton (every bone along X in its rest pose) was refused ("the
    foot bones are vertical"); it walks from a standing frame of its own clip, its feet planted,
    no joint faster than the QA's cap, no point below the ground."""
    from pathlib import Path
    clip = Path(__file__).resolve().parents[3] / "shared" / "data" / "mocap" / "bandai-namco-1" / \
        "dataset-1_walk_normal_001.bvh"
    if not clip.exists():
        pytest.skip(f"the Bandai Namco corpus is not at {clip.parent}")
    out = tmp_path / "bandai_walk.blend"
    r = run("walk", str(clip), "--line", "3", "--out", str(out), "--json")
    assert r.returncode == 0, r.stderr
    s = json.loads(r.stdout)
    assert s["max_foot_slip_mm"] < 2.0 and s["cycle_length_error_max"] < 0.05 and s["unreached_frames"] == 0
    qa = s["qa"]["measures"]
    for measure in ("slide", "penetration", "pop_velocity", "bone_length", "nonfinite"):
        assert qa[measure]["passed"] is not False, (measure, qa[measure])


@pytest.mark.parametrize("args,needle", [
    (("--path", "Nothing"), "no curve object named"),
    (("--style", "moonwalk"), "unknown style"),
    (("--set", "wobble=2"), "unknown parameter"),
    (("--line", "3", "--speed-keys", "0:x"), "DISTANCE:SPEED"),
    (("--line", "3", "--speed", "9"), "beyond the gait model"),
    (("--line", "3", "--generator", "nope:arm.R:1"), "no action named"),
])
def test_walk_mistakes_are_one_line(tmp_path, args, needle):
    r = run("walk", CMU_CLIPS[0], "--out", str(tmp_path / "x.blend"), *args)
    assert r.returncode == 2 and needle in r.stderr and "Traceback" not in r.stderr, r.stderr
