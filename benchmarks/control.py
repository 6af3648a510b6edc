#!/usr/bin/env python3
"""Speed of Oshita's dynamic motion control loop (solver/motion_control/controller.py), beside the
loop as it was before it was split into parts (commit BASELINE, extracted from git into a
temporary package for the run).

    python3 benchmarks/control.py              # a table
    python3 benchmarks/control.py --json       # one JSON object (writes benchmarks/results/control.json)
    python3 benchmarks/control.py --repeats 5  # best of 5 bakes per case (default 3)
    python3 benchmarks/control.py --sample     # the CMU cases only, one bake each per implementation
    python3 benchmarks/control.py --tricks     # also the current code with every "control" trick of
                                               # benchmarks/microopt.py switched on (keys tricks_...)

What is measured: CPU milliseconds (time.process_time: the machine is shared, wall time is not the
loop's) per control step, median and worst over the steps of a bake (one step per frame while
standing), the best of `--repeats` bakes, for
- the 18-segment, 39-DOF Oshita-like figure standing still for 2 s at 30 fps with the feet planted
  (tracking, constrained legs, dynamic control's early exit), and the same holding 15 kg (comfort
  control acting);
- the CMU clip 131_01 (31 bones, 120 fps, dynamic control acting on about a third of the steps),
  with the default prediction of the planted legs' re-solve and with the exact re-solve;
- the CMU clip knocked over by a 150 N s push sideways at 0.5 s (a fallen body on the ground for
  most of the bake): its steps, and the whole bake's real-time factor beside the unpushed clip's,
  which is the claim "bake speed independent of falls" (a fallen body takes the steps its
  contact spheres' speed needs, _Loop._fall_steps).
Both implementations bake every case in turn (baseline, current, baseline, ...), so a swing of the
machine's load falls on both; per case the claim is the current median step over the baseline's
(aim: within 10 %, ratio <= 1.1). Per case the real-time factor at 30 Hz (seconds of motion per CPU second with one mean step per
1/30 s) and the whole bake's (set-up included, at the clip's own frame rate). The thesis: 0.8 ms
average, 3.1 ms worst per step (C++, 800 MHz Pentium III). The issue's aims: median step < 0.5 ms
and a real-time factor > 50 at 30 Hz. Compare implementations side by side in the same minutes
(absolute times on a shared host swing 2-3x with load: machine_speed gives numpy's a+b then).
Run it with OPENBLAS_NUM_THREADS=1: on a busy 2-core host OpenBLAS's spinning threads made every
knocked-over step of both implementations 20x slower (process_time counts their CPU).

Where the current step's time over the baseline's goes (issue #27 item 3, profiled part by part,
both implementations, standing and CMU steps):
- the baseline held about 20 micro-optimisations in Dynamic Control (direct LAPACK calls, products
  with ones for row sums, take for fancy indexing, a preallocated expand buffer, ...) that
  benchmarks/microopt.py judged one by one under 5 % of a bake, so the product code holds their
  plain formulas (the project's rule). Together they are about a tenth of a step: `--tricks`
  bakes the current code with every "control" trick of microopt.py switched on as a third
  implementation in the same run (tricks_<case>_over_baseline_median);
- new work by design: the planted legs' exact re-solve (cmu_exact_resolve, foot_iterations=1, not
  the default) takes the full forward kinematics, which turns a two-axis foot's parent-side axis,
  instead of the baseline's feet-only chain, which did not; np.errstate around the integration
  instead of the private np.seterrobj (about 2 us, under 0.5 % of a step); a lifted foot's leg
  held by the inverse kinematics over its release (feet.RELEASE_TIME): on the CMU walk 57 of the
  203 steps with a planted foot hold a second leg the baseline had let go (its factorisation and
  projections, about 25 us in such a step); the modes' memory (under 1 us); a gripped load's body
  per grip step (built in the steps that take the load up: not in the median).
"""

import argparse
import importlib
import json
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests" / "solver"))

from humananim.solver.dynamics import oshita_figure  # noqa: E402
from humananim.solver.motion_control import controller as ctl  # noqa: E402
from humananim.solver.trajectories import Trajectories  # noqa: E402
from machine import numpy_add_us  # noqa: E402  (the contract's machine-speed indicator)

BASELINE = "a662106"  # the controller as one 1,500-line module, before its split into parts
REPO = Path(__file__).resolve().parent.parent


def baseline_controller(workdir):
    """The baseline commit's solver package, extracted with `git archive` into `workdir` as the
    package humananim_baseline; its controller module."""
    data = subprocess.run(["git", "-C", str(REPO), "archive", BASELINE, "solver"], check=True,
                          capture_output=True).stdout
    root = Path(workdir) / "humananim_baseline"
    root.mkdir()
    (root / "__init__.py").write_text("")
    archive = Path(workdir) / "solver.tar"
    archive.write_bytes(data)
    with tarfile.open(archive) as tar:
        tar.extractall(root)
    sys.path.insert(0, str(workdir))
    return importlib.import_module("humananim_baseline.solver.motion_control.controller")


def loop_class(module):
    return getattr(module, "ControlLoop", None) or module._Loop


def standing(sk, seconds=2.0, fps=30.0):
    n = int(round(seconds * fps)) + 1
    rot = np.zeros((n, sk.joint_count, 4))
    rot[..., 0] = 1.0
    return Trajectories(np.arange(n) + 1.0, fps, rot, np.zeros((n, sk.joint_count, 3)), np.eye(4))


def step_times(impl, sk, tr, settings):
    """CPU ms of every control step of one bake by the controller module `impl`, the bake's CPU
    seconds (set-up included), and the result."""
    times = []
    cls = loop_class(impl)
    original = cls.step

    def timed(self, *args, **kw):
        t0 = time.process_time()
        original(self, *args, **kw)
        times.append((time.process_time() - t0) * 1e3)

    cls.step = timed
    try:
        t0 = time.process_time()
        res = impl.control(sk, tr, settings)
        total = time.process_time() - t0
    finally:
        cls.step = original
    return np.array(times), total, res


def cases(impl, sample=False):
    """(name, skeleton, motion, settings) per case, with the settings classes of `impl`."""
    out = []
    if not sample:
        fig = oshita_figure()
        tr = standing(fig)
        out += [("figure_standing", fig, tr, impl.ControlSettings()),
                ("figure_15kg", fig, tr, impl.ControlSettings(loads=(impl.Load("hand.L", 7.5), impl.Load("hand.R", 7.5))))]
    from test_dynamics_closed_loop_rigs import load
    sk, cmu = load("cmu_131_01")
    out.append(("cmu", sk, cmu, impl.ControlSettings()))
    if not sample:
        # the planted legs' exact position re-solve after the step (the default predicts it)
        out.append(("cmu_exact_resolve", sk, cmu, impl.ControlSettings(foot_iterations=1)))
    chest = sk.roles.chain("spine")[-1]
    push = impl.Impulse(0.5, chest, (0.0, 0.1, 0.0), (0.0, 1.0, 0.0), 150.0)
    out.append(("cmu_knocked_over", sk, cmu, impl.ControlSettings(impulses=(push,))))
    return out


def figures(name, runs, motion, out):
    ms = [r[0] for r in runs]
    duration = (motion.frame_count - 1) / motion.fps
    out[f"{name}_step_median_ms"] = float(min(np.median(m) for m in ms))
    out[f"{name}_step_worst_ms"] = float(min(m.max() for m in ms))
    out[f"{name}_step_mean_ms"] = float(min(m.mean() for m in ms))
    out[f"{name}_steps"] = len(ms[0])
    out[f"{name}_fell"] = bool(runs[0][2].falling.any())
    out[f"{name}_frames_falling"] = int(runs[0][2].falling.sum())
    # at 30 Hz: one (mean) step per 1/30 s of motion
    out[f"{name}_realtime_factor_30hz"] = 1.0 / (out[f"{name}_step_mean_ms"] * 1e-3 * 30.0)
    out[f"{name}_bake_cpu_s"] = float(min(r[1] for r in runs))
    out[f"{name}_bake_realtime_factor"] = duration / out[f"{name}_bake_cpu_s"]


class WithTricks:
    """The current controller with every "control" trick of benchmarks/microopt.py switched on for
    the bakes it runs (the product's versions put back after each)."""

    def __init__(self):
        import importlib.util
        spec = importlib.util.spec_from_file_location("benchmarks_microopt", Path(__file__).parent / "microopt.py")
        micro = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(micro)
        self.tricks = [t for t in micro.tricks() if t.capability == "control"]
        self.ControlLoop = ctl.ControlLoop
        for name in ("ControlSettings", "Load", "Impulse"):
            setattr(self, name, getattr(ctl, name))

    def control(self, *args):
        held = [(owner, attr, getattr(owner, attr)) for t in self.tricks for owner, attr in t.targets]
        try:
            for t in self.tricks:
                t.use("trick")
            return ctl.control(*args)
        finally:
            for owner, attr, value in held:
                setattr(owner, attr, value)


def measure(repeats=3, sample=False, tricks=False):
    """The current controller's figures (keys <case>_...), the baseline's (baseline_<case>_...) and
    per case the ratio of their median and mean steps (<case>_over_baseline_median, _mean)."""
    out = {"baseline_commit": BASELINE}
    with tempfile.TemporaryDirectory() as tmp:
        try:
            base = baseline_controller(tmp)
        except Exception as exc:  # no git history (an installed copy): the current code alone
            base = None
            out["baseline_error"] = str(exc)
        impls = [("", ctl)] + ([("baseline_", base)] if base is not None else [])
        if tricks:
            impls.append(("tricks_", WithTricks()))
        todo = {prefix: cases(impl, sample) for prefix, impl in impls}
        for i, (name, sk, motion, _) in enumerate(todo[""]):
            runs = {prefix: [] for prefix, _ in impls}
            for _ in range(max(1, repeats)):  # interleaved: a swing of the load falls on both
                for prefix, impl in impls[::-1]:
                    runs[prefix].append(step_times(impl, sk, motion, todo[prefix][i][3]))
            for prefix, _ in impls:
                figures(prefix + name, runs[prefix], motion, out)
            if base is not None:
                for stat in ("median", "mean"):
                    out[f"{name}_over_baseline_{stat}"] = (out[f"{name}_step_{stat}_ms"]
                                                           / out[f"baseline_{name}_step_{stat}_ms"])
                if tricks:
                    out[f"tricks_{name}_over_baseline_median"] = (out[f"tricks_{name}_step_median_ms"]
                                                                  / out[f"baseline_{name}_step_median_ms"])
    return out


def contract(out):
    """The benchmarks' JSON object: claims with their aims, then every figure."""
    def claim(text, key, unit, aim=None, met=None):
        value = out.get(key)
        return {"claim": text, "value": None if value is None else round(float(value), 4), "unit": unit,
                "aim": aim, "met": None if value is None or met is None else bool(met(value))}

    claims = [
        claim("figure standing: median control step", "figure_standing_step_median_ms", "ms", "< 0.5 ms",
              lambda v: v < 0.5),
        claim("CMU 131_01: median control step", "cmu_step_median_ms", "ms", "< 0.5 ms", lambda v: v < 0.5),
        claim("CMU 131_01: real-time factor at 30 Hz", "cmu_realtime_factor_30hz", "x", "> 50", lambda v: v > 50),
    ]
    for name in ("figure_standing", "figure_15kg", "cmu", "cmu_exact_resolve", "cmu_knocked_over"):
        if f"{name}_over_baseline_median" in out:
            claims.append(claim(f"{name}: median control step over the baseline's ({BASELINE}), same run",
                                f"{name}_over_baseline_median", "ratio", "<= 1.1 (within 10 %)",
                                lambda v: v <= 1.1))
    if "cmu_knocked_over_bake_realtime_factor" in out and out.get("cmu_bake_realtime_factor"):
        out["knocked_over_over_unpushed_bake_speed"] = (out["cmu_knocked_over_bake_realtime_factor"]
                                                        / out["cmu_bake_realtime_factor"])
        claims.append(claim("CMU knocked over: whole bake's speed over the unpushed bake's",
                            "knocked_over_over_unpushed_bake_speed", "ratio",
                            "bake speed independent of falls: >= 0.5", lambda v: v >= 0.5))
    return {"benchmark": "control", "date": time.strftime("%Y-%m-%d"),
            "machine_speed": {"numpy_add_us": round(numpy_add_us(), 4)}, "claims": claims,
            **{k: (round(v, 4) if isinstance(v, float) else v) for k, v in out.items()}}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--repeats", type=int, default=3, help="bakes per case (the best is reported)")
    parser.add_argument("--sample", action="store_true", help="the CMU cases only, one bake each")
    parser.add_argument("--tricks", action="store_true",
                        help="also the current code with microopt.py's control tricks switched on")
    args = parser.parse_args(argv)
    out = measure(1 if args.sample else args.repeats, sample=args.sample, tricks=args.tricks)
    if args.json:
        report = contract(out)
        print(json.dumps(report))
        results = Path(__file__).resolve().parent / "results"
        results.mkdir(exist_ok=True)
        (results / "control.json").write_text(json.dumps(report, indent=1) + "\n")
    else:
        for k, v in out.items():
            print(f"{k:40s} {v:.3f}" if isinstance(v, float) else f"{k:40s} {v}")


if __name__ == "__main__":
    main()
