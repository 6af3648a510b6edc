"""One take of a batch, in its own process with Blender as a module:

    python -m humananim.humananim_addon.batch.take SPEC.json

runs the take's pipeline steps one after the other in this process (Blender is imported once
per take, not once per step), each exactly as `python -m humananim <step> FILE --out ... --json`
would, the next step reading the .blend the previous one wrote. Everything goes into the spec's
folder (the current directory): each step's files, a thumbnail of the result (result.svg) and,
last, the record take.json with every step's JSON summary (its `qa` included when the command
reports one). A step's bad input ends the take with exit status 2 and the one-line error in the
record; the batch runner publishes the folder only when the record says done.
"""

import json
import os
import signal
import sys
import threading
import time
import traceback

from .plan import RECORD, write_json_atomic

THUMBNAIL = "result.svg"
THUMBNAIL_POSES = 6


def main(argv):
    with open(argv[0], encoding="utf-8") as f:
        spec = json.load(f)
    _exit_with_parent()
    folder = spec["folder"]
    record = {"name": spec["name"], "file": spec["file"], "options_hash": spec["options_hash"],
              "status": "failed", "steps": [], "started": time.time()}
    try:
        status = run_steps(spec, record)
    except Exception as error:  # a crash in a step: the take fails, its message is the last line
        traceback.print_exc()
        record["error"] = f"{type(error).__name__}: {str(error).strip().splitlines()[-1] if str(error).strip() else ''}"
        status = 1
    record["seconds"] = round(time.time() - record.pop("started"), 3)
    record["work_seconds"] = round(sum(s["seconds"] for s in record["steps"]), 3)
    record["outputs"] = sorted(f for f in os.listdir(folder) if f != RECORD and not f.endswith(".tmp"))
    write_json_atomic(os.path.join(folder, RECORD), record)
    return status


def run_steps(spec, record):
    from ...solver.errors import HumanAnimError
    from .. import cli
    from ..cli import COMMANDS, UsageError, _chatter_to_stderr, _registered
    parser = _parser()
    commands = _subparsers(parser)
    current = spec["file"]
    if not os.path.isfile(current):
        record["error"] = f"no such file: {current}"
        return 2
    with _chatter_to_stderr(), _registered():
        for index, words in enumerate(spec["steps"], start=1):
            command = words[0]
            argv = [command, current] + words[1:]
            if "--out" in {s for a in commands[command]._actions for s in a.option_strings}:
                argv += ["--out", os.path.join(spec["folder"], f"{index}-{command}.blend")]
            args = parser.parse_args(argv + ["--json"])
            t0 = time.perf_counter()
            try:
                result = COMMANDS[command](args)
                if "qa" not in result and hasattr(cli, "qa_of_result"):  # as `main` does for --json
                    result["qa"] = cli.qa_of_result(result)
            except (HumanAnimError, UsageError) as error:
                record["error"] = f"{command}: {' '.join(str(error).split())}"
                record["failed_step"] = index
                return 2
            result = json.loads(json.dumps(result))  # exactly what --json prints
            record["steps"].append({"step": index, "command": command, "argv": argv + ["--json"],
                                    "seconds": round(time.perf_counter() - t0, 3), "qa": result.get("qa"),
                                    "result": result})
            qa = result.get("qa") or {}
            if getattr(args, "strict", False) and qa.get("passed") is False:  # --strict: a failed QA fails
                warning = (qa.get("warnings") or ["see the record"])[0]
                record["error"] = f"{command}: the result fails the motion QA: {warning}"
                record["failed_step"] = index
                return 3
            blends = [p for p in result.get("wrote", []) if str(p).endswith(".blend")]
            if blends:
                current = blends[0]
        armature = next((s["result"].get("armature") for s in reversed(record["steps"])
                         if s["result"].get("armature")), None)
        try:
            _write_thumbnail(os.path.join(spec["folder"], THUMBNAIL), armature, record)
        except Exception as error:  # a missing picture is not a failed take: say why in the record
            record["thumbnail_error"] = f"{type(error).__name__}: {error}"
    record["status"] = "done"
    record["result_file"] = os.path.basename(current) if os.path.dirname(current) == spec["folder"] else None
    return 0


_PARSER = []


def _parser():
    """The command line parser, built once per process (a forked take inherits its starter's)."""
    if not _PARSER:
        from ..cli import build_parser
        _PARSER.append(build_parser())
    return _PARSER[0]


def _subparsers(parser):
    return next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction").choices


def _write_thumbnail(path, armature_name, record):
    """Bone segments of the result at a few frames, drawn as an onion-skin stick figure."""
    import bpy
    from .report import stick_figure_svg
    obj = bpy.data.objects.get(armature_name) if armature_name else None
    if obj is None or obj.type != "ARMATURE":
        obj = next((o for o in bpy.data.objects if o.type == "ARMATURE"), None)
    if obj is None:
        raise ValueError("no armature to draw")
    scene = obj.users_scene[0] if obj.users_scene else bpy.context.scene
    action = obj.animation_data.action if obj.animation_data else None
    start, end = (action.frame_range if action else (scene.frame_current, scene.frame_current))
    frames = sorted({round(start + (end - start) * i / max(1, THUMBNAIL_POSES - 1)) for i in range(THUMBNAIL_POSES)})
    poses = []
    world = obj.matrix_world
    for frame in frames:
        scene.frame_set(int(frame))
        # parentless bones are often a placement joint at the origin, not part of the body
        poses.append([[tuple(world @ pb.head), tuple(world @ pb.tail)] for pb in obj.pose.bones if pb.parent])
    with open(path + ".tmp", "w", encoding="utf-8") as f:
        f.write(stick_figure_svg(poses, title=f"{obj.name}: frames {frames[0]}-{frames[-1]}"))
    os.replace(path + ".tmp", path)
    record["thumbnail"] = THUMBNAIL


def _exit_with_parent(before_exit=None):
    """If the batch worker that started this take dies (killed, or its machine's scheduler gone),
    stop too: an orphaned take would only burn a core while its work is redone elsewhere."""
    parent = os.getppid()

    def watch():
        while os.getppid() == parent:
            time.sleep(0.5)
        if before_exit:
            before_exit()
        os._exit(3)
    threading.Thread(target=watch, daemon=True).start()


def serve():
    """The take starter of one batch worker (`... take --serve`): imports Blender and registers
    the add-on once, then for every spec path read on stdin forks a new process that runs that
    take (so each take still has its own process: a crash or a leak dies with it) and answers
    `pid N` when the take starts and `exit STATUS` when it ends. A forked take starts in
    milliseconds where a fresh interpreter spends seconds importing Blender."""
    protocol = os.fdopen(os.dup(1), "w", buffering=1)
    os.dup2(2, 1)  # whatever Blender prints goes to stderr, never into the protocol
    child = []

    def kill_child():
        if child:
            try:
                os.killpg(child[0], 9)
            except ProcessLookupError:
                pass
    _exit_with_parent(kill_child)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the driver's: it stops the workers, we follow
    import bpy  # noqa: F401
    from ..cli import _registered
    _parser()
    with _registered():
        protocol.write("ready\n")
        for line in sys.stdin:
            spec = line.strip()
            if not spec:
                continue
            pid = os.fork()
            if pid == 0:
                _forked_take(spec)
            child[:] = [pid]
            protocol.write(f"pid {pid}\n")
            _, status = os.waitpid(pid, 0)
            child.clear()
            protocol.write(f"exit {os.waitstatus_to_exitcode(status)}\n")


def _forked_take(spec):
    """In the forked process: its own session (the runner kills the group on a timeout), the
    take's folder as the working directory, its output in take.log; never returns."""
    status = 1
    try:
        os.setsid()
        folder = os.path.dirname(spec)
        os.chdir(folder)
        log = os.open(os.path.join(folder, "take.log"), os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        os.dup2(log, 1)
        os.dup2(log, 2)
        sys.stdin.close()
        status = main([spec])
    except BaseException:
        traceback.print_exc()
    finally:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(status)


if __name__ == "__main__":
    if sys.argv[1:] == ["--serve"]:
        serve()
    else:
        sys.exit(main(sys.argv[1:]))
