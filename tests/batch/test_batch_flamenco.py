"""The Flamenco job type: node (v20) runs the job-type file against a stub of Flamenco's author
API; the tasks it builds run the same steps, on the same files, into the same take folders as
`python -m humananim batch` plans."""

import json
import os
import shutil
import subprocess

import pytest

from humananim.humananim_addon.batch.plan import parse_pipeline, plan
from humananim.humananim_addon.cli import build_parser

JOB_TYPE = os.path.join(os.path.dirname(__file__), "..", "..", "humananim_addon", "batch",
                        "flamenco_humananim_batch.js")
NODE = shutil.which("node")

HARNESS = r"""
const fs = require("fs"), vm = require("vm");
const [file, settingsJson] = process.argv.slice(2);
const tasks = [];
const author = {
  Task: (name, type) => { const t = {name, type, commands: [], deps: []};
    t.addCommand = c => t.commands.push(c); t.addDependency = d => t.deps.push(d.name); return t; },
  Command: (name, params) => ({name, params}),
};
const context = vm.createContext({author, console});
vm.runInContext(fs.readFileSync(file, "utf8") + "\nthis.JOB_TYPE = JOB_TYPE; this.compileJob = compileJob;", context,
                {filename: file});
const job = {settings: JSON.parse(settingsJson), addTask: t => tasks.push(t)};
let error = null;
try { context.compileJob(job); } catch (e) { error = String(e.message); }
console.log(JSON.stringify({jobType: context.JOB_TYPE, tasks, error}));
"""

pytestmark = pytest.mark.skipif(NODE is None, reason="node is not installed")


def compile_job(tmp_path, **settings):
    harness = tmp_path / "harness.js"
    harness.write_text(HARNESS)
    run = subprocess.run([NODE, str(harness), os.path.abspath(JOB_TYPE), json.dumps(settings)],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, timeout=60)
    assert run.returncode == 0, run.stderr
    return json.loads(run.stdout)


def test_the_job_type_declares_its_settings(tmp_path):
    result = compile_job(tmp_path, takes="/a.bvh", pipeline="info", out_dir="/out")
    jt = result["jobType"]
    assert jt["label"] == "HumanAnim Batch"
    keys = {s["key"]: s for s in jt["settings"]}
    assert set(keys) == {"takes", "pipeline", "out_dir", "blender_args"}
    assert keys["out_dir"]["subtype"] == "dir_path" and keys["takes"]["required"]


def test_tasks_run_the_batch_pipeline_steps_into_the_batch_take_folders(tmp_path):
    files = ["/mnt/mocap/walk.bvh", "/mnt/mocap/run.bvh", "/mnt/other/walk.bvh", "/mnt/rigs/hero take.blend"]
    pipeline = "info -> control --load-left 5 --impulse '30:Hips:0,80,0' -> compress --degrees 0.5"
    result = compile_job(tmp_path, takes="\n".join(files[:2]) + ";" + ";".join(files[2:]), pipeline=pipeline,
                         out_dir="/mnt/out/", blender_args="--python-exit-code 1")
    assert result["error"] is None
    tasks = result["tasks"]
    steps = parse_pipeline([pipeline])
    takes = plan(files, steps, build_parser())
    assert [t["name"] for t in tasks] == [f"humananim-{t.name}" for t in takes]
    assert [t.name for t in takes] == ["walk", "run", "walk-2", "hero_take"]
    for task, take in zip(tasks, takes):
        assert task["type"] == "blender"
        expected, current = [], take.file
        for i, words in enumerate(take.steps, start=1):
            argv = [words[0], current] + words[1:]
            if words[0] != "info":
                current = f"/mnt/out/{take.name}/{i}-{words[0]}.blend"
                argv += ["--out", current]
            expected.append(["--python-exit-code", "1", "--command", "humananim"] + argv + ["--json"])
        assert [c["name"] for c in task["commands"]] == ["exec"] * 3
        assert [c["params"]["exe"] for c in task["commands"]] == ["{blender}"] * 3
        assert [c["params"]["args"] for c in task["commands"]] == expected
    # the quoted option is one word, as the shell and Python's shlex read it
    control = tasks[0]["commands"][1]["params"]["args"]
    assert control[control.index("--impulse") + 1] == "30:Hips:0,80,0"


def test_only_info_writes_nothing_among_the_file_commands():
    """The job type's WRITES_NOTHING list is the commands that read a file and have no --out."""
    sub = next(a for a in build_parser()._actions if a.__class__.__name__ == "_SubParsersAction")
    no_out = sorted(name for name, p in sub.choices.items()
                    if [a.dest for a in p._actions if not a.option_strings] == ["file"]
                    and "--out" not in {s for a in p._actions for s in a.option_strings})
    with open(JOB_TYPE) as f:
        declared = json.loads(f.read().split("const WRITES_NOTHING = ", 1)[1].split(";", 1)[0])
    assert no_out == declared == ["info"]


def test_mistakes_are_refused_when_the_job_is_submitted(tmp_path):
    assert compile_job(tmp_path, takes="", pipeline="info", out_dir="/o")["error"].startswith("no takes")
    assert compile_job(tmp_path, takes="/a.bvh", pipeline=" -> ", out_dir="/o")["error"] == "the pipeline is empty"
    assert "sets --out" in compile_job(tmp_path, takes="/a.bvh", pipeline="compress --out x", out_dir="/o")["error"]
    assert "unclosed quote" in compile_job(tmp_path, takes="/a.bvh", pipeline="control --push 'x", out_dir="/o")["error"]
