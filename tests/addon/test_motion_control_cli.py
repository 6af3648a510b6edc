"""`python -m humananim control ...` and the demo's dynamic control, in fresh processes."""

import json
import os
import subprocess
import sys

import pytest

from conftest import CMU_CLIPS

pytest.importorskip("bpy")
pytestmark = pytest.mark.slow


def run(*args):
    return subprocess.run([sys.executable, "-m", "humananim", *args], capture_output=True, text=True, timeout=300)


def _png_size(path):
    with open(path, "rb") as f:
        head = f.read(24)
    assert head[:8] == b"\x89PNG\r\n\x1a\n"
    return int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big")


def test_control_command_writes_an_action_a_picture_and_reports(tmp_path):
    out, picture = tmp_path / "control.blend", tmp_path / "control.png"
    r = run("control", CMU_CLIPS[0], "--frames", "1", "72", "--load-left", "8", "--load-right", "8",
            "--impulse", "36:Chest:0,-30,0", "--out", str(out), "--picture", str(picture), "--json")
    assert r.returncode == 0, r.stderr
    s = json.loads(r.stdout)
    assert s["command"] == "control" and s["wrote"] == [str(out), str(picture)]
    assert out.exists() and _png_size(picture) == (1280, 540)
    assert s["action"].startswith("cmu_131_01.control") and s["frames"] == 72
    assert s["loads_kg"] == {"LeftWrist": 8.0, "RightWrist": 8.0} and s["impulses"] == 1
    for key in ("peak_stress_nm", "max_balance_error_m", "max_foot_slide_mm", "real_time_factor"):
        assert s[key] >= 0.0
    assert 0 <= s["frames_falling"] <= 72
    r = run("info", str(out), "--json")  # the .blend holds the result as the active action
    assert r.returncode == 0 and json.loads(r.stdout)["action"] == s["action"]


@pytest.mark.parametrize("args,needle", [
    (("--impulse", "10:Chest:1,2"), "FX,FY,FZ"),
    (("--impulse", "10:NoSuchBone:1,0,0"), "no bone named"),
    (("--collide", "Nothing"), "no object named"),
    (("--action", "Nope"), "no action named"),
])
def test_control_command_mistakes_are_one_line(tmp_path, args, needle):
    r = run("control", CMU_CLIPS[0], "--frames", "1", "10", "--out", str(tmp_path / "x.blend"), *args)
    assert r.returncode == 2 and needle in r.stderr and "Traceback" not in r.stderr


def test_demo_runs_dynamic_control_and_writes_a_blend_and_a_picture(tmp_path):
    out = tmp_path / "demo.blend"
    r = run("demo", "--out", str(out), "--json")
    assert r.returncode == 0, r.stderr
    demo = json.loads(r.stdout)
    control = demo["control"]
    assert out.exists() and demo["picture"] == str(tmp_path / "demo.png")
    assert _png_size(demo["picture"]) == (1280, 540)
    assert control["loads_kg"] == {"LeftWrist": 5.0, "RightWrist": 5.0} and control["impulses"] == 1
    assert control["action"].startswith("cmu_131_01.control")
    assert demo["seconds"] > 0  # measured, not bounded: times belong in benchmarks
