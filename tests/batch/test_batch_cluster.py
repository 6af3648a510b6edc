"""The batch on a Dask cluster started with Dask's own commands on 127.0.0.1: `dask scheduler`
and two `dask worker` processes; then the scheduler killed in the middle of a run, and the rerun
(on a local pool) doing only the takes that had not finished."""

import json
import os
import signal
import subprocess
import sys

import pytest

from batch_helpers import (SHORT_BANDAI, bandai, batch_command, batch_env, needs_dask, progress, run_batch,
                           wait_for)

needs_dask()
DASK = os.path.join(os.path.dirname(sys.executable), "dask")


def _worker_count(scheduler_file):
    from dask.distributed import Client
    with Client(scheduler_file=scheduler_file, timeout="10s") as client:
        return len(client.scheduler_info()["workers"])


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    """(address, scheduler process) of a scheduler and two single-threaded workers, for this
    module's tests (the last one kills the scheduler)."""
    tmp_path = tmp_path_factory.mktemp("cluster")
    scheduler_file = str(tmp_path / "scheduler.json")
    logs = open(tmp_path / "cluster.log", "w")
    procs = [subprocess.Popen([DASK, "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                               "--scheduler-file", scheduler_file], stdout=logs, stderr=logs, env=batch_env())]
    try:
        wait_for(lambda: os.path.exists(scheduler_file), 120, "the scheduler")
        with open(scheduler_file) as f:
            address = json.load(f)["address"]
        assert address.startswith("tcp://127.0.0.1:")
        for _ in range(2):
            procs.append(subprocess.Popen([DASK, "worker", address, "--nthreads", "1", "--nworkers", "1",
                                           "--host", "127.0.0.1", "--no-dashboard", "--death-timeout", "30"],
                                          stdout=logs, stderr=logs, env=batch_env()))
        wait_for(lambda: _worker_count(scheduler_file) == 2, 120, "two workers")
        yield address, procs[0]
    finally:
        for proc in reversed(procs):
            if proc.poll() is None:
                proc.terminate()
        for proc in procs:
            try:
                proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                proc.kill()
        logs.close()


def test_batch_on_a_scheduler_and_two_workers(cluster, tmp_path):
    address, _ = cluster
    out = str(tmp_path / "out")
    clips = [bandai(n) for n in SHORT_BANDAI[:4]]
    status, summary, stderr = run_batch(*clips, "--pipeline", "info -> compress", "--out-dir", out,
                                        "--scheduler", address)
    assert status == 0, stderr
    assert summary["engine"]["kind"] == "scheduler" and summary["engine"]["address"] == address
    assert summary["engine"]["workers"] == 2
    assert (summary["done"], summary["failed"]) == (4, 0)
    for row in summary["results"]:
        assert [s["command"] for s in row["steps"]] == ["info", "compress"]
        assert os.path.isfile(os.path.join(out, row["name"], "2-compress.blend"))


def test_a_killed_scheduler_loses_no_finished_take(cluster, tmp_path):
    address, scheduler = cluster
    out = str(tmp_path / "out")
    args = [*[bandai(n) for n in SHORT_BANDAI[:8]], "--pipeline", "info", "--out-dir", out, "--no-progress"]
    driver = subprocess.Popen(batch_command(*args, "--scheduler", address), stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True, env=batch_env())
    try:
        wait_for(lambda: (progress(out) or {}).get("done", 0) >= 2, 300, "two finished takes")
        scheduler.send_signal(signal.SIGKILL)
        _, stderr = driver.communicate(timeout=180)
    finally:
        if driver.poll() is None:
            driver.kill()
    assert driver.returncode == 2
    assert stderr.strip().splitlines()[-1].startswith("humananim batch: error: interrupted:")
    finished = sorted(n for n in os.listdir(out) if os.path.isfile(os.path.join(out, n, "take.json")))
    assert 2 <= len(finished) < 8
    status, summary, stderr = run_batch(*args, "--workers", "1")
    assert status == 0, stderr
    assert summary["done"] == 8 and summary["skipped"] == len(finished) and summary["ran"] == 8 - len(finished)
