"""`python -m humananim flexible simulate|optimize ...` in fresh processes."""

import json
import subprocess
import sys

import pytest

pytest.importorskip("bpy")
pytestmark = pytest.mark.slow


def run(*args):
    return subprocess.run([sys.executable, "-m", "humananim", "flexible", *args], capture_output=True, text=True,
                          timeout=300)


def test_simulate_optimize_and_bake_the_best_again(tmp_path):
    first = tmp_path / "table.blend"
    r = run("simulate", "--demo", "--frames", "1", "25", "--out", str(first), "--json")
    assert r.returncode == 0, r.stderr
    s = json.loads(r.stdout)
    assert s["command"] == "flexible simulate" and s["wrote"] == [str(first)] and first.exists()
    assert s["modes"] == ["shear", "bend", "squash", "hsquash"] and s["frames"] == 25
    assert s["lattice_action"] and s["key_action"] and s["controller"] == "POSES"
    second = tmp_path / "optimized.blend"
    args = ("optimize", str(first), "--trials", "3", "--trial-seconds", "2", "--seed", "3", "--json")
    r = run(*args, "--out", str(second))
    assert r.returncode == 0, r.stderr
    o = json.loads(r.stdout)
    assert o["trials"] == 3 and len(o["costs"]) == 3 and len(o["best_durations"]) == 2
    again = json.loads(run(*args, "--out", str(tmp_path / "again.blend")).stdout)
    assert again["costs"] == o["costs"] and again["best_poses"] == o["best_poses"]   # same seed, same result
    r = run("simulate", str(second), "--controller", "BEST", "--frames", "1", "13")
    assert r.returncode == 0, r.stderr
    assert "flexible simulate: 'Flexible Table'" in r.stdout and "wrote actions" in r.stdout


@pytest.mark.parametrize("args,needle", [
    (("simulate",), "--demo"),
    (("simulate", "nothing.blend"), "no such file"),
    (("optimize", "--demo", "--trials", "1", "--trial-seconds", "1", "--slope", "10", "--friction", "0.3",
      "--direction", "0", "0", "0"), "direction"),
])
def test_mistakes_are_one_line(tmp_path, args, needle):
    r = run(*args, "--out", str(tmp_path / "x.blend"))
    assert r.returncode == 2 and needle in r.stderr and "Traceback" not in r.stderr
