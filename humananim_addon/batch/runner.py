"""Running a batch on Dask: a LocalCluster (one single-threaded worker process per core) by
default, or an existing cluster at `--scheduler tcp://HOST:PORT`.

A Dask task runs one take: it starts the take's own process (`python -m
humananim.humananim_addon.batch.take`, Blender as a module) in a fresh folder under
OUT/.partial/, waits for it with a timeout, retries a crash or a timeout, and when the take's
record says done renames the folder to OUT/<take>/ — so a take's outputs appear whole or not at
all, and a finished take survives whatever happens to the driver, the scheduler or other workers.

Each worker has one thread: its task only waits on the take's process, which is the one that
uses a core (its BLAS held to one thread); a second thread per worker would run two takes on one
core. A worker that dies takes its running take with it (the take's process notices its parent
is gone and stops); the scheduler gives that take to another worker.

No bpy here; dask is imported only when a batch runs.
"""

import contextlib
import os
import shutil
import socket
import subprocess
import sys
import threading
import time
import uuid
from concurrent.futures import CancelledError

from .plan import PARTIAL, RECORD, Take, is_complete, load_record, write_json_atomic
from .report import Progress, take_summary, write_summary

class SchedulerLost(Exception):
    """The Dask scheduler stopped answering in the middle of a batch."""


TAKE_MODULE = "humananim.humananim_addon.batch.take"
THREAD_ENV = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


def run_take(take, out_dir, python, timeout, retries, start="fork"):
    """Run one take (a Take as a dict) to the end: its record (status done or failed). `start`:
    "fork" forks the take from this worker's warm take starter, "spawn" starts a new interpreter."""
    take = Take(**take)
    final = take.folder(out_dir)
    error, attempts, t0, started_at = None, 0, time.monotonic(), time.time()
    for attempts in range(1, retries + 2):
        partial = os.path.join(out_dir, PARTIAL, f"{take.name}.{uuid.uuid4().hex[:8]}")
        os.makedirs(partial)
        spec = os.path.join(partial, "spec.json")
        write_json_atomic(spec, {"name": take.name, "file": take.file, "steps": take.steps,
                                 "options_hash": take.options_hash, "folder": partial})
        if start == "fork":
            status, error = _starter(python).run(spec, timeout)
            if error is None and status:
                error = _last_line(os.path.join(partial, "take.log"))
        else:
            status, error = _run_process(python, spec, partial, timeout)
        record = load_record(partial)
        if status == 0 and record and record.get("status") == "done":
            os.remove(spec)
            record["outputs"] = [f for f in record["outputs"] if f != "spec.json"]
            record.update(attempts=attempts, wall_seconds=round(time.monotonic() - t0, 3), worker=_where(),
                          started_at=round(started_at, 3), finished_at=round(time.time(), 3))
            write_json_atomic(os.path.join(partial, RECORD), record)
            _publish(partial, final, out_dir)
            return record
        if record and record.get("error"):
            error = record["error"]
        shutil.rmtree(partial, ignore_errors=True)
        if status in (2, 3):  # bad input or a failed --strict QA: the same answer on every try
            break
    return {"name": take.name, "file": take.file, "status": "failed", "error": error, "attempts": attempts,
            "wall_seconds": round(time.monotonic() - t0, 3), "worker": _where(), "steps": []}


def _run_process(python, spec, folder, timeout):
    """(exit status, one-line error or None) of the take's process."""
    env = dict(os.environ, **THREAD_ENV)
    log_path = os.path.join(folder, "take.log")
    with open(log_path, "w") as log:
        proc = subprocess.Popen([python, "-m", TAKE_MODULE, spec], cwd=folder, stdout=log,
                                stderr=subprocess.STDOUT, env=env, start_new_session=True)
        try:
            status = proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            _kill_group(proc)
            return None, f"timed out after {timeout:g} s"
        except BaseException:  # the worker is stopping: never leave the take running
            _kill_group(proc)
            raise
    if status == 0:
        return 0, None
    return status, _last_line(log_path) or f"the take's process ended with status {status}"


class TakeStarter:
    """This worker's take starter (`take --serve`): a process with Blender imported that forks one
    process per take. Started on the first take, started again if it dies."""

    def __init__(self, python):
        env = dict(os.environ, **THREAD_ENV)
        self.proc = subprocess.Popen([python, "-m", TAKE_MODULE, "--serve"], stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, env=env)
        self.buffer = b""
        self.ready = False

    def alive(self):
        return self.proc.poll() is None

    def run(self, spec, timeout):
        """(exit status, error or None) of the take; the timeout covers the starter's start too."""
        deadline = time.monotonic() + timeout
        if not self.ready:
            if self._line(deadline) != "ready":
                return None, "the take starter did not start (see the worker's log)"
            self.ready = True
        self.proc.stdin.write(spec.encode() + b"\n")
        self.proc.stdin.flush()
        started = self._line(deadline)
        if not started or not started.startswith("pid "):
            return None, "the take starter stopped"
        pid = int(started.split()[1])
        try:
            ended = self._line(deadline)
        except BaseException:  # the worker is stopping: never leave the take running
            _kill_pid_group(pid)
            raise
        if ended is None:
            if not self.alive():
                return None, "the take starter stopped"
            _kill_pid_group(pid)
            self._line(time.monotonic() + 30)
            return None, f"timed out after {timeout:g} s"
        return int(ended.split()[1]), None

    def _line(self, deadline):
        """The next protocol line, or None at the deadline or the end of the stream."""
        import select
        fd = self.proc.stdout.fileno()
        while b"\n" not in self.buffer:
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([fd], [], [], left)[0]:
                return None
            chunk = os.read(fd, 4096)
            if not chunk:
                return None
            self.buffer += chunk
        line, self.buffer = self.buffer.split(b"\n", 1)
        return line.decode().strip()


_STARTERS = {}


def _starter(python):
    """The starter of this worker thread (a worker with several threads has one per thread: the
    protocol is one take at a time)."""
    key = (python, threading.get_ident())
    starter = _STARTERS.get(key)
    if starter is None or not starter.alive():
        starter = _STARTERS[key] = TakeStarter(python)
    return starter


def _kill_pid_group(pid):
    with contextlib.suppress(ProcessLookupError):
        os.killpg(pid, 9)


def _kill_group(proc):
    with contextlib.suppress(ProcessLookupError):
        os.killpg(proc.pid, 9)
    proc.wait()


def _last_line(path):
    with open(path, errors="replace") as f:
        lines = [line.strip() for line in f if line.strip()]
    return lines[-1][:300] if lines else None


def _publish(partial, final, out_dir):
    """Move a finished take's folder into place; an older result of the take is replaced."""
    if os.path.exists(final):
        old = os.path.join(out_dir, PARTIAL, f"{os.path.basename(final)}.old.{uuid.uuid4().hex[:8]}")
        os.rename(final, old)
        os.rename(partial, final)
        shutil.rmtree(old, ignore_errors=True)
    else:
        os.rename(partial, final)


def _where():
    return f"{socket.gethostname()}:{os.getpid()}"


@contextlib.contextmanager
def engine(workers=None, scheduler=None):
    """A dask Client and a description of its engine: on `scheduler`, or on a LocalCluster of
    `workers` single-threaded processes (default: one per core)."""
    import logging
    from dask.distributed import Client, LocalCluster
    logging.getLogger("distributed").setLevel(logging.WARNING)
    if scheduler:
        with Client(scheduler, timeout="20s") as client:
            n = len(client.scheduler_info().get("workers", {}))
            yield client, {"kind": "scheduler", "address": scheduler, "workers": n,
                           "description": f"Dask cluster at {scheduler} ({n} workers)"}
        return
    workers = workers or os.cpu_count() or 1
    with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None,
                      silence_logs=logging.ERROR) as cluster, Client(cluster) as client:
        yield client, {"kind": "local", "workers": workers, "threads_per_worker": 1, "address": cluster.scheduler_address,
                       "description": f"Dask LocalCluster, {workers} worker processes x 1 thread"}


def run_batch(takes, steps, out_dir, python=None, workers=None, scheduler=None, timeout=600.0, retries=1,
              force=False, progress_stream=None, on_client=None, start="fork"):
    """Run the takes not yet complete in `out_dir`; write summary.json and report.html; return the
    summary. On Ctrl-C or a lost scheduler the summary says `interrupted` and finished takes stay."""
    python = python or sys.executable
    out_dir = os.path.abspath(out_dir)
    os.makedirs(os.path.join(out_dir, PARTIAL), exist_ok=True)
    _clear_stale(out_dir)
    t0 = time.monotonic()
    todo = [t for t in takes if force or not is_complete(t, out_dir)]
    results = {t.name: take_summary(load_record(t.folder(out_dir)), skipped=True) for t in takes if t not in todo}
    progress = Progress(out_dir, len(takes), len(results), progress_stream)
    engine_info = {"kind": "none", "description": "nothing to run: every take is complete"}
    status = "finished"
    try:
        if todo:
            with engine(workers, scheduler) as (client, engine_info):
                if on_client:
                    on_client(client)
                engine_info["start"] = start
                _run_on(client, todo, out_dir, python, timeout, retries, start, results, progress)
    except KeyboardInterrupt:
        status = "interrupted"
    except (OSError, SchedulerLost) as error:  # the scheduler is unreachable or went away
        status = "interrupted"
        engine_info = dict(engine_info, error=f"{type(error).__name__}: {error}")
    for take in takes:  # takes this run never heard back about: finished by a worker, or not
        if take.name not in results or results[take.name]["status"] == "pending":
            record = load_record(take.folder(out_dir)) if is_complete(take, out_dir) else None
            results[take.name] = take_summary(record) if record else {
                "name": take.name, "file": take.file, "status": "not run", "error": "interrupted before it finished",
                "skipped": False, "steps": [], "outputs": []}
    if status == "finished":
        _clear_stale(out_dir)  # e.g. the folder of a take whose worker was killed (the take was redone)
    progress.finish(status)
    ordered = [results[t.name] for t in takes]
    summary = summarize(ordered, steps, out_dir, engine_info, time.monotonic() - t0, status)
    summary["report"] = write_summary(out_dir, summary)
    return summary


def _run_on(client, todo, out_dir, python, timeout, retries, start, results, progress):
    from dask.distributed import as_completed
    futures = {client.submit(run_take, t.to_dict(), out_dir, python, timeout, retries, start,
                             key=f"take-{t.name}-{uuid.uuid4().hex[:6]}", pure=False): t for t in todo}
    for future in as_completed(futures):
        take = futures[future]
        try:
            record = future.result()
        except CancelledError:  # the scheduler went away: the take may still finish, or not
            raise SchedulerLost(f"lost the scheduler at {client.scheduler.address}") from None
        except Exception as error:  # e.g. KilledWorker: the take's worker died on every try
            record = {"name": take.name, "file": take.file, "status": "failed", "steps": [],
                      "error": f"{type(error).__name__}: {str(error).splitlines()[0] if str(error) else ''}"}
        results[take.name] = take_summary(record)
        progress.take_finished(record["status"] == "done")


def _clear_stale(out_dir):
    """Half-written takes of an earlier, interrupted run (one batch per output folder at a time)."""
    partial = os.path.join(out_dir, PARTIAL)
    for name in os.listdir(partial):
        shutil.rmtree(os.path.join(partial, name), ignore_errors=True)


def summarize(results, steps, out_dir, engine_info, seconds, status):
    done = [r for r in results if r["status"] == "done"]
    ran = [r for r in done if not r.get("skipped")]
    walls = [r["wall_seconds"] for r in ran if r.get("wall_seconds")]
    works = [r["work_seconds"] for r in ran if r.get("work_seconds") is not None]
    return {"command": "batch", "status": status, "out": out_dir, "pipeline": [str(s) for s in steps],
            "engine": engine_info, "takes": len(results), "done": len(done),
            "failed": sum(r["status"] == "failed" for r in results),
            "not_run": sum(r["status"] == "not run" for r in results),
            "skipped": sum(bool(r.get("skipped")) for r in done), "ran": len(ran),
            "seconds": round(seconds, 3),
            "takes_per_minute": round(60.0 * len(ran) / seconds, 2) if ran and seconds > 0 else None,
            "mean_take_wall_seconds": round(sum(walls) / len(walls), 3) if walls else None,
            "mean_take_work_seconds": round(sum(works) / len(works), 3) if works else None,
            "results": results, "wrote": [os.path.join(out_dir, "summary.json"), os.path.join(out_dir, "report.html")]}
