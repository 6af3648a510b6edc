#!/usr/bin/env python3
"""Throughput of `python -m humananim batch` on the Bandai Namco corpus, and what a take costs
beyond its work.

    PYTHONPATH=<worktree parent> <bpy50 venv>/bin/python benchmarks/batch.py [--sample N] [--json]

The pipeline is `control --load-left 5 -> compress --degrees 0.5` over the corpus's 174 takes
(../shared/data/mocap/bandai-namco-1/, read in place), or over N of them spread evenly through the
sorted list with --sample N. The same takes run, each into a fresh output folder, on:

- a LocalCluster with 1 worker, then with 2 workers (one single-threaded worker process per core);
- a cluster started with Dask's own commands on 127.0.0.1 (`dask scheduler` and two
  `dask worker --nthreads 1`), through --scheduler;
- a LocalCluster with 1 worker whose takes each start a new interpreter (--start spawn), the
  cost a take would pay without the workers' warm take starter.

Reported per run: takes per minute over the whole batch (cluster start included) and from the
first take's start to the last take's end; per take its wall time (from the worker starting it to
its folder in place) against its work (the commands' own time: reading the clip, the solver,
saving). Overhead = 1 - work / wall: per take on each worker's takes after its first (the take
starter is warm then), each worker's one-off start (importing Blender and registering the add-on
once) apart, and over all takes together. Scaling efficiency = the 2-worker throughput over twice
the 1-worker throughput. Aims: at least 85 % of linear scaling, under 15 % overhead per take.
The host's load average and numpy speed are printed beside the figures: on a shared machine
absolute times swing 2-3x, so compare runs of one invocation only.
"""

import argparse
import datetime
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time

import numpy as np
from machine import numpy_add_us  # noqa: E402  (the contract's machine-speed indicator)

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CORPUS = os.path.join(REPO, "..", "shared", "data", "mocap", "bandai-namco-1")
PIPELINE = "control --load-left 5 -> compress --degrees 0.5"


def takes(sample):
    files = sorted(os.path.join(CORPUS, f) for f in os.listdir(CORPUS) if f.endswith(".bvh"))
    if sample and sample < len(files):
        step = len(files) / sample
        files = [files[int(i * step)] for i in range(sample)]
    return files


def run(files, out, *engine):
    cmd = [sys.executable, "-m", "humananim", "batch", *files, "--pipeline", PIPELINE, "--out-dir", out,
           "--json", "--no-progress", *engine]
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    done = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    if done.returncode != 0:
        raise SystemExit(f"batch failed: {done.stderr.strip().splitlines()[-1]}")
    s = json.loads(done.stdout)
    ran = [r for r in s["results"] if r["status"] == "done"]
    wall = sum(r["wall_seconds"] for r in ran)
    work = sum(r["work_seconds"] for r in ran)
    by_worker = {}
    for r in sorted(ran, key=lambda r: r["started_at"]):
        by_worker.setdefault(r["worker"], []).append(r)
    later = [r for takes_of in by_worker.values() for r in takes_of[1:]]  # the starter is warm
    first = [takes_of[0] for takes_of in by_worker.values()]
    per_take = (sum(r["wall_seconds"] - r["work_seconds"] for r in later) / len(later)) if later else None
    span = max(r["finished_at"] for r in ran) - min(r["started_at"] for r in ran)
    return {"engine": s["engine"]["description"], "takes": s["takes"], "done": s["done"], "failed": s["failed"],
            "seconds": s["seconds"], "takes_per_minute": s["takes_per_minute"],
            "takes_per_minute_running": round(60.0 * len(ran) / span, 2),
            "mean_wall_s": round(wall / len(ran), 3), "mean_work_s": round(work / len(ran), 3),
            "overhead": round(1.0 - work / wall, 4),
            "overhead_per_take_s": None if per_take is None else round(per_take, 3),
            "overhead_per_take": None if per_take is None else round(
                per_take / (sum(r["wall_seconds"] for r in later) / len(later)), 4),
            "worker_start_s": round(sum(r["wall_seconds"] - r["work_seconds"] for r in first) / len(first)
                                    - (per_take or 0.0), 3),
            "workers_used": len(by_worker)}


def dask_cluster(folder):
    """`dask scheduler` and two `dask worker` processes on 127.0.0.1: (address, processes)."""
    dask = os.path.join(os.path.dirname(sys.executable), "dask")
    sfile = os.path.join(folder, "scheduler.json")
    log = open(os.path.join(folder, "cluster.log"), "w")
    procs = [subprocess.Popen([dask, "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                               "--scheduler-file", sfile], stdout=log, stderr=log)]
    while not os.path.exists(sfile):
        time.sleep(0.2)
    with open(sfile) as f:
        address = json.load(f)["address"]
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    procs += [subprocess.Popen([dask, "worker", address, "--nthreads", "1", "--host", "127.0.0.1",
                                "--no-dashboard"], stdout=log, stderr=log, env=env) for _ in range(2)]
    from dask.distributed import Client
    with Client(address, timeout="60s") as client:
        client.wait_for_workers(2, timeout=120)
    return address, procs


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sample", type=int, default=0, help="run N takes spread through the corpus (default all 174)")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    files = takes(args.sample)
    tmp = tempfile.mkdtemp(prefix="humananim-batch-bench-")
    load_before = os.getloadavg()
    out = {"benchmark": "batch", "date": datetime.date.today().isoformat(),
           "machine_speed": {"numpy_add_us": round(numpy_add_us(), 3)}, "cores": os.cpu_count(),
           "pipeline": PIPELINE, "takes": len(files), "corpus_takes": len(takes(0))}
    try:
        runs = {"local_1": run(files, os.path.join(tmp, "l1"), "--workers", "1"),
                "local_2": run(files, os.path.join(tmp, "l2"), "--workers", "2")}
        address, procs = dask_cluster(tmp)
        try:
            runs["dask_cluster_2"] = run(files, os.path.join(tmp, "c2"), "--scheduler", address)
        finally:
            for p in procs:
                p.terminate()
            for p in procs:
                p.wait(30)
        runs["local_1_spawn"] = run(files, os.path.join(tmp, "s1"), "--workers", "1", "--start", "spawn")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    out["runs"] = runs
    out["load_average"] = {"before": [round(v, 2) for v in load_before], "after": [round(v, 2) for v in os.getloadavg()]}
    workers = min(2, os.cpu_count() or 1)
    one = runs["local_1"]["takes_per_minute_running"]
    efficiency = runs["local_2"]["takes_per_minute_running"] / (workers * one)
    cluster_eff = runs["dask_cluster_2"]["takes_per_minute_running"] / (workers * one)
    whole_eff = runs["local_2"]["takes_per_minute"] / (workers * runs["local_1"]["takes_per_minute"])
    steady = runs["local_2"]["overhead_per_take"]
    out["claims"] = [
        {"claim": f"takes per minute, {PIPELINE}, 1 local worker (whole batch, cluster start included)",
         "value": runs["local_1"]["takes_per_minute"], "unit": "takes/min", "aim": None, "met": None},
        {"claim": "takes per minute, 2 local workers (whole batch)", "value": runs["local_2"]["takes_per_minute"],
         "unit": "takes/min", "aim": None, "met": None},
        {"claim": "takes per minute, dask scheduler + 2 dask workers on 127.0.0.1 (whole batch)",
         "value": runs["dask_cluster_2"]["takes_per_minute"], "unit": "takes/min", "aim": None, "met": None},
        {"claim": "scaling efficiency, 2 local workers against 1, first take start to last take end",
         "value": round(100 * efficiency, 1), "unit": "% of linear", "aim": ">= 85 % of linear",
         "met": efficiency >= 0.85},
        {"claim": "scaling efficiency, the 2-worker dask cluster against 1 local worker, same span",
         "value": round(100 * cluster_eff, 1), "unit": "% of linear", "aim": ">= 85 % of linear",
         "met": cluster_eff >= 0.85},
        {"claim": "scaling efficiency, 2 local workers against 1, whole batch (cluster start included)",
         "value": round(100 * whole_eff, 1), "unit": "% of linear", "aim": None, "met": None},
        {"claim": "overhead per take with a warm take starter (a worker's takes after its first), 2 local workers",
         "value": None if steady is None else round(100 * steady, 1), "unit": "% of the take's wall time",
         "aim": "< 15 %", "met": None if steady is None else steady < 0.15},
        {"claim": "overhead of all takes including each worker's one-off starter start, 2 local workers",
         "value": round(100 * runs["local_2"]["overhead"], 1), "unit": "% of wall time", "aim": None, "met": None},
        {"claim": "overhead with a new interpreter per take (--start spawn), 1 worker",
         "value": round(100 * runs["local_1_spawn"]["overhead"], 1), "unit": "% of wall time", "aim": None,
         "met": None},
    ]
    if args.json:
        os.makedirs(os.path.join(REPO, "benchmarks", "results"), exist_ok=True)
        with open(os.path.join(REPO, "benchmarks", "results", "batch.json"), "w") as f:
            json.dump(out, f, indent=1)
        print(json.dumps(out, indent=1))
        return
    print(f"{len(files)} of {out['corpus_takes']} takes, {PIPELINE}; numpy a+b {out['machine_speed']['numpy_add_us']} us, "
          f"load {out['load_average']}")
    for name, r in runs.items():
        print(f"  {name:15s} {r['takes_per_minute']:6.1f} takes/min ({r['takes_per_minute_running']:.1f} while "
              f"running)  {r['seconds']:6.1f} s  per take wall {r['mean_wall_s']:.2f} s, work {r['mean_work_s']:.2f} s, "
              f"overhead {100 * r['overhead']:.1f} % (after each worker's first take: {r['overhead_per_take_s']} s; "
              f"worker start {r['worker_start_s']} s)")
    for c in out["claims"][3:]:
        print(f"  {c['claim']}: {c['value']} {c['unit']} (aim {c['aim']}: {'met' if c['met'] else 'not met' if c['met'] is False else '-'})")


if __name__ == "__main__":
    main()
