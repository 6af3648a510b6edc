"""The runs test_numpy_versions.py compares across numpy versions: the thesis's load experiments
on the box squat (Oshita 2003, sec. 2.6; squat_scene.box_squat with 0, 8 and 15 kg in the hands,
as test_motion_control_experiments.py runs them) and the closed loop (Huang 1996) tracking the
CMU clip 131_01 with the default strength (as test_dynamics_closed_loop_rigs.py runs it).

Each run gives every bone's local rotation (F, J, 4) and world head position in metres (F, J, 3).
Run as a script (`python numpy_versions_runs.py OUT.npz [case ...]`) it saves them with the
numpy version and the path of the humananim package it ran, for another interpreter to compare.
"""

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))  # the scene helpers next to this file

CASES = ("squat_0kg", "squat_8kg", "squat_15kg", "cmu_closed_loop")


def run(case):
    """(rotations (F, J, 4), head positions (F, J, 3) in metres) of one case."""
    if case.startswith("squat_"):
        from humananim.solver.motion_control import ControlSettings, control
        from squat_scene import box_squat, hand_loads
        sk, tr = box_squat(rest=2.0)
        kg = float(case[len("squat_"):-len("kg")])
        res = control(sk, tr, ControlSettings(loads=hand_loads(sk, kg) if kg else ()))
    elif case == "cmu_closed_loop":
        from humananim.solver.dynamics import GroundModel, Settings, simulate
        from test_dynamics_closed_loop_rigs import load, lowest_points
        sk, tr = load("cmu_131_01")
        res = simulate(sk, tr, Settings(ground=GroundModel(height=float(lowest_points(sk, tr).min()))))
    else:
        raise ValueError(f"unknown case {case!r}")
    out = res.trajectories
    heads = out.world_frames(sk)[..., :3, 3] * sk.unit_scale
    return np.asarray(out.rotations, float), heads


def main(argv):
    import humananim
    path, cases = argv[0], argv[1:] or CASES
    arrays = {"numpy_version": np.array(np.__version__), "humananim": np.array(str(Path(humananim.__file__).resolve()))}
    for case in cases:
        arrays[f"{case}.rotations"], arrays[f"{case}.heads"] = run(case)
    np.savez(path, **arrays)


if __name__ == "__main__":
    main(sys.argv[1:])
