"""The batch's progress line, summary rows and HTML report from hand-made records (no bpy, no
dask): the QA of every step as the commands' --json reports it, failures first."""

import json

from humananim.humananim_addon.batch import report

QA_FAILED = {"passed": False, "warnings": ["planted foot slides: 3.2 cm (limit 2) 'Foot_L' at frames 10-14"],
             "measures": {"slide": {"value": 3.2, "unit": "cm", "limit": 2.0, "passed": False, "bone": "Foot_L"},
                          "penetration": {"value": 0.4, "unit": "cm", "limit": 1.0, "passed": True},
                          "pop_velocity": {"value": None, "unit": "deg/s", "limit": 900, "passed": None}}}


def _record(name, status="done", qa=None, error=None):
    steps = [] if status != "done" else [
        {"command": "control", "seconds": 1.5, "qa": qa, "result": {"wrote": ["/x/1-control.blend"],
                                                                    "max_foot_slide_mm": 4.0, "peak_stress_frame": 3}}]
    return {"name": name, "file": f"/clips/{name}.bvh", "status": status, "error": error, "steps": steps,
            "thumbnail": "result.svg" if status == "done" else None, "result_file": "1-control.blend",
            "wall_seconds": 2.0, "work_seconds": 1.5}


def test_progress_line_counts_and_eta():
    state = {"total": 12, "done": 5, "failed": 1, "remaining": 6, "eta_seconds": 75}
    assert report.progress_line(state, width=12) == "[######......] 5/12 done, 1 failed, 6 left, ETA 1:15"
    assert report.progress_line(dict(state, eta_seconds=None), width=4).endswith("ETA --:--")


def test_take_summary_carries_the_qa_and_its_verdict():
    row = report.take_summary(_record("walk", qa=QA_FAILED))
    assert row["qa_passed"] is False
    assert row["qa_warnings"] == ["control: " + QA_FAILED["warnings"][0]]
    assert row["steps"][0]["qa"] == QA_FAILED
    assert report.qa_figures(row["steps"][0]) == [("slide", "3.2 cm", True), ("penetration", "0.4 cm", False)]
    no_qa = report.take_summary(_record("run"))
    assert no_qa["qa_passed"] is None
    # without a qa object the command's own measures of its result are shown (not frame numbers)
    assert report.qa_figures(no_qa["steps"][0]) == [("max_foot_slide_mm", "4", False)]


def test_html_report_lists_failures_first_with_their_error_and_qa():
    rows = [report.take_summary(_record("a_walk", qa=QA_FAILED)),
            report.take_summary(_record("b_broken", status="failed", error="compress: line 4: bad OFFSET <x>")),
            report.take_summary(_record("c_run"), skipped=True)]
    summary = {"results": rows, "pipeline": ["control --load-left 5"], "done": 2, "failed": 1, "skipped": 1,
               "seconds": 12.0, "engine": {"description": "Dask LocalCluster, 2 worker processes x 1 thread"}}
    page = report.html_report(summary)
    assert page.index('id="take-b_broken"') < page.index('id="take-a_walk"') < page.index('id="take-c_run"')
    assert "compress: line 4: bad OFFSET &lt;x&gt;" in page  # escaped
    assert '<span class="bad">slide 3.2 cm</span>' in page and "QA 1 warning(s)" in page
    assert '<img src="a_walk/result.svg"' in page and "done (earlier run)" in page
    assert "<script" not in page


def test_stick_figure_svg_is_a_drawing_of_every_bone():
    pose = [[(0, 0, 0), (0, 0, 1)], [(0, 0, 1), (0.3, 0, 1.5)]]
    svg = report.stick_figure_svg([pose, pose], title="a <b>")
    assert svg.startswith("<svg") and svg.count("<line") == 4 and "a &lt;b&gt;" in svg


def test_summary_files_are_written_whole(tmp_path):
    summary = {"results": [], "pipeline": ["info"], "done": 0, "failed": 0, "skipped": 0, "seconds": 0.0,
               "engine": {"description": "none"}}
    path = report.write_summary(str(tmp_path), summary)
    assert json.loads((tmp_path / "summary.json").read_text())["pipeline"] == ["info"]
    assert path.endswith("report.html") and sorted(p.name for p in tmp_path.iterdir()) == ["report.html", "summary.json"]
