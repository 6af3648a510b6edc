#!/usr/bin/env python3
"""Speed of Oshita's dynamic motion control loop (solver/motion_control/controller.py).

    python3 benchmarks/control.py              # a table
    python3 benchmarks/control.py --json       # one JSON object, units in the names
    python3 benchmarks/control.py --repeats 5  # best of 5 bakes per case (default 3)

CPU milliseconds (time.process_time: the machine is shared, wall time is not the loop's) per
control step, median and worst over the steps of a bake (one step per frame), the best of
`--repeats` bakes, for the 18-segment, 39-DOF Oshita-like figure standing still for 2 s at 30 fps
with the feet planted (tracking, constrained legs, dynamic control's early exit), the same holding
15 kg (comfort control acting), and for the CMU clip 131_01 (31 bones, 120 fps, dynamic control
acting on about a third of the steps); the real-time factor at 30 Hz (seconds of motion per CPU
second with one mean step per 1/30 s), and the whole bake's (set-up included, at the clip's own
frame rate). The thesis: 0.8 ms average, 3.1 ms worst per step (C++, 800 MHz Pentium III).

Measured with CPU time, best of 3-4 bakes, the previous implementation (commit 8b3ebab) baked
alternately in the same process (quiet minute, load average ~1). OpenBLAS's thread pool spins
after some calls and that spinning is counted as CPU time, for both implementations alike, so the
table gives single-threaded BLAS (OPENBLAS_NUM_THREADS=1) and the default pool:

                                   before           now              issue's aim
  OPENBLAS_NUM_THREADS=1
  figure standing, median / worst  1.01 / 1.68 ms   0.57 / 1.08 ms   median < 0.5 ms
  figure 15 kg, median / worst     1.06 / 2.09 ms   0.62 / 1.35 ms
  CMU 131_01, median / worst       1.94 / 14.1 ms   0.96 / 5.26 ms   median < 0.5 ms
  real-time factor at 30 Hz        33 / 31 / 12.6   57 / 52 / 28.6   > 50
  whole bake, CPU s (CMU, 200 fr)  0.96 s           0.42 s
  default OpenBLAS threads
  figure standing, median          2.07 ms          1.22 ms
  CMU 131_01, median / worst       2.05 / 17.2 ms   0.92 / 5.35 ms
  real-time factor at 30 Hz        15.7 / 11.8      27 / 29.5        (figure / CMU)

How (outputs equal to the previous implementation within 1e-11, every control decision the same:
tests/solver/test_motion_control_reference.py): the step is bound by the count of numpy calls
(1-5 us each on this machine, whatever the array size), so the work is fused into fewer calls:
tracking errors on per-frame precomputed target matrices; cached frames, motion subspace,
composite inertias, lazy world inertias and velocity terms per configuration; inverse dynamics
whose subtree wrenches carry the ground reaction directly; both legs' Jacobians in batched
products on their own DOFs (one damped least-squares solve per right-hand side: a matrix of
right-hand sides woke OpenBLAS's thread pool, whose spinning cost more than it saved); required
torques, support polygon and balance error remembered per control state; LAPACK gesdd/gesv
instead of numpy.linalg; plain floats for 2- and 3-vectors (ZMP, MMP, hull, foot wrenches); the
set-up's forward kinematics of every frame in one batched pass (the input's sole points shared by
the floor, the skate removal, the rolling anchor and the input allowance). Function calls per step
(Python and C, operators not counted; median): figure 731 -> 386, CMU 1390 -> 629. What remains
(two forward kinematics, two manifold integrations, one inverse dynamics, the tracking error,
strength, both legs' projections, the collision pass) keeps the median just above the issue's
0.5 ms for the figure; the CMU rig (23 bodies, 72 DOFs) also runs dynamic control (passive,
comfort and balance, several inverse-dynamics passes and pseudo-inverses) on a third of its steps
and stays near 1 ms. Reaching 0.5 ms there needs the required torques as one linear map per
step (tau = tau0 + T a, built once per state) instead of an inverse-dynamics pass per candidate,
or compiled code.
"""

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests" / "solver"))

from humananim.solver.dynamics import oshita_figure  # noqa: E402
from humananim.solver.motion_control import controller as ctl  # noqa: E402
from humananim.solver.trajectories import Trajectories  # noqa: E402


def standing(sk, seconds=2.0, fps=30.0):
    n = int(round(seconds * fps)) + 1
    rot = np.zeros((n, sk.joint_count, 4))
    rot[..., 0] = 1.0
    return Trajectories(np.arange(n) + 1.0, fps, rot, np.zeros((n, sk.joint_count, 3)), np.eye(4))


def step_times(sk, tr, settings):
    """CPU ms of every control step of one bake, the bake's CPU seconds (set-up included), and
    the result."""
    times = []
    original = ctl._Loop.step

    def timed(self, *args, **kw):
        t0 = time.process_time()
        original(self, *args, **kw)
        times.append((time.process_time() - t0) * 1e3)

    ctl._Loop.step = timed
    try:
        t0 = time.process_time()
        res = ctl.control(sk, tr, settings)
        total = time.process_time() - t0
    finally:
        ctl._Loop.step = original
    return np.array(times), total, res


def measure(repeats=3):
    out = {}
    fig = oshita_figure()
    tr = standing(fig)
    cases = [("figure_standing", fig, tr, ctl.ControlSettings()),
             ("figure_15kg", fig, tr, ctl.ControlSettings(loads=(ctl.Load("hand.L", 7.5), ctl.Load("hand.R", 7.5))))]
    try:
        from test_dynamics_closed_loop_rigs import load
        sk, cmu = load("cmu_131_01")
        cases.append(("cmu", sk, cmu, ctl.ControlSettings()))
    except Exception as exc:  # the fixture is in the repository's tests
        out["cmu_error"] = str(exc)
    for name, sk, motion, settings in cases:
        runs = [step_times(sk, motion, settings) for _ in range(max(1, repeats))]
        ms = [r[0] for r in runs]
        duration = (motion.frame_count - 1) / motion.fps
        out[f"{name}_step_median_ms"] = float(min(np.median(m) for m in ms))
        out[f"{name}_step_worst_ms"] = float(min(m.max() for m in ms))
        out[f"{name}_step_mean_ms"] = float(min(m.mean() for m in ms))
        out[f"{name}_steps"] = len(ms[0])
        out[f"{name}_fell"] = bool(runs[0][2].falling.any())
        # at 30 Hz: one (mean) step per 1/30 s of motion
        out[f"{name}_realtime_factor_30hz"] = 1.0 / (out[f"{name}_step_mean_ms"] * 1e-3 * 30.0)
        out[f"{name}_bake_cpu_s"] = float(min(r[1] for r in runs))
        out[f"{name}_bake_realtime_factor"] = duration / out[f"{name}_bake_cpu_s"]
    return out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--repeats", type=int, default=3, help="bakes per case (the best is reported)")
    args = parser.parse_args(argv)
    out = measure(args.repeats)
    if args.json:
        print(json.dumps({k: (round(v, 4) if isinstance(v, float) else v) for k, v in out.items()}))
    else:
        for k, v in out.items():
            print(f"{k:40s} {v:.3f}" if isinstance(v, float) else f"{k:40s} {v}")


if __name__ == "__main__":
    main()
