"""The Batch panel in a headless bpy session: Start returns at once with the batch running in the
background, the polling function (what the UI's timer calls; timers never fire headless) moves
the progress on and ends with the report; Stop ends a batch as Ctrl-C would and Start again does
only the rest; the panel draws in both states."""

import json
import os
import sys
import tempfile
import time

import pytest

os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="humananim-user-"))
from batch_helpers import SHORT_BANDAI, STOPPABLE, STOPPABLE_PIPELINE, bandai, needs_dask  # noqa: E402

needs_dask()
import bpy  # noqa: E402

from humananim import panels  # noqa: E402
from humananim.humananim_addon.batch import blender as batch_blender  # noqa: E402
from humananim.operators import batch as batch_ops  # noqa: E402


@pytest.fixture(scope="module", autouse=True)
def registered():
    import humananim
    if hasattr(bpy.types.Scene, "humananim_batch"):  # the add-on tests' session already registered it
        yield
        return
    humananim.register()
    yield
    humananim.unregister()


class Layout:
    """Records what the panel draws; checks every property exists."""

    def __init__(self, log):
        self.log = log

    def __getattr__(self, name):
        if name in ("row", "column", "box"):
            return lambda *a, **k: Layout(self.log)
        raise AttributeError(name)

    def prop(self, data, name, **_):
        assert name in data.bl_rna.properties, name
        self.log.append(("prop", name))

    def operator(self, idname, **_):
        module, op = idname.split(".")
        getattr(getattr(bpy.ops, module), op).get_rna_type()
        self.log.append(("operator", idname))

    def progress(self, factor=0.0, text="", **_):
        self.log.append(("progress", round(factor, 3), text))

    def label(self, text="", **_):
        self.log.append(("label", text))


def draw(context):
    log = []
    (panel,) = [c for c in panels.CLASSES if getattr(c, "bl_label", "") == "Batch"]
    assert panel.poll(context)  # no armature needed: a batch works on files
    panel.draw(type("P", (), {"layout": Layout(log)})(), context)
    return log


def _settings(tmp_path, clips, pipeline="info"):
    bpy.ops.wm.read_homefile(use_empty=True)
    s = bpy.context.scene.humananim_batch
    s.inputs = ";".join(bandai(n) for n in clips)
    s.pipeline = pipeline
    s.out_dir = str(tmp_path / "out")
    s.engine, s.workers, s.python, s.timeout = "LOCAL", 1, sys.executable, 300.0
    return s


def _poll_to_end(settings, scene_name, timeout=300):
    seen, end = [], time.monotonic() + timeout
    while time.monotonic() < end:
        next_poll = batch_ops._poll(scene_name)  # what the timer calls
        seen.append((settings.done, round(settings.fraction, 3), settings.status))
        if next_poll is None:
            return seen
        assert next_poll == batch_blender.POLL_SECONDS
        time.sleep(0.3)
    raise AssertionError("the batch did not end")


def test_start_returns_at_once_and_polling_shows_progress_and_the_report(tmp_path):
    s = _settings(tmp_path, SHORT_BANDAI[:3])
    assert ("operator", "humananim.batch_start") in draw(bpy.context)
    t0 = time.monotonic()
    assert bpy.ops.humananim.batch_start() == {"FINISHED"}
    assert time.monotonic() - t0 < 5.0  # the UI is not held while the batch runs
    assert s.running and batch_blender.JOBS["current"].poll()["running"]
    assert ("operator", "humananim.batch_stop") in draw(bpy.context)
    seen = _poll_to_end(s, bpy.context.scene.name)
    assert not s.running and s.error == ""
    assert (s.done, s.failed, s.total) == (3, 0, 3) and s.fraction == 1.0
    assert "3 of 3 done, 0 failed" in s.status
    assert os.path.isfile(s.report) and s.report.endswith("report.html")
    assert seen[0][0] < 3  # it was polled while running, not only after
    log = draw(bpy.context)
    assert ("operator", "humananim.batch_report") in log
    assert [e for e in log if e[0] == "progress"] == [("progress", 1.0, s.status)]


def test_stop_keeps_finished_takes_and_start_again_does_the_rest(tmp_path):
    s = _settings(tmp_path, STOPPABLE, STOPPABLE_PIPELINE)
    bpy.ops.humananim.batch_start()
    end = time.monotonic() + 300
    while s.done < 1 and time.monotonic() < end:
        batch_blender.poll_job(s)
        time.sleep(0.3)
    assert s.done >= 1
    bpy.ops.humananim.batch_stop()
    _poll_to_end(s, bpy.context.scene.name)
    assert s.error.startswith("humananim batch: error: interrupted:")
    kept = s.done
    assert kept < 6
    bpy.ops.humananim.batch_start()
    _poll_to_end(s, bpy.context.scene.name)
    summary = batch_blender.JOBS["current"].poll()["summary"]
    assert summary["done"] == 6 and summary["skipped"] >= kept and summary["ran"] == 6 - summary["skipped"]


def test_start_without_a_batch_python_is_one_clear_message(tmp_path, monkeypatch):
    s = _settings(tmp_path, SHORT_BANDAI[:1])
    s.python = ""
    monkeypatch.delenv("HUMANANIM_BATCH_PYTHON", raising=False)
    monkeypatch.setattr(batch_blender.batch_job, "_in_bpy_module", lambda: False)  # as inside Blender itself
    with pytest.raises(RuntimeError, match="set Batch Python"):
        bpy.ops.humananim.batch_start()


def test_blender_command_hands_the_batch_to_the_batch_python(tmp_path, monkeypatch, capsys):
    """`blender --command humananim batch ...` inside Blender (no dask there): the same batch runs
    in --python's interpreter and its summary is the command's."""
    from humananim.humananim_addon import cli
    from humananim.humananim_addon.batch import command
    monkeypatch.setattr(command, "_has_bpy_module", lambda: False)
    monkeypatch.delenv("HUMANANIM_BATCH_PYTHON", raising=False)
    out = str(tmp_path / "out")
    argv = ["batch", bandai(SHORT_BANDAI[0]), "--pipeline", "info", "--out-dir", out, "--workers", "1", "--json"]
    assert cli.blender_command(argv) == 2  # no batch interpreter given: one line, status 2
    assert capsys.readouterr().err.strip().startswith("humananim batch: error: the batch runs in a Python with bpy")
    assert cli.blender_command(argv + ["--python", sys.executable]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["delegated_to"] == sys.executable and summary["done"] == 1
    assert os.path.isfile(os.path.join(out, f"dataset-1_{SHORT_BANDAI[0]}", "take.json"))
