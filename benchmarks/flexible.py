#!/usr/bin/env python3
"""Speed of the flexible-character solver (solver/flexible, issue 8).

    python3 benchmarks/flexible.py          # a table
    python3 benchmarks/flexible.py --json   # one JSON object, units in the names

CPU milliseconds (best of a few repeats: other load on a shared machine counts as little as
possible) of
- the thesis workload: the table of 11 points and 4 modes, 1,200 steps at dt 0.01 (12 s), under
  pose control on the ground (the thesis: 0.12 s CPU per trial in 1995; the aim here: < 20 ms),
  per integrator; the explicit thesis scheme diverges under pose control at this step, so it
  is timed on the passive table dropped on the ground;
- a 200-point, 8-mode character (B-spline lattice) dropped on the ground, 1,200 steps at 0.01;
and CPU seconds of 60 annealing trials of 12 s each (the thesis's experiment, Fig. 5.3), with
microseconds per step alongside.

Measured on the shared 2-CPU machine (load 2.5-6 from other jobs: the spread below is that load),
before -> after the fused kernel (solver/flexible/kernel.py), same runs of this script:
    thesis workload, semi-implicit     215-460 us/step (260-550 ms) -> 40-80 us/step (48-96 ms)
    thesis workload, implicit          500-1000 us/step (0.6-1.2 s) -> 85-110 us/step (100-131 ms)
    thesis workload, thesis scheme     140-160 us/step (170-190 ms) -> 37-47 us/step (45-56 ms)
    200 points, 8 modes, semi-implicit  550-660 us/step (0.66-0.79 s) -> 150-180 us/step (0.18-0.22 s)
    200 points, 8 modes, implicit       900-1320 us/step (1.1-1.6 s)  -> 270-325 us/step (0.33-0.39 s)
    60 annealing trials                 13.7 s                        -> 1.9-2.9 s (same result)
Then fewer calls a step (kernel.py: 35 -> 27 for a semi-implicit step on the ground; the solve in
place; - M du / h of the corrector inside the velocity product; for many points M from its
polynomial in gamma and the ground's share of A from the touching points alone). Same trajectories
(tests/solver/test_flexible_kernel_paths.py). Measured in one process, the previous kernel and
this one taking turns (CPU time, best of 8; the machine at load 15-20 on 2 CPUs, so every figure
is about twice what it is on a quiet machine, and the ratio is the thing to read):
    thesis workload, semi-implicit      60-107 ms -> 49-92 ms     x1.17-1.23
    thesis workload, implicit          141-229 ms -> 102-183 ms   x1.25-1.39
    thesis workload, thesis scheme      57-99 ms  -> 51-83 ms     x1.12-1.19
    200 points, 8 modes, semi-implicit  189-214 ms -> 164-188 ms  x1.00-1.31
    200 points, 8 modes, implicit       158 -> 134 ms for 4 s simulated (same Simulator)  x1.18
    one 12 s annealing trial (dt 0.02)  42.4 -> 28.9 ms           x1.47
The aim of 20 ms (16 us a step) is still not reached with numpy alone, and can't be by trimming
calls: at this load a step's floor is its numpy calls (27, ~1 us each however small the arrays),
the LAPACK Cholesky solve (dposv in place: ~7 us, most of it the factorisation of the 10 x 10
matrix itself: calling LAPACK through ctypes was measured no faster) and the rigid motion in
plain Python (~100 float operations, ~7 us); half of each on a quiet machine. The floating-frame invariants (M(gamma) from
constant sums over the points) replace the one product that gives M with another for 11 points;
they pay off for many points, where they are used.
The step's floor, printed beside the workload (floor_*, numpy_add_us), measured with the thesis
workload in one run (2026-11-22, a quiet guest but 25-37 % of its CPU stolen by the host, so every
figure about twice a quiet host's): the Cholesky solve 4.8 us and the rigid motion 3.9 us a step,
one numpy call 1.09 us (np.add on 33 floats), against the aim's 16.7 us a step; the
semi-implicit workload 91 ms (76 us a step).

The floor of a whole step, printed as floor_minimal_step_us: minimal_step_floor() runs, on buffers
of the table's sizes, only what no numpy step can do without (its docstring lists them: 17 numpy
operations fused as far as one product allows, the LAPACK solve, the rigid motion in floats), and
leaves out part of what the real step does. In one run (2026-11-22 evening, numpy a+b 1.17 us): the
minimal step 48.5 us against the real semi-implicit step's 75.3 us, so 64 % of it. The real step's
best figure on this machine (numpy a+b 0.50 us, the fastest this host has been) is 35.6 us, which
puts the minimal step at about 23 us there: above the aim's 16.7 us before any of the work it
leaves out. The 20 ms aim is out of reach of a numpy step on this machine, however fused; it needs
compiled code (a loop in C, or numba), which the solver's numpy-and-scipy rule excludes.
"""

import argparse
import json
import time
from operator import mul

import numpy as np
from machine import numpy_op_us

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
            "floor_minimal_step_us": minimal_step_floor(steps), "numpy_add_us": numpy_op_us(),
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


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true")
    parser.add_argument("--trials", type=int, default=60)
    args = parser.parse_args()
    out = {}
    out.update(thesis_workload())
    out.update(step_floor())
    out.update(big_character())
    out.update(annealing(args.trials))
    out = {k: round(v, 3) if isinstance(v, float) else v for k, v in out.items()}
    if args.json:
        print(json.dumps(out, indent=1))
        return
    for key, value in out.items():
        print(f"{key:45s} {value}")


if __name__ == "__main__":
    main()
