"""Planning a batch without running it: inputs, manifests, pipelines, per-take options,
the options hash and the resumability check. No bpy, no dask."""

import json
import os
import time

import pytest

from humananim.humananim_addon.batch import plan as batch_plan
from humananim.humananim_addon.batch.plan import PlanError, Step, parse_pipeline, plan
from humananim.humananim_addon.cli import build_parser

PARSER = build_parser()


def _bvh(folder, name):
    path = os.path.join(folder, name)
    with open(path, "w") as f:
        f.write("HIERARCHY\n")
    return path


def test_pipeline_syntax_takes_any_registered_command():
    steps = parse_pipeline(["control --load-left 5 -> compress --degrees 0.5", "filter --denoise-hz 6"])
    assert [(s.command, s.args) for s in steps] == [("control", ["--load-left", "5"]),
                                                   ("compress", ["--degrees", "0.5"]),
                                                   ("filter", ["--denoise-hz", "6"])]
    assert str(steps[0]) == "control --load-left 5"
    with pytest.raises(PlanError, match="empty"):
        parse_pipeline([" "])


def test_steps_are_checked_against_the_command_line(tmp_path):
    f = _bvh(tmp_path, "a.bvh")
    with pytest.raises(PlanError, match="unknown pipeline step 'teleport'"):
        plan([f], [Step("teleport", ["--to", "rig.blend"])], PARSER)
    with pytest.raises(PlanError, match="the batch sets --out itself"):
        plan([f], [Step("compress", ["--out", "x.blend"])], PARSER)
    with pytest.raises(PlanError, match=r"pipeline step 'compress --degrees lots': .*lots"):
        plan([f], [Step("compress", ["--degrees", "lots"])], PARSER)
    with pytest.raises(PlanError, match="unknown pipeline step 'batch'"):
        plan([f], [Step("batch", [])], PARSER)


def test_inputs_from_folders_and_globs_sorted_without_repeats(tmp_path):
    for name in ("b.bvh", "a.bvh", "notes.txt", "c.blend", "d.fbx"):
        _bvh(tmp_path, name)
    takes = plan([str(tmp_path), str(tmp_path / "*.bvh")], [Step("info", [])], PARSER)
    assert [t.name for t in takes] == ["a", "b", "c", "d"]  # .fbx goes through Blender's FBX importer
    assert all(os.path.isabs(t.file) for t in takes)
    with pytest.raises(PlanError, match="no .bvh, .fbx or .blend files"):
        plan([str(tmp_path / "*.glb")], [Step("info", [])], PARSER)


def test_same_stem_in_two_folders_gets_two_take_folders(tmp_path):
    for sub in ("x", "y"):
        os.makedirs(tmp_path / sub)
        _bvh(tmp_path / sub, "walk.bvh")
    takes = plan([str(tmp_path / "x"), str(tmp_path / "y")], [Step("info", [])], PARSER)
    assert [t.name for t in takes] == ["walk", "walk-2"]


def test_csv_manifest_routes_per_take_options_to_their_steps(tmp_path):
    _bvh(tmp_path, "a.bvh")
    _bvh(tmp_path, "b.bvh")
    (tmp_path / "takes.csv").write_text("file,name,control.load-left,frames,compress.degrees\n"
                                        "a.bvh,first,5,1 40,\n"
                                        "b.bvh,,,,0.25\n")
    steps = parse_pipeline(["control --strength 0.8 -> compress"])
    first, second = plan([str(tmp_path / "takes.csv")], steps, PARSER)
    assert first.name == "first" and second.name == "b"
    assert first.file == str(tmp_path / "a.bvh")
    # a plain option goes to every step that has it (control has --frames, compress has not)
    assert first.steps == [["control", "--strength", "0.8", "--load-left", "5", "--frames", "1", "40"],
                           ["compress"]]
    assert second.steps == [["control", "--strength", "0.8"], ["compress", "--degrees", "0.25"]]
    assert first.options_hash != second.options_hash


def test_json_manifest_with_flags_lists_and_numbers(tmp_path):
    _bvh(tmp_path, "a.bvh")
    (tmp_path / "takes.json").write_text(json.dumps({"takes": [
        {"file": "a.bvh", "name": "walk.v2", "control.tracking-only": True, "control.frames": [1, 30], "compress.cm": 0.3,
         "control.ground": None}]}))
    (take,) = plan([str(tmp_path / "takes.json")], parse_pipeline(["control -> compress"]), PARSER)
    assert take.steps == [["control", "--tracking-only", "--frames", "1", "30"], ["compress", "--cm", "0.3"]]
    assert take.name == "walk.v2"  # a manifest's name is kept whole


def test_manifest_mistakes_are_one_line_errors(tmp_path):
    _bvh(tmp_path, "a.bvh")
    (tmp_path / "bad.csv").write_text("file,compress.wobble\na.bvh,3\n")
    with pytest.raises(PlanError, match="compress has no option --wobble"):
        plan([str(tmp_path / "bad.csv")], parse_pipeline(["compress"]), PARSER)
    (tmp_path / "nostep.csv").write_text("file,wobble\na.bvh,3\n")
    with pytest.raises(PlanError, match="no step has the option --wobble"):
        plan([str(tmp_path / "nostep.csv")], parse_pipeline(["compress"]), PARSER)
    (tmp_path / "nofile.csv").write_text("name\nx\n")
    with pytest.raises(PlanError, match="has no 'file'"):
        plan([str(tmp_path / "nofile.csv")], parse_pipeline(["compress"]), PARSER)
    (tmp_path / "broken.json").write_text("{ not json")
    with pytest.raises(PlanError, match="cannot read manifest"):
        plan([str(tmp_path / "broken.json")], parse_pipeline(["compress"]), PARSER)


def _finish(take, out_dir, outputs=("1-compress.blend",)):
    folder = take.folder(out_dir)
    os.makedirs(folder, exist_ok=True)
    for name in outputs:
        open(os.path.join(folder, name), "w").close()
    batch_plan.write_json_atomic(os.path.join(folder, batch_plan.RECORD), {
        "name": take.name, "file": take.file, "status": "done", "options_hash": take.options_hash,
        "outputs": list(outputs)})


def test_a_take_is_complete_only_with_its_record_outputs_options_and_a_newer_result(tmp_path):
    src = tmp_path / "in"
    os.makedirs(src)
    f = _bvh(src, "a.bvh")
    past = time.time() - 100
    os.utime(f, (past, past))
    out = str(tmp_path / "out")
    (take,) = plan([f], parse_pipeline(["compress --degrees 0.5"]), PARSER)
    assert not batch_plan.is_complete(take, out)
    _finish(take, out)
    assert batch_plan.is_complete(take, out)
    (other_options,) = plan([f], parse_pipeline(["compress --degrees 0.25"]), PARSER)
    assert not batch_plan.is_complete(other_options, out)  # options changed: redo
    os.remove(os.path.join(take.folder(out), "1-compress.blend"))
    assert not batch_plan.is_complete(take, out)  # an output is missing: redo
    _finish(take, out)
    os.utime(f, None)  # the input changed after the result
    future = time.time() + 5
    os.utime(f, (future, future))
    assert not batch_plan.is_complete(take, out)


def test_write_json_atomic_leaves_no_temporary_file(tmp_path):
    path = tmp_path / "x.json"
    batch_plan.write_json_atomic(str(path), {"a": 1})
    assert json.loads(path.read_text()) == {"a": 1}
    assert os.listdir(tmp_path) == ["x.json"]


def test_the_batch_qa_fails_when_one_take_fails_and_names_the_take():
    from humananim.humananim_addon.batch.command import batch_qa
    ok = {"name": "walk", "qa_passed": True, "qa_warnings": []}
    bad = {"name": "kick", "qa_passed": False, "qa_warnings": ["slide 12 mm at foot.L, frames 3-9"]}
    broken = {"name": "broken", "qa_passed": None, "qa_warnings": []}
    assert batch_qa([ok, broken])["passed"] is True
    failed = batch_qa([ok, bad, broken])
    assert failed["passed"] is False
    assert failed["warnings"] == ["kick: slide 12 mm at foot.L, frames 3-9"]
    assert failed["note"].startswith("2 of 3 takes measured")
    assert batch_qa([broken])["passed"] is None
