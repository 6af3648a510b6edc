"""`python -m humananim capture ...` in a fresh process, with simulated devices."""

import json
import subprocess
import sys

import pytest

from conftest import CMU_CLIPS

pytest.importorskip("bpy")
pytest.importorskip("serial")


def run(*args):
    return subprocess.run([sys.executable, "-m", "humananim", *args], capture_output=True, text=True, timeout=300)


def test_capture_command_records_simulated_devices_into_an_action(tmp_path):
    out = tmp_path / "capture.blend"
    r = run("capture", CMU_CLIPS[0], "--flock", "sim", "--birds", "1,2", "--bones", "Hips,LeftWrist",
            "--glove", "sim", "--rate", "120", "--seconds", "1.5", "--out", str(out), "--json")
    assert r.returncode == 0, r.stderr
    s = json.loads(r.stdout)
    assert s["command"] == "capture" and s["wrote"] == [str(out)] and out.exists()
    assert s["dropped"] == 0 and s["action"].startswith("capture")
    assert s["samples"]["fob/bird1"] >= 120 and s["samples"]["fob/bird2"] >= 120 and s["samples"]["glove/glove"] >= 120
    assert all(d["status"] == "stopped" or d["status"] == "connected" for d in s["devices"])
    assert s["devices"][0]["rate_hz"] > 0 and s["devices"][0]["channels"] == 2  # the rate is shown per bird
    r = run("info", str(out), "--json")
    assert r.returncode == 0 and json.loads(r.stdout)["action"] == s["action"]


def test_capture_command_records_a_simulated_mvn_stream_through_the_calibration(tmp_path):
    out = tmp_path / "mvn.blend"
    r = run("capture", CMU_CLIPS[0], "--mvn", "sim", "--rate", "60", "--seconds", "1.5", "--out", str(out), "--json")
    assert r.returncode == 0, r.stderr
    s = json.loads(r.stdout)
    assert s["dropped"] == 0 and s["discarded_bytes"] == 0 and s["action"].startswith("capture")
    assert s["samples"]["mvn/actor0/Pelvis"] >= 60 and s["samples"]["mvn/actor0/LeftHand"] >= 60
    assert s["devices"][0]["kind"] == "mvn" and s["devices"][0]["channels"] == 23


def test_capture_command_mistakes_are_one_line(tmp_path):
    r = run("capture", CMU_CLIPS[0], "--out", str(tmp_path / "x.blend"))
    assert r.returncode == 2 and "give at least one device" in r.stderr and "Traceback" not in r.stderr
    r = run("capture", CMU_CLIPS[0], "--flock", "sim", "--bones", "Nope", "--out", str(tmp_path / "x.blend"))
    assert r.returncode == 2 and "no bone named 'Nope'" in r.stderr and "Traceback" not in r.stderr
    r = run("capture", CMU_CLIPS[0], "--mvn", "suit", "--out", str(tmp_path / "x.blend"))
    assert r.returncode == 2 and "--mvn: a UDP port number or 'sim'" in r.stderr and "Traceback" not in r.stderr
