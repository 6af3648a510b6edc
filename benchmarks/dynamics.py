#!/usr/bin/env python3
"""Speed of the articulated-body dynamics (solver/dynamics).

    python3 benchmarks/dynamics.py          # a table
    python3 benchmarks/dynamics.py --json   # one JSON object, also benchmarks/results/dynamics.json

Microseconds of CPU time per call (best of several repeats, so other load on a shared machine
counts as little as possible) of forward kinematics, inverse dynamics (RNEA), the inertia matrix
(CRBA), forward dynamics (ABA, and Cholesky of H), the ZMP and a full control step (RNEA, CRBA
and ZMP for one state), for the 18-segment, 39-DOF Oshita-like figure; and the real-time factor
of Huang's closed-loop simulation tracking 2 s of the CMU clip 131_01 (31 bones, role-based masses),
with its tracking error (joint positions and rotations against the clip). The real-time factor is
simulated seconds per wall second, so it swings with the host's load: read it beside the
machine-speed indicator (machine.py).
"""

import argparse
import time
import timeit
from pathlib import Path

import numpy as np


from humananim.solver import bvh, rotations  # noqa: E402
from humananim.solver.dynamics import (GroundModel, Settings, aba, build_model, crba,  # noqa: E402
                                       default_contacts, desired_motion, forward_dynamics_dense,
                                       integrate, oshita_figure, point_positions, rnea, simulate,
                                       update_frames, zmp)
from humananim.solver.dynamics.closed_loop import _Constant, step_implicit  # noqa: E402
from humananim.solver.trajectories import Trajectories  # noqa: E402
from machine import claim, emit, result  # noqa: E402

CMU = Path(__file__).resolve().parent.parent / "humananim_addon" / "data" / "mocap" / "cmu_131_01.bvh"


def per_call_us(fn, number=200, repeat=7):
    """Best CPU time per call: other processes on a shared machine inflate wall time."""
    fn()
    return min(timeit.Timer(fn, timer=time.process_time).repeat(number=number, repeat=repeat)) / number * 1e6


def figure_timings():
    m = build_model(oshita_figure())
    d = m.create_data()
    rng = np.random.default_rng(0)
    q = integrate(m, m.neutral(), 0.5 * rng.normal(size=m.nv))
    v, a = rng.normal(size=m.nv), rng.normal(size=m.nv)
    tau = rnea(m, d, q, v, a)

    def fresh(fn):  # every call sees a new configuration: no cached frames
        def run():
            d.key = None
            fn()
        return run

    def control_step():  # one state: frames once, then inverse dynamics, H and the ZMP
        d.key = None
        rnea(m, d, q, v, a)
        crba(m, d, q)
        zmp(m, d, q, v, a)

    st = Settings()
    contacts = default_contacts(m)
    servo = _Constant(np.zeros(m.nv))
    passive = np.zeros(m.nv)
    q_stand = m.neutral()
    q_stand[2] -= 0.002  # feet 2 mm into the ground: eight active contacts

    out = {
        "figure_segments": m.nb, "figure_dof": m.nv - 6,
        "fk_us": per_call_us(fresh(lambda: update_frames(m, d, q))),
        "rnea_us": per_call_us(fresh(lambda: rnea(m, d, q, v, a))),
        "rnea_cached_frames_us": per_call_us(lambda: rnea(m, d, q, v, a)),
        "crba_us": per_call_us(fresh(lambda: crba(m, d, q))),
        "aba_us": per_call_us(fresh(lambda: aba(m, d, q, v, tau)), number=50),
        "forward_dynamics_cholesky_us": per_call_us(fresh(lambda: forward_dynamics_dense(m, d, q, v, tau))),
        "zmp_us": per_call_us(fresh(lambda: zmp(m, d, q, v, a))),
        "control_step_us": per_call_us(control_step),
        "simulation_step_us": per_call_us(
            lambda: step_implicit(m, d, q_stand, np.zeros(m.nv), servo, 1e-3, st, contacts, None, passive),
            number=50),
    }
    return out


def cmu_closed_loop(seconds=2.0, start=300):
    b = bvh.read(CMU)
    sk = bvh.skeleton(b)
    full = bvh.trajectories(b, sk)
    n = int(round(seconds * b.fps))
    s = slice(start, start + n)
    tr = Trajectories(full.frames[s], full.fps, full.rotations[s], full.translations[s],
                      full.armature_to_world)
    m = build_model(sk)
    d = m.create_data()
    c = default_contacts(m)
    lowest = [(point_positions(m, d, q, c.joints, c.points)[:, 2] - c.radii).min()
              for q in desired_motion(m, sk, tr)[0]]
    settings = Settings(ground=GroundModel(height=float(np.percentile(lowest, 10))))
    t0 = time.perf_counter()
    res = simulate(sk, tr, settings)
    elapsed = time.perf_counter() - t0
    w0, w1 = tr.world_frames(sk), res.trajectories.world_frames(sk)
    pos = np.linalg.norm(w1[..., :3, 3] - w0[..., :3, 3], axis=-1)
    return {
        "cmu_bones": sk.joint_count, "cmu_dof": res.model.nv - 6, "cmu_frames": n,
        "cmu_sim_seconds": n / b.fps, "cmu_wall_s": elapsed,
        "cmu_realtime_factor": (n / b.fps) / elapsed,
        "cmu_joint_position_error_max_m": float(pos.max()),
        "cmu_joint_position_error_mean_m": float(pos.mean()),
        "cmu_rotation_error_mean_rad": float(
            rotations.angle_between(res.trajectories.rotations, tr.rotations).mean()),
    }


def claims(out):
    figure = "18-segment, 39-DOF figure"
    found = [
        claim(f"{figure}: inverse dynamics (RNEA), per call", out["rnea_us"], "us CPU"),
        claim(f"{figure}: forward dynamics (ABA), per call", out["aba_us"], "us CPU"),
        claim(f"{figure}: one control step (RNEA, CRBA and ZMP of one state)", out["control_step_us"], "us CPU"),
        claim(f"{figure}: one implicit simulation step standing on eight contacts", out["simulation_step_us"],
              "us CPU"),
    ]
    if "cmu_realtime_factor" in out:
        found += [
            claim("CMU 131_01 closed-loop tracking (31 bones, 2 s): simulated seconds per wall second",
                  out["cmu_realtime_factor"], "x"),
            claim("CMU 131_01 closed-loop tracking: mean joint position error against the clip",
                  out["cmu_joint_position_error_mean_m"] * 1000, "mm"),
        ]
    return found


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args(argv)
    out = {"numpy_version": np.__version__}
    out.update(figure_timings())
    if CMU.exists():
        out.update(cmu_closed_loop())
    if args.json:
        emit(result("dynamics", claims(out), **{k: (round(v, 4) if isinstance(v, float) else v)
                                                for k, v in out.items()}))
    else:
        for k, v in out.items():
            print(f"{k:36s} {v:.4g}" if isinstance(v, float) else f"{k:36s} {v}")


if __name__ == "__main__":
    main()
