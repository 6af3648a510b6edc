"""A 12-take batch (10 Bandai Namco clips and the 2 bundled CMU clips, from a CSV manifest) on a
LocalCluster of 2 workers, with one worker killed while it runs a take; then a rerun that redoes
nothing; then a batch with a broken file and a missing one; then Ctrl-C in the middle of a run."""

import html
import json
import os
import re
import shutil
import signal
import subprocess
import time

import pytest

from batch_helpers import (CMU, SHORT_BANDAI, STOPPABLE, STOPPABLE_PIPELINE, bandai, batch_command, batch_env,
                           needs_dask, progress, run_batch, wait_for)

needs_dask()
psutil = pytest.importorskip("psutil")


def _takes(out_dir):
    return sorted(n for n in os.listdir(out_dir) if os.path.isfile(os.path.join(out_dir, n, "take.json")))


def _record(out_dir, name):
    with open(os.path.join(out_dir, name, "take.json")) as f:
        return json.load(f)


@pytest.fixture(scope="module")
def twelve(tmp_path_factory):
    """The 12-take batch with a worker killed mid-run: (out dir, summary, killed worker pid,
    the take that worker was running, its take process pid, the starter's pid)."""
    root = tmp_path_factory.mktemp("batch12")
    manifest = root / "takes.csv"
    rows = ["file,name,compress.degrees"]
    # the CMU clips first: the worker is killed in the middle of one of them (seconds of work, so
    # the take can't finish between finding it and the kill)
    rows += [f"{path},cmu-{os.path.basename(path)[8:10]}," for path in CMU]
    rows += [f"{bandai(n)},,{'0.25' if i == 0 else ''}" for i, n in enumerate(SHORT_BANDAI)]
    manifest.write_text("\n".join(rows) + "\n")
    out = str(root / "out")
    driver = subprocess.Popen(batch_command(str(manifest), "--pipeline", "compress --degrees 1", "--out-dir", out,
                                            "--workers", "2", "--json", "--no-progress"),
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=batch_env())
    try:
        def busy_worker():  # a worker whose starter has been running a CMU take for a moment
            for proc in psutil.Process(driver.pid).children(recursive=True):
                try:
                    if "--serve" in proc.cmdline() and proc.children():
                        take = proc.children()[0]
                        if "cmu-" in take.cwd() and time.time() - take.create_time() > 0.5:
                            return proc.parent(), proc, take
                except psutil.NoSuchProcess:
                    continue
            return None
        worker, starter, take_proc = wait_for(busy_worker, 300, "a worker running a CMU take")
        take_name = os.path.basename(take_proc.cwd()).rsplit(".", 1)[0]
        worker.send_signal(signal.SIGKILL)
        stdout, stderr = driver.communicate(timeout=600)
    finally:
        if driver.poll() is None:
            driver.kill()
    assert driver.returncode == 0, stderr[-2000:]
    return out, json.loads(stdout), worker.pid, take_name, take_proc.pid, starter.pid


def test_twelve_takes_all_done_despite_a_killed_worker(twelve):
    out, summary, killed, take_name, take_pid, starter_pid = twelve
    assert summary["takes"] == 12 and summary["done"] == 12 and summary["failed"] == 0 and summary["ran"] == 12
    assert summary["engine"]["kind"] == "local" and summary["engine"]["workers"] == 2
    assert summary["engine"]["threads_per_worker"] == 1
    assert _takes(out) == sorted([f"dataset-1_{n}" for n in SHORT_BANDAI] + ["cmu-01", "cmu-03"])
    assert os.listdir(os.path.join(out, ".partial")) == []  # nothing half-written left behind
    # the take the killed worker was running was done again, by a worker that lived
    redone = _record(out, take_name)
    assert redone["status"] == "done" and not redone["worker"].endswith(f":{killed}")
    # the killed worker's starter and take process did not outlive it
    time.sleep(1.5)
    for pid in (take_pid, starter_pid):
        assert not psutil.pid_exists(pid) or psutil.Process(pid).status() == psutil.STATUS_ZOMBIE


def test_every_take_has_its_result_qa_of_every_step_and_a_thumbnail(twelve):
    out, summary, *_ = twelve
    for row in summary["results"]:
        record = _record(out, row["name"])
        (step,) = record["steps"]
        assert step["command"] == "compress" and step["argv"][1] == row["file"]
        # what `compress --json` reports, whole (its `qa` too when the command has one)
        assert step["result"]["keys_after"] < step["result"]["keys_before"]
        assert step["qa"] == step["result"].get("qa")
        assert row["result_file"] == "1-compress.blend" and os.path.getsize(os.path.join(out, row["name"], "1-compress.blend")) > 0
        with open(os.path.join(out, row["name"], "result.svg")) as f:
            svg = f.read()
        assert svg.startswith("<svg") and svg.count("<line") >= 20
    # the manifest's per-take option reached its take only
    first = _record(out, f"dataset-1_{SHORT_BANDAI[0]}")["steps"][0]["result"]
    second = _record(out, f"dataset-1_{SHORT_BANDAI[1]}")["steps"][0]["result"]
    assert first["tolerance_deg"] == 0.25 and second["tolerance_deg"] == 1.0


def test_summary_files_and_report_agree_with_the_run(twelve):
    out, summary, *_ = twelve
    with open(os.path.join(out, "summary.json")) as f:
        assert json.load(f)["done"] == 12
    state = progress(out)
    assert state["done"] == 12 and state["failed"] == 0 and state["remaining"] == 0 and not state["running"]
    with open(os.path.join(out, "report.html")) as f:
        page = f.read()
    assert page.count('<tr class="done"') == 12 and 'class="failed"' not in page


def test_rerun_redoes_nothing(twelve):
    out, summary, *_ = twelve
    before = {n: os.path.getmtime(os.path.join(out, n, "take.json")) for n in _takes(out)}
    manifest = os.path.join(os.path.dirname(out), "takes.csv")
    status, again, stderr = run_batch(manifest, "--pipeline", "compress --degrees 1", "--out-dir", out, "--workers", "2")
    assert status == 0, stderr
    assert again["skipped"] == 12 and again["ran"] == 0 and again["done"] == 12
    assert again["engine"]["kind"] == "none"  # not even a cluster was started
    assert {n: os.path.getmtime(os.path.join(out, n, "take.json")) for n in _takes(out)} == before


@pytest.fixture(scope="module")
def with_broken(tmp_path_factory):
    """A batch of two good clips, a broken file and a missing one: (out dir, summary)."""
    root = tmp_path_factory.mktemp("broken")
    broken = root / "broken.bvh"
    broken.write_text("HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0 nonsense\n")
    out = str(root / "out")
    status, summary, stderr = run_batch(bandai(SHORT_BANDAI[0]), str(broken), str(root / "gone.bvh"),
                                        bandai(SHORT_BANDAI[1]), "--pipeline", "compress", "--out-dir", out,
                                        "--workers", "2", "--retries", "2")
    assert status == 0, stderr
    return out, summary


def test_broken_and_missing_files_are_reported_and_the_others_done(with_broken):
    out, summary = with_broken
    assert (summary["done"], summary["failed"]) == (2, 2)
    rows = {r["name"]: r for r in summary["results"]}
    assert rows["broken"]["status"] == "failed" and rows["gone"]["status"] == "failed"
    assert rows["broken"]["attempts"] == 1  # bad input is not retried: it would fail the same way
    assert "compress:" in rows["broken"]["error"] and "\n" not in rows["broken"]["error"]
    assert "no such file" in rows["gone"]["error"]
    assert not os.path.exists(os.path.join(out, "broken")) and not os.path.exists(os.path.join(out, "gone"))
    assert _takes(out) == sorted(f"dataset-1_{n}" for n in SHORT_BANDAI[:2])
    with open(os.path.join(out, "report.html")) as f:
        page = f.read()
    assert page.index('class="failed"') < page.index('class="done"')  # failures first


def test_ctrl_c_keeps_finished_takes_and_the_rerun_does_only_the_rest(tmp_path):
    out = str(tmp_path / "out")
    clips = [bandai(n) for n in STOPPABLE]
    args = [*clips, "--pipeline", STOPPABLE_PIPELINE, "--out-dir", out, "--workers", "1", "--no-progress"]
    # started as a script's background job would be, with SIGINT ignored (that survives exec)
    driver = subprocess.Popen(batch_command(*args), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                              env=batch_env(), start_new_session=True,
                              preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))
    try:
        wait_for(lambda: (progress(out) or {}).get("done", 0) >= 2, 300, "two finished takes")
        os.killpg(driver.pid, signal.SIGINT)  # Ctrl-C: the terminal signals the whole process group
        _, stderr = driver.communicate(timeout=120)
    finally:
        if driver.poll() is None:
            driver.kill()
    assert driver.returncode == 2, stderr[-2000:]
    last = stderr.strip().splitlines()[-1]
    assert last.startswith("humananim batch: error: interrupted:") and "run the same command again" in last
    finished = _takes(out)
    assert 2 <= len(finished) < 6
    before = {n: os.path.getmtime(os.path.join(out, n, "take.json")) for n in finished}
    status, summary, stderr = run_batch(*args)
    assert status == 0, stderr
    assert summary["done"] == 6 and summary["skipped"] == len(finished) and summary["ran"] == 6 - len(finished)
    assert {n: os.path.getmtime(os.path.join(out, n, "take.json")) for n in finished} == before


def test_the_report_opens_from_file_in_headless_chromium(with_broken, tmp_path):
    """Chromium (Debian's package, installed by .ci/setup) loads the report from file:// with no
    server: failed rows first with their errors, every thumbnail image loaded."""
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        pytest.fail("chromium is missing: .ci/setup installs Debian's chromium and chromium-driver")
    out, summary = with_broken
    with open(os.path.join(out, "report.html")) as f:
        page = f.read()
    # the same page with a probe that records, once loaded, what the browser made of it
    probe = page.replace("</body>", PROBE + "</body>")
    check = os.path.join(out, "report-check.html")
    with open(check, "w") as f:
        f.write(probe)
    flags = [chromium, "--headless", "--no-sandbox", "--disable-gpu", "--allow-file-access-from-files",
             f"--user-data-dir={tmp_path / 'profile'}", "--virtual-time-budget=10000"]
    dom = subprocess.run(flags + ["--dump-dom", "file://" + check], stdout=subprocess.PIPE,
                         stderr=subprocess.DEVNULL, text=True, timeout=120).stdout
    found = re.search(r'data-probe="([^"]*)"', dom)
    assert found, dom[:500]
    probe = json.loads(html.unescape(found.group(1)))
    assert probe["statuses"] == ["failed", "failed", "done", "done"]
    assert all(e for e in probe["errors"][:2])
    assert probe["images"] == [[160, 120], [160, 120]]  # both thumbnails loaded from file://
    shot = tmp_path / "report.png"
    subprocess.run(flags + [f"--screenshot={shot}", "--window-size=1000,700", "file://" + os.path.join(out, "report.html")],
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=120)
    assert shot.stat().st_size > 5000


PROBE = """<script>window.addEventListener("load", () => {
  const rows = [...document.querySelectorAll("tbody tr")];
  document.body.setAttribute("data-probe", JSON.stringify({
    statuses: rows.map(r => r.className),
    errors: rows.map(r => (r.querySelector(".err") || {}).textContent || ""),
    images: [...document.images].map(i => [i.naturalWidth, i.naturalHeight])}));
});</script>"""
