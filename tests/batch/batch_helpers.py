"""Batch tests: real batches in subprocesses (`python -m humananim batch`) on a Dask LocalCluster
or a `dask scheduler` + `dask worker` cluster on 127.0.0.1, over short Bandai Namco and CMU clips
(read where they are, never copied)."""

import json
import os
import subprocess
import sys
import time

import pytest

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
MOCAP = os.path.join(REPO, "..", "shared", "data", "mocap")
if not os.path.isdir(MOCAP):
    MOCAP = "/work/shared/data/mocap"
BANDAI = os.path.join(MOCAP, "bandai-namco-1")
CMU = [os.path.join(REPO, "humananim_addon", "data", "mocap", f) for f in ("cmu_131_01.bvh", "cmu_131_03.bvh")]
# the shortest clips of the corpus (20-72 frames): the tests check the batch, not the commands
SHORT_BANDAI = ["dash_normal_001", "run_normal_001", "walk-back_normal_001", "walk_normal_002", "byebye_angry_001",
                "run_masculinity_001", "dash_giant_001", "dash_musical_001", "dash_chimpira_001",
                "bow_masculinity_001"]
# a batch to interrupt: two short takes that finish at once, then four of the longest (360-480
# frames) under a pipeline that takes seconds each, so a stop after the short ones always finds
# takes left to do (with `info` on short clips the whole batch can end before the stop arrives)
STOPPABLE = SHORT_BANDAI[:2] + ["walk-back_not-confident_001", "walk-back_sad_001", "walk_sad_002",
                                "walk_not-confident_001"]
STOPPABLE_PIPELINE = "compress --degrees 0.5"
PYTHON = sys.executable


def bandai(name):
    return os.path.join(BANDAI, f"dataset-1_{name}.bvh")


def batch_command(*args):
    return [PYTHON, "-m", "humananim", "batch", *args]


def run_batch(*args, timeout=600):
    """(exit status, summary dict or None, stderr) of a whole batch run."""
    run = subprocess.run(batch_command(*args, "--json"), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         text=True, timeout=timeout, env=batch_env())
    summary = json.loads(run.stdout) if run.returncode == 0 else None
    return run.returncode, summary, run.stderr


def batch_env():
    return dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")


def wait_for(predicate, timeout, what):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        value = predicate()
        if value:
            return value
        time.sleep(0.2)
    raise AssertionError(f"timed out waiting for {what}")


def progress(out_dir):
    try:
        with open(os.path.join(out_dir, "progress.json")) as f:
            return json.load(f)
    except (OSError, ValueError):
        return None


def needs_dask():
    pytest.importorskip("dask.distributed", reason="dask is installed into the batch environment by .ci/setup")
    pytest.importorskip("bpy")
