"""The batch command line as a user runs it: `python -m humananim ...` in a fresh process."""

import json
import os
import subprocess
import sys

import pytest

from conftest import CMU_CLIPS

pytest.importorskip("bpy")
pytestmark = pytest.mark.slow


def run(*args, cwd=None):
    env = dict(os.environ)
    return subprocess.run([sys.executable, "-m", "humananim", *args], capture_output=True, text=True,
                          timeout=300, cwd=cwd, env=env)


def test_info_on_a_bvh_prints_json(tmp_path):
    r = run("info", CMU_CLIPS[0], "--json", "--mass", "75")
    assert r.returncode == 0, r.stderr
    info = json.loads(r.stdout)
    assert info["bone_count"] == 31
    assert info["missing_roles"] == []
    assert info["total_mass_kg"] == pytest.approx(75.0)
    assert info["frame_range"] == [1.0, 995.0]
    assert info["fps"] == pytest.approx(120.0, rel=1e-4)
    assert info["bvh_unit"] == "m"
    assert info["roles"]["thigh.L"] == ["LeftHip"]


def test_demo_writes_a_blend_and_info_reads_it(tmp_path):
    out = tmp_path / "demo.blend"
    r = run("demo", "--out", str(out), "--json")
    assert r.returncode == 0, r.stderr
    demo = json.loads(r.stdout)
    assert demo["wrote"][0] == str(out) and out.exists()
    skirts = demo["cloth"]  # a generated skirt on the walk and on the hop, played from point caches
    assert [s["armature"] for s in skirts] == ["cmu_131_01", "cmu_131_03"]
    for s in skirts:
        assert s["complete"] and s["max_depth_inside_mm"] < 2.0 and s["max_mean_stretch"] < 0.02
        assert all(os.path.getsize(path) > 0 for path in s["wrote"] if path.endswith(".pc2"))
    r = run("info", str(out), "--armature", "cmu_131_01")
    assert r.returncode == 0, r.stderr
    assert "70.0 kg" in r.stdout and "cmu_131_01" in r.stdout


@pytest.mark.parametrize("args,needle", [
    (("info", "/no/such/file.bvh"), "no such file"),
    (("info", "__BROKEN_BLEND__"), "cannot open"),
    (("info", "__NOT_BVH__"), "not a BVH file"),
])
def test_user_mistakes_are_one_line_without_traceback(tmp_path, args, needle):
    broken = tmp_path / "broken.blend"
    broken.write_bytes(b"BLENDER-v300 this is not a blend file")
    not_bvh = tmp_path / "notes.bvh"
    not_bvh.write_text("hello")
    args = [str(broken) if a == "__BROKEN_BLEND__" else str(not_bvh) if a == "__NOT_BVH__" else a for a in args]
    r = run(*args)
    assert r.returncode == 2
    assert needle in r.stderr
    assert "Traceback" not in r.stderr
    assert len([l for l in r.stderr.splitlines() if l.startswith("humananim")]) == 1


def test_blender_command_front_door_runs_the_same_commands(capsys):
    """`blender --command humananim ...` calls this handler with the arguments after the id."""
    import bpy
    from humananim.humananim_addon import cli
    assert cli.blender_command(["info", CMU_CLIPS[1], "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["frame_range"] == [1.0, 1248.0] and info["bone_count"] == 31
    assert cli.blender_command(["info", "/no/such.blend"]) == 2
    assert "no such file" in capsys.readouterr().err
    assert cli.blender_command(["--help"]) == 0
    if hasattr(bpy.utils, "register_cli_command"):
        import humananim.humananim_addon as addon
        assert addon._cli_handle is not None


def test_simulate_command_writes_an_action_and_reports(tmp_path):
    out = tmp_path / "sim.blend"
    r = run("simulate", CMU_CLIPS[0], "--frames", "1", "60", "--push", "30:Chest:0,300,0", "--load-left", "5",
            "--out", str(out), "--json")
    assert r.returncode == 0, r.stderr
    summary = json.loads(r.stdout)
    assert summary["action"] == "cmu_131_01.sim" and summary["frames"] == 60
    assert abs(summary["ground_height_m"]) < 0.1  # the capture's own floor, near zero
    assert summary["pushes"] == 1 and summary["loads_kg"] == {"LeftWrist": 5.0}
    assert summary["real_time_factor"] > 0 and summary["wrote"] == [str(out)] and out.exists()
    bad = run("simulate", CMU_CLIPS[0], "--push", "30:Chest:0,0")
    assert bad.returncode == 2 and "FX,FY,FZ" in bad.stderr and "Traceback" not in bad.stderr
