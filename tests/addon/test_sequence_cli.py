"""`python -m humananim filter|blend|compress|warp` as a user runs them, in a fresh process."""

import json
import os
import subprocess
import sys

import pytest

from conftest import CMU_CLIPS

pytest.importorskip("bpy")
pytestmark = pytest.mark.slow


def run(*args):
    return subprocess.run([sys.executable, "-m", "humananim", *args], capture_output=True, text=True,
                          timeout=300, env=dict(os.environ))


def test_compress_a_bvh_meets_its_tolerances_and_reports(tmp_path):
    out = tmp_path / "c.blend"
    r = run("compress", CMU_CLIPS[0], "--degrees", "1", "--cm", "1", "--out", str(out), "--json")
    assert r.returncode == 0, r.stderr
    s = json.loads(r.stdout)
    assert s["command"] == "compress" and s["wrote"] == [str(out)] and out.exists()
    assert s["keys_after"] < s["keys_before"] / 10
    assert s["max_error_deg"] <= 1.0 and s["max_error_cm"] <= 1.0
    assert 0 < s["tail_error_cm"] <= s["tail_10cm_error_cm"]
    assert s["action"] == "cmu_131_01.compressed" and s["ms"] > 0
    # planted feet kept within 2.5 mm of the source by default (docs/qa.md), and the QA's slide holds
    assert s["tolerance_feet_mm"] == 2.5 and s["feet_error_mm"] <= 2.5
    assert s["qa"]["measures"]["slide"]["passed"] is True
    r = run("compress", CMU_CLIPS[0], "--feet-mm", "-1", "--out", str(tmp_path / "bad.blend"))
    assert r.returncode == 2 and "Traceback" not in r.stderr and not (tmp_path / "bad.blend").exists()


def test_filter_then_warp_a_blend_and_plain_summaries(tmp_path):
    filtered = tmp_path / "f.blend"
    r = run("filter", CMU_CLIPS[0], "--denoise-hz", "8", "--out", str(filtered))
    assert r.returncode == 0, r.stderr
    assert "cmu_131_01.eq" in r.stdout and "wrote" in r.stdout
    warped = tmp_path / "w.blend"
    r = run("warp", str(filtered), "--action", "cmu_131_01.eq", "--map", "100:80,500:520", "--bones",
            "LeftKnee,RightKnee", "--out", str(warped), "--json")
    assert r.returncode == 0, r.stderr
    s = json.loads(r.stdout)
    assert s["source_action"] == "cmu_131_01.eq" and s["action"] == "cmu_131_01.eq.warped"
    assert s["bones"] == ["LeftKnee", "RightKnee"] and s["curves"] == 6
    assert [100.0, 80.0] in s["constraints"] and [500.0, 520.0] in s["constraints"]


def test_blend_two_bvh_clips(tmp_path):
    out = tmp_path / "b.blend"
    r = run("blend", CMU_CLIPS[0], "--with", CMU_CLIPS[1], "--start", "900", "--window", "20",
            "--out", str(out), "--json")
    assert r.returncode == 0, r.stderr
    s = json.loads(r.stdout)
    assert s["action_b"] == "cmu_131_03" and s["start"] == 900.0
    assert s["frames"][0] == 1.0 and s["frames"][1] == 900.0 + 1247.0
    assert 900.0 <= s["transition"][0] < s["transition"][1] <= 920.0
    # the planted feet are held through the transition: the result's contacts within the QA
    feet = s["feet"]
    assert set(feet["held"]) == {"L", "R"} and "released" in feet
    assert s["qa"]["measures"]["slide"]["passed"] and s["qa"]["measures"]["penetration"]["passed"]


@pytest.mark.parametrize("args,needle", [
    (("warp", CMU_CLIPS[0]), "give --map"),
    (("warp", CMU_CLIPS[0], "--map", "100-80"), "OLD:NEW"),
    (("filter", CMU_CLIPS[0]), "give --gains or --denoise-hz"),
    (("compress", CMU_CLIPS[0], "--bones", "Tail"), "no bone named"),
    (("blend", CMU_CLIPS[0], "--with", "nothing"), "no such file"),
])
def test_user_mistakes_are_one_line(args, needle, tmp_path):
    r = run(*args, "--out", str(tmp_path / "x.blend"))
    assert r.returncode == 2, r.stderr
    assert needle in r.stderr and "Traceback" not in r.stderr
    assert len([line for line in r.stderr.splitlines() if line.startswith("humananim")]) == 1
