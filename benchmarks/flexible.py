#!/usr/bin/env python3
"""Speed of the flexible-character solver (solver/flexible, issue 8).

    python3 benchmarks/flexible.py          # a table
    python3 benchmarks/flexible.py --json   # one JSON object (also written to benchmarks/results/flexible.json)

CPU milliseconds (best of a few repeats, so other load on a shared machine counts as little as
possible) of
- the thesis workload: the table of 11 points and 4 modes, 1,200 steps at dt 0.01 (12 s), under
  pose control on the ground (the thesis: 0.12 s CPU per trial in 1995; the aim here: < 20 ms),
  per integrator; the explicit thesis scheme diverges under pose control at this step, so it
  is timed on the passive table dropped on the ground;
- the same semi-implicit workload by the readable reference step (Simulator.reference_run) beside
  the fused kernel (Simulator.run), in the same run: the kernel's speed-up, the measure that keeps
  it (a speed trick stays only where it saves at least 5 % of the capability's time);
- a 200-point, 8-mode character (B-spline lattice) dropped on the ground, 1,200 steps at 0.01;
and CPU seconds of 60 annealing trials of 12 s each (the thesis's experiment, Fig. 5.3), with
microseconds per step alongside.

The floor of a step, printed beside the workload (floor_*): what a step of the thesis table can't
do without, timed alone on buffers of its sizes: the Cholesky solve, the rigid motion of the
floating frame on floats, and minimal_step_floor() (only the operations no numpy step can do
without, each fused as far as one product allows). numpy_add_us (a + b on two 1,000-float arrays)
is the machine-speed indicator: every absolute figure scales with it.
"""

import argparse
import datetime
import json
import time
from operator import mul
from pathlib import Path

import numpy as np
from machine import numpy_add_us, numpy_op_us

from humananim.solver.flexible import Ground, ModeGains, Settings, Simulator
from humananim.solver.flexible.control import AnnealSettings, CostSpec, anneal
from humananim.solver.flexible.demo import blob_body, table_body
from humananim.solver.flexible.simulate import Controller, State
from humananim.solver.progress import run_to_end


def cpu_ms(fn, repeat=3):
    best = float("inf")
    for _ in range(repeat):
        t0 = time.process_time()
        fn()
        best = min(best, time.process_time() - t0)
    return best * 1e3


def table_controller(body):
    active = [0, 1, 2]
    m = body.modal_masses()[active]
    w = 2 * np.pi * 4.0
    return Controller(active, [[0.4, 0.4, 0.4], [-0.4, -0.4, -0.4]], [0.3, 0.3], m * w * w, 1.6 * w * m)


def thesis_workload():
    body = table_body(count=11)
    gains = ModeGains.from_frequency(body, 3.0, 0.3)
    start = State.rest(4, t=(0, 0, 0.3))
    out = {}
    for integrator in ("implicit", "semi_implicit"):
        sim = Simulator(body, gains, Settings(dt=0.01, integrator=integrator, ground=Ground.flat(), cond_every=0),
                        table_controller(body))
        ms = cpu_ms(lambda: sim.run(start, 12.0))
        out[f"thesis_workload_{integrator}_ms"] = ms
        out[f"thesis_workload_{integrator}_us_per_step"] = ms / 1.2
    drop = State.rest(4, t=(0, 0, 0.5))
    sim = Simulator(body, gains, Settings(dt=0.01, integrator="thesis", ground=Ground.flat(), cond_every=0))
    ms = cpu_ms(lambda: sim.run(drop, 12.0))
    out["thesis_workload_thesis_scheme_passive_ms"] = ms
    out["thesis_workload_thesis_scheme_passive_us_per_step"] = ms / 1.2
    return out


def step_floor(steps=1200):
    """What a step of the thesis table can't do without, per step (us): the Cholesky solve of its
    10 x 10 system (one LAPACK call, as the kernel makes it), the rigid motion of the floating frame
    (plain Python floats, as the kernel does it), and one small numpy operation (the price of
    every other operation of the step, however small)."""
    from humananim.solver.flexible.kernel import rigid_move
    from humananim.solver.flexible.lapack import CholeskySolver
    rng = np.random.default_rng(0)
    a = rng.normal(size=(10, 10))
    spd = a @ a.T + 10 * np.eye(10)
    A, b = np.empty((10, 10)), np.empty(10)
    solver = CholeskySolver(A, b)

    def solves():
        for _ in range(steps):
            np.copyto(A, spd)
            b.fill(1.0)
            solver.solve()

    def moves():
        q, t = [1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0]
        mv = [1e-3, 2e-3, 0.0, 1e-3, 0.0, 2e-3]
        for _ in range(steps):
            rigid_move(q, t, mv)

    per = lambda fn: cpu_ms(fn, repeat=5) * 1e3 / steps
    return {"floor_solve_us_per_step": per(solves), "floor_rigid_move_us_per_step": per(moves),
            "floor_minimal_step_us": minimal_step_floor(steps), "numpy_small_op_us": numpy_op_us(),
            "aim_us_per_step": 20.0e3 / steps}


def minimal_step_floor(steps=1200, points=11, modes=4):
    """A lower bound of a semi-implicit step of the thesis table on the ground (us): only what no
    numpy step can do without, each fused as far as one product allows, on buffers of the real
    sizes: the body points and their Jacobian from gamma, into the ground's frame, positions and
    velocities, the penalty springs and dampers with the inertial terms (their rotation written
    into the product's matrix from floats), the touching mask, the one-sided normal force, the
    Coulomb cap (its magnitude, the sliding mask, the scale), the forces, the generalised forces
    with the mode forces, the system matrix, the Cholesky solve, the consumed power, the state
    update and the rigid motion. It leaves out what the real step also does (the anchors' sliding
    and setting, the joint-limit and divergence checks, the controller's targets, the branches that
    choose among them), so the real step costs more than this."""
    from humananim.solver.flexible.kernel import rigid_move
    from humananim.solver.flexible.lapack import CholeskySolver
    P, n = points, 6 + modes
    rng = np.random.default_rng(0)
    GY = rng.normal(size=(1 + modes, 3 * P * (n + 1)))           # G and y, polynomials in gamma
    c = np.ones(1 + modes)
    Gb = np.empty(3 * P * (n + 1))
    Gb2, Rq, Gq = Gb.reshape(3, -1), np.eye(3), np.empty((3, P * (n + 1)))
    Gq2 = Gq.reshape(3 * P, n + 1)[:, :n]
    U, VY = rng.normal(size=(3, n + 1)), np.empty((3, 3 * P))
    FW, table, fB = rng.normal(size=(5, 9)), rng.normal(size=(9, P)), np.empty((5, P))
    touch, ftn, F, W = np.empty(P), np.empty(P), np.empty((3, P)), rng.random((3, P))
    slide, scale, cap = np.empty(P, bool), np.ones(P), np.full(P, 0.5)
    FWflat = FW.reshape(-1)
    WG, A, x = np.empty((3 * P, n)), np.empty((n, n)), np.empty(n)
    spd = 10.0 * np.eye(n)
    solver = CholeskySolver(A, x)
    T, ZX, ZM = 1e-3 * rng.normal(size=(n + 6, 2 * n)), np.ones(2 * n), np.empty(n + 6)

    GqT, Wc = Gq.reshape(3 * P, n + 1).T, W.reshape(-1, 1)     # views made once, as the kernel does
    f, fn, s, fx, fy, Ff = fB[:3], fB[2], fB[4], fB[0], fB[1], F.reshape(-1)
    mv = ZM[n:]

    def run():
        q, t = [1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0]
        consumed = 0.0
        for _ in range(steps):
            c.dot(GY, out=Gb)
            Rq.dot(Gb2, out=Gq)
            U.dot(GqT, out=VY)
            FWflat[13:45] = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, t[2], -t[1], 0.0, 0.0, 0.0, 0.0, 0.0, -t[2],
                             0.0, t[0], 0.0, 0.0, 0.0, 0.0, 0.0, t[1], -t[0], 0.0, -t[0], -t[1],
                             -t[2], -t[2], t[2], 0.0, 0.0, -9.81]
            FW.dot(table, out=fB)
            np.less(s, 0.0, out=touch)
            np.maximum(fn, 0.0, out=fn)
            np.multiply(f, touch, out=f)
            np.hypot(fx, fy, out=ftn)
            np.greater(ftn, cap, out=slide)
            np.divide(cap, ftn, out=scale, where=slide)
            np.multiply(f, scale, out=f)
            np.multiply(f, W, out=F)
            Ff.dot(Gq2, out=x)
            np.multiply(Gq2, Wc, out=WG)
            Gq2.T.dot(WG, out=A)
            np.copyto(A, spd)                                  # keep it positive definite
            consumed += sum(map(abs, map(mul, x.tolist()[6:], q)))
            solver.solve()
            T.dot(ZX, out=ZM)
            rigid_move(q, t, mv.tolist())

    return cpu_ms(run, repeat=7) * 1e3 / steps


def big_character():
    body = blob_body(points=200, modes=8)
    gains = ModeGains.from_frequency(body, 3.0, 0.3)
    start = State.rest(8, t=(0, 0, 0.6))
    out = {}
    for integrator in ("implicit", "semi_implicit"):
        sim = Simulator(body, gains, Settings(dt=0.01, integrator=integrator, ground=Ground.flat(), cond_every=0))
        ms = cpu_ms(lambda: sim.run(start, 12.0), repeat=2)
        out[f"points200_modes8_{integrator}_ms"] = ms
        out[f"points200_modes8_{integrator}_us_per_step"] = ms / 1.2
    return out


def annealing(trials=60, step=0.02):
    body = table_body(count=11)
    gains = ModeGains.from_frequency(body, 3.0, 0.3)
    settings = Settings(dt=step, integrator="semi_implicit", ground=Ground.flat(), cond_every=0)
    ctl = table_controller(body)
    start = State.rest(4, t=(0, 0, 0.3))
    t0 = time.process_time()
    result = run_to_end(anneal(lambda c: Simulator(body, gains, settings, c), ctl, start, CostSpec("energy_distance"),
                           AnnealSettings(trials=trials, seed=1)))
    seconds = time.process_time() - t0
    steps = trials * int(round(12.0 / step))
    return {f"annealing_{trials}_trials_s": seconds, "annealing_trial_step_s": step,
            "annealing_us_per_step": seconds / steps * 1e6, "annealing_accepted": result.accepted,
            "annealing_best_distance_m": result.measures["distance_m"]}


def kernel_against_reference(repeat=3):
    """The semi-implicit thesis workload by the fused kernel and by the reference step, CPU ms."""
    body = table_body(count=11)
    gains = ModeGains.from_frequency(body, 3.0, 0.3)
    start = State.rest(4, t=(0, 0, 0.3))
    sim = Simulator(body, gains, Settings(dt=0.01, integrator="semi_implicit", ground=Ground.flat(), cond_every=0),
                    table_controller(body))
    kernel = cpu_ms(lambda: sim.run(start, 12.0), repeat)
    reference = cpu_ms(lambda: sim.reference_run(start, 12.0), repeat)
    return {"kernel_ms": kernel, "reference_step_ms": reference, "kernel_speedup": reference / kernel}


def claims(out, trials):
    aim_ms = 20.0
    return [
        {"claim": "thesis workload (11 points, 4 modes, 1,200 semi-implicit steps under pose control on the ground)",
         "value": out["thesis_workload_semi_implicit_ms"], "unit": "ms CPU",
         "aim": f"< {aim_ms:g} ms (the thesis: 120 ms in 1995)",
         "met": out["thesis_workload_semi_implicit_ms"] < aim_ms},
        {"claim": "the fused kernel's speed-up over the readable reference step (same workload, same run)",
         "value": out["kernel_speedup"], "unit": "x", "aim": ">= 1.05 (a kept speed trick saves >= 5 %)",
         "met": out["kernel_speedup"] >= 1.05},
        {"claim": "200 points, 8 modes dropped on the ground, 1,200 semi-implicit steps",
         "value": out["points200_modes8_semi_implicit_ms"], "unit": "ms CPU", "aim": None, "met": None},
        {"claim": f"{trials} annealing trials of 12 s (Fig. 5.3)", "value": out[f"annealing_{trials}_trials_s"],
         "unit": "s CPU", "aim": None, "met": None},
    ]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true")
    parser.add_argument("--trials", type=int, default=60)
    args = parser.parse_args()
    out = {}
    out.update(thesis_workload())
    out.update(kernel_against_reference())
    out.update(step_floor())
    out.update(big_character())
    out.update(annealing(args.trials))
    out = {k: round(v, 3) if isinstance(v, float) else v for k, v in out.items()}
    if args.json:
        result = {"benchmark": "flexible", "date": datetime.date.today().isoformat(),
                  "machine_speed": {"numpy_add_us": round(numpy_add_us(), 4)}, "claims": claims(out, args.trials), **out}
        text = json.dumps(result, indent=1)
        print(text)
        folder = Path(__file__).resolve().parent / "results"
        folder.mkdir(exist_ok=True)
        (folder / "flexible.json").write_text(text + "\n")
        return
    for key, value in out.items():
        print(f"{key:45s} {value}")


if __name__ == "__main__":
    main()
