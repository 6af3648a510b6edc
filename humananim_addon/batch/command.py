"""The `batch` command: `python -m humananim batch INPUTS... --pipeline "control --load-left 5 ->
compress --degrees 0.5" --out-dir out/batch [--workers N | --scheduler tcp://HOST:PORT]`."""

import json
import os
import signal
import subprocess
import sys
import threading

from .plan import PlanError, parse_pipeline, plan

PYTHON_ENV = "HUMANANIM_BATCH_PYTHON"  # an interpreter with bpy, dask and humananim


def add_commands(sub, add_common_options):
    b = sub.add_parser("batch", help="run a pipeline of commands over many takes (a folder, a glob or a "
                                     "CSV/JSON manifest) on Dask; resumable, with a JSON summary and an HTML report")
    b.add_argument("inputs", nargs="+", help="folders, globs or files (.bvh/.fbx/.blend), or one manifest (.csv/.json)")
    b.add_argument("--pipeline", action="append", default=[], metavar="'CMD [OPTIONS] -> CMD ...'",
                   help="the steps, separated by '->'; any command that reads a file can be a step")
    b.add_argument("--step", action="append", default=[], metavar="'CMD [OPTIONS]'",
                   help="one step (repeatable; after the --pipeline steps)")
    b.add_argument("--out-dir", default=os.path.join("out", "batch"), help="output folder (default out/batch)")
    b.add_argument("--workers", type=int, help="local worker processes, one thread each (default: one per core)")
    b.add_argument("--scheduler", metavar="tcp://HOST:PORT", help="run on this Dask cluster instead")
    b.add_argument("--timeout", type=float, default=600.0, help="seconds a take may run (default 600)")
    b.add_argument("--retries", type=int, default=1,
                   help="runs again after a crash or timeout (not after bad input; default 1)")
    b.add_argument("--force", action="store_true", help="redo takes that are already complete")
    b.add_argument("--python", default=os.environ.get(PYTHON_ENV),
                   help=f"interpreter for the takes, with bpy, dask and humananim (default: ${PYTHON_ENV}, or this one)")
    b.add_argument("--start", choices=("fork", "spawn"), default="fork" if sys.platform.startswith("linux") else "spawn",
                   help="fork each take from a worker's warm process with Blender imported (default on Linux), "
                        "or spawn a new interpreter per take (default elsewhere: macOS and Windows can't fork "
                        "a process that has loaded Blender safely)")
    b.add_argument("--no-progress", action="store_true", help="no progress line on stderr")
    add_common_options(b)
    return {"batch": cmd_batch}


def cmd_batch(args):
    from ..cli import UsageError, build_parser
    if args.workers is not None and args.workers < 1:
        raise UsageError("--workers must be at least 1")
    if args.timeout <= 0 or args.retries < 0:
        raise UsageError("--timeout must be positive and --retries at least 0")
    if args.mass or args.scale:
        raise UsageError("--mass and --scale belong to the steps: put them in --pipeline")
    try:
        steps = parse_pipeline(args.pipeline + args.step)
        takes = plan(args.inputs, steps, build_parser())
    except (PlanError, ValueError) as error:
        raise UsageError(str(error)) from None
    if not _has_bpy_module():
        return _in_batch_python(args)
    from .runner import run_batch
    _listen_for_ctrl_c()
    summary = run_batch(takes, steps, args.out_dir, python=args.python or sys.executable, workers=args.workers,
                        scheduler=args.scheduler, timeout=args.timeout, retries=args.retries, force=args.force,
                        start=args.start, progress_stream=None if args.no_progress else sys.stderr)
    if summary["status"] == "interrupted":
        raise UsageError(f"interrupted: {summary['done']} of {summary['takes']} takes done (kept); run the same "
                         f"command again to finish the other {summary['takes'] - summary['done']}"
                         + (f" ({summary['engine']['error']})" if summary["engine"].get("error") else ""))
    summary["qa"] = batch_qa(summary["results"])
    summary["summary"] = text_summary(summary)
    return summary


def _listen_for_ctrl_c():
    """Ctrl-C and the panel's Stop (SIGINT to the batch's process group) end the run with the
    finished takes kept. An ignored SIGINT survives exec, so a batch started by a process that
    ignores it (a shell script's background job, a test runner that ran a take starter) would
    otherwise run to the end."""
    if threading.current_thread() is threading.main_thread() and signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)


def batch_qa(results):
    """The batch's motion QA in the `qa` form every command reports: passed when every measured
    take passed, failed when one did (its warnings prefixed with the take), None when no step
    measured a motion."""
    verdicts = [r["qa_passed"] for r in results if r.get("qa_passed") is not None]
    warnings = [f"{r['name']}: {w}" for r in results for w in r.get("qa_warnings") or []]
    return {"passed": (all(verdicts) if verdicts else None), "measures": {}, "warnings": warnings,
            "note": f"{len(verdicts)} of {len(results)} takes measured; each take's QA is in summary.json"}


def _has_bpy_module():
    """True in the bpy module (`python -m humananim`), false inside the Blender executable, whose
    Python has no dask and cannot start takes as modules."""
    try:
        import bpy
        import dask  # noqa: F401
    except ImportError:
        return False
    return bpy.app.binary_path == ""


def _in_batch_python(args):
    """`blender --command humananim batch`: hand the whole batch to the batch interpreter."""
    from ..cli import UsageError
    if not args.python:
        raise UsageError(f"the batch runs in a Python with bpy and dask: pass --python PATH or set {PYTHON_ENV} "
                         "(see docs/batch.md)")
    argv = batch_argv_of(args)
    run = subprocess.run([args.python, "-m", "humananim"] + argv, stdout=subprocess.PIPE, text=True)
    if run.returncode != 0:
        raise UsageError(f"the batch in {args.python} ended with status {run.returncode}")
    summary = json.loads(run.stdout)
    summary["delegated_to"] = args.python
    return summary


def batch_argv_of(args):
    """The `batch` command line of parsed arguments (to run the same batch elsewhere), with --json."""
    argv = ["batch", *args.inputs]
    for option in ("pipeline", "step"):
        for text in getattr(args, option):
            argv += [f"--{option}", text]
    argv += ["--out-dir", os.path.abspath(args.out_dir), "--timeout", f"{args.timeout:g}", "--retries",
             str(args.retries), "--start", args.start, "--python", args.python]
    if args.workers:
        argv += ["--workers", str(args.workers)]
    if args.scheduler:
        argv += ["--scheduler", args.scheduler]
    return argv + [flag for flag, on in (("--force", args.force), ("--no-progress", args.no_progress)) if on] + ["--json"]


def text_summary(s):
    lines = [f"batch: {s['done']} of {s['takes']} takes done ({s['skipped']} from earlier runs), "
             f"{s['failed']} failed, in {s['seconds']:.1f} s on {s['engine']['description']}"]
    if s["takes_per_minute"]:
        lines.append(f"  {s['takes_per_minute']:.1f} takes per minute; per take {s['mean_take_wall_seconds']:.2f} s "
                     f"wall, {s['mean_take_work_seconds']:.2f} s in the commands")
    for r in s["results"]:
        if r["status"] != "done":
            lines.append(f"  {r['status']}: {r['name']}: {r['error']}")
    lines.append(f"  wrote {s['report']}")
    return "\n".join(lines)
