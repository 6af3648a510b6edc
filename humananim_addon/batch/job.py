"""A batch started from Blender: the same `python -m humananim batch` command in a background
process, watched through the files it writes (progress.json, summary.json). No bpy here: the
Batch panel's timer calls `BatchJob.poll`, and so do the tests (timers never fire headless).

Blender's own Python has neither dask nor the bpy module, so the job runs in the batch
interpreter: the panel's Python field, else $HUMANANIM_BATCH_PYTHON, else this interpreter when
it is the bpy module (a development session). See docs/batch.md.
"""

import json
import os
import shlex
import signal
import subprocess
import sys

from .command import PYTHON_ENV
from .report import PROGRESS, SUMMARY, progress_line

LOG = "batch.log"


def batch_python(configured=""):
    """The interpreter that runs the batch, or "" when there is none to use."""
    if configured:
        return configured
    if os.environ.get(PYTHON_ENV):
        return os.environ[PYTHON_ENV]
    return sys.executable if _in_bpy_module() else ""


def _in_bpy_module():
    """True in the bpy module (or with no Blender at all), false inside the Blender executable."""
    try:
        import bpy
    except ImportError:
        return True
    return bpy.app.binary_path == ""


def batch_argv(inputs, pipeline, out_dir, workers=0, scheduler="", retries=1, timeout=600.0):
    """The `batch` command's arguments for the panel's settings (inputs: ';'-separated)."""
    argv = ["batch"] + [s.strip() for s in inputs.split(";") if s.strip()]
    argv += ["--pipeline", pipeline, "--out-dir", out_dir, "--retries", str(retries), "--timeout", f"{timeout:g}"]
    if scheduler:
        argv += ["--scheduler", scheduler]
    elif workers:
        argv += ["--workers", str(workers)]
    return argv + ["--no-progress"]


class BatchJob:
    """One background batch: start it, poll it, stop it."""

    def __init__(self, python, argv, out_dir):
        self.out_dir = os.path.abspath(out_dir)
        os.makedirs(self.out_dir, exist_ok=True)
        for stale in (PROGRESS, SUMMARY):  # an earlier run's files would read as this run's progress
            path = os.path.join(self.out_dir, stale)
            if os.path.exists(path):
                os.remove(path)
        self.command = [python, "-m", "humananim"] + argv
        self.log_path = os.path.join(self.out_dir, LOG)
        self.log = open(self.log_path, "w")
        self.proc = subprocess.Popen(self.command, stdout=self.log, stderr=subprocess.STDOUT,
                                     start_new_session=True)
        self.summary = None
        self.error = None

    def describe(self):
        return " ".join(shlex.quote(w) for w in self.command)

    def poll(self):
        """The job's state now, without waiting: {"running", "progress" (counts or None), "line"
        (the progress line), "summary" (when finished), "error" (one line, when it failed)}."""
        progress = _read(os.path.join(self.out_dir, PROGRESS))
        running = self.proc.poll() is None
        if not running and self.summary is None and self.error is None:
            self.log.close()
            if self.proc.returncode == 0:
                self.summary = _read(os.path.join(self.out_dir, SUMMARY))
            else:
                self.error = _last_line(self.log_path) or f"the batch ended with status {self.proc.returncode}"
        line = progress_line(progress) if progress else "starting..."
        return {"running": running, "progress": progress, "line": line, "summary": self.summary,
                "error": self.error, "report": os.path.join(self.out_dir, "report.html")}

    def stop(self):
        """Stop as Ctrl-C would: finished takes are kept, a rerun does the rest."""
        if self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGINT)

    def wait(self, timeout=None):
        self.proc.wait(timeout)
        return self.poll()


def _read(path):
    try:
        with open(path, encoding="utf-8") as f:
            return json.load(f)
    except (OSError, ValueError):
        return None


def _last_line(path):
    try:
        with open(path, errors="replace") as f:
            lines = [line.strip() for line in f if line.strip()]
    except OSError:
        return None
    return lines[-1] if lines else None
