"""The same inputs on Blender's numpy (1.26, the bpy50 environment) and on numpy 2 give the same
results within 0.1 deg and 1 mm: the thesis's load experiments on the box squat and the closed
loop on the CMU clip (numpy_versions_runs.py), run here and, in a subprocess, by the other
environment's interpreter ($HUMANANIM_VENVS/numpy2/bin/python on numpy 1, .../bpy50/bin/python on
numpy 2), on the same humananim package. It runs from the numpy 1 side only (CI's numpy 2 lane
runs beside it); skipped, saying why, when the other interpreter is missing or does not import
this humananim.
"""

import os
import subprocess
import tempfile
from pathlib import Path

import numpy as np
import pytest

import humananim
from humananim.solver import rotations

from numpy_versions_runs import CASES, run

HERE = Path(__file__).resolve().parent
ANGLE_DEG = 0.1
DISTANCE_M = 1e-3


def other_interpreter():
    """(path, label) of the interpreter on the other numpy major version."""
    venvs = Path(os.environ.get("HUMANANIM_VENVS", HERE.parents[1] / ".venv"))
    label = "numpy2" if np.lib.NumpyVersion(np.__version__) < "2.0.0" else "bpy50"
    return venvs / label / "bin" / "python", label


@pytest.fixture(scope="module")
def both():
    """{case: ((rotations, heads) here, (rotations, heads) there)}, the other interpreter running
    in parallel with this one."""
    if np.lib.NumpyVersion(np.__version__) >= "2.0.0":
        # CI runs the numpy 2 lane beside the Blender 5.0 lane: one comparison, started from there
        pytest.skip("the comparison runs once, from Blender's numpy (numpy 1), against numpy 2")
    python, label = other_interpreter()
    if not python.exists():
        pytest.skip(f"no {label} interpreter at {python} (set HUMANANIM_VENVS to the folder of the "
                    f"environments): nothing to compare numpy {np.__version__} with")
    here_pkg = Path(humananim.__file__).resolve()
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(Path(humananim.__file__).parent.parent)] + [p for p in [os.environ.get("PYTHONPATH")] if p]))
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "other.npz"
        child = subprocess.Popen([str(python), str(HERE / "numpy_versions_runs.py"), str(out)], cwd=HERE, env=env,
                                 stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        try:
            mine = {case: run(case) for case in CASES}
        finally:
            log, _ = child.communicate()
        if child.returncode != 0:
            pytest.fail(f"the {label} interpreter failed:\n{log[-3000:]}")
        theirs = np.load(out)
        if Path(str(theirs["humananim"])) != here_pkg:
            pytest.skip(f"the {label} interpreter imports humananim from {theirs['humananim']}, not {here_pkg}")
        if str(theirs["numpy_version"]).split(".")[0] == np.__version__.split(".")[0]:
            pytest.skip(f"the {label} interpreter runs numpy {theirs['numpy_version']} too")
        return {case: (mine[case], (theirs[f"{case}.rotations"], theirs[f"{case}.heads"])) for case in CASES}


@pytest.mark.parametrize("case", CASES)
def test_results_agree_across_numpy_versions(both, case):
    (rot, heads), (rot2, heads2) = both[case]
    assert rot.shape == rot2.shape
    angle = np.degrees(rotations.angle_between(rot, rot2))
    distance = np.linalg.norm(heads - heads2, axis=-1)
    f, j = np.unravel_index(np.argmax(angle), angle.shape)
    print(f"{case}: largest difference {angle.max():.2e} deg (frame {f}, bone {j}), {distance.max():.2e} m")
    assert angle.max() < ANGLE_DEG, f"frame {f}, bone {j}: {angle.max():.3f} deg"
    assert distance.max() < DISTANCE_M
