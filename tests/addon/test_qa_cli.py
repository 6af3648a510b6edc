"""Bad input on the command line, every case of issue 23 and its kind: exit status 2, one line
on stderr (no traceback), nothing written; and the motion QA in every command's output."""

import json
import os

import pytest

from conftest import CMU_CLIPS

bpy = pytest.importorskip("bpy")

from humananim.humananim_addon import cli  # noqa: E402
from humananim.solver import bvh  # noqa: E402


def short_clip(folder, name="clip.bvh", frames=40, every=4, edit=None, rename=None):
    """The CMU walk's first `frames` frames at 30 fps, optionally edited (values, names)."""
    clip = bvh.read(CMU_CLIPS[0])
    values = clip.values[:frames * every:every].copy()
    text_clip = bvh.BVH(clip.names if rename is None else tuple(rename(n) for n in clip.names), clip.parents,
                        clip.offsets, clip.end_sites, clip.channels, clip.frame_time * every, clip.root_positions,
                        clip.rotations[:len(values)], values, None, clip.file_offsets, clip.file_ends)
    text = bvh.write(text_clip)
    if edit:
        text = edit(text)
    path = os.path.join(folder, name)
    with open(path, "w") as f:
        f.write(text)
    return path


def run(capfd, *args):
    code = cli.main([str(a) for a in args])
    out, err = capfd.readouterr()
    return code, out, err


def assert_refused(code, err, needle, out_path=None):
    assert code == 2, err
    lines = [line for line in err.splitlines() if line.startswith("humananim")]
    assert len(lines) == 1 and "error" in lines[0], err
    assert needle in lines[0], err
    assert "Traceback" not in err
    if out_path is not None:
        folder = os.path.dirname(out_path)
        assert not os.path.exists(out_path)
        assert not [f for f in os.listdir(folder) if ".tmp" in f] if os.path.isdir(folder) else True


def _replace_value(text, frame, column, value):
    head, motion = text.split("Frame Time:")
    lines = motion.splitlines()
    row = lines[frame].split()
    row[column] = value
    lines[frame] = " ".join(row)
    return head + "Frame Time:" + "\n".join(lines) + "\n"


@pytest.mark.parametrize("edit,needle", [
    (lambda t: _replace_value(t, 5, 10, "nan"), "NaN or infinite values (first at frame 5"),
    (lambda t: _replace_value(t, 7, 3, "1e400"), "NaN or infinite values (first at frame 7"),
    (lambda t: t.replace("Frames: 40", "Frames: 80"), "promises 80 frames"),
    (lambda t: t[:len(t) // 2], "not closed"),  # truncated in the hierarchy... or the motion
    (lambda t: t[:-2000], "complete frames (truncated?)"),
    (lambda t: "\x89PNG garbage " * 50, "not a BVH file"),
    (lambda t: t.replace("OFFSET", "OFFSET x", 1), "OFFSET"),
])
@pytest.mark.parametrize("command", ["info", "simulate", "compress"])
def test_a_broken_clip_is_refused_by_every_command(tmp_path, capfd, edit, needle, command):
    path = short_clip(str(tmp_path), edit=edit)
    if needle == "not closed" and "MOTION" in open(path).read():
        needle = "complete frames"
    out = tmp_path / "out" / "result.blend"
    extra = [] if command == "info" else ["--out", out]
    code, _, err = run(capfd, command, path, *extra)
    assert_refused(code, err, needle, str(out))


@pytest.mark.parametrize("args,needle", [
    (("info", "CLIP", "--mass", "-70"), "argument --mass: expected a finite number > 0, got '-70'"),
    (("info", "CLIP", "--scale", "-1"), "argument --scale: expected a finite number > 0"),
    (("info", "CLIP", "--scale", "0"), "argument --scale"),
    (("simulate", "CLIP", "--load-left", "nan"), "argument --load-left: expected a finite number >= 0, got 'nan'"),
    (("simulate", "CLIP", "--load-right", "-5"), "argument --load-right"),
    (("control", "CLIP", "--load-left", "-8"), "argument --load-left"),
    (("control", "CLIP", "--load-left", "1e400"), "argument --load-left"),
    (("simulate", "CLIP", "--tracking", "2"), "argument --tracking: expected a finite number >= 0 <= 1"),
    (("walk", "CLIP", "--speed", "0"), "argument --speed: expected a finite number > 0, got '0'"),
    (("walk", "CLIP", "--speed", "-1"), "argument --speed"),
    (("walk", "CLIP", "--segment-speeds", "1.2,0,1"), "--segment-speeds '1.2,0,1': expected speeds > 0"),
    (("walk", "CLIP", "--speed-keys", "0:1,3:nan"), "--speed-keys"),
    (("compress", "CLIP", "--degrees", "0"), "argument --degrees"),
    (("filter", "CLIP", "--denoise-hz", "-8"), "argument --denoise-hz"),
    (("filter", "CLIP", "--gains", "1,nan,1"), "--gains '1,nan,1'"),
    (("simulate", "CLIP", "--frames", "1", "500"), "outside 'clip' (frames 1-40)"),
    (("simulate", "CLIP", "--frames", "0", "20"), "frames start at 1"),
    (("control", "CLIP", "--frames", "30", "10"), "is empty"),
    (("control", "CLIP", "--frames", "-5", "10"), "frames start at 1"),
    (("control", "CLIP", "--frames", "1", "20", "--impulse", "30:Chest:0,30,0"),
     "impulse on 'Chest' at frame 30 is outside the frame range 1-20"),
    (("simulate", "CLIP", "--push", "90:Chest:0,300,0"), "push on 'Chest' at frame 90 is outside"),
    (("control", "CLIP", "--frames", "1", "20", "--load-left", "5", "--load-frame", "30"), "pick-up frame 30"),
    (("control", "CLIP", "--impulse", "10:Chest:0,30,0:nan"), "SECONDS must be a finite number"),
    (("control", "CLIP", "--impulse", "10:Chest:0,nan,0"), "three finite components"),
    (("control", "CLIP", "--impulse", "10:NoSuchBone:0,30,0"), "no bone named 'NoSuchBone'"),
    (("simulate", "CLIP", "--out", "__FILE__/x.blend"), "is not a writable folder"),
    (("simulate", "CLIP", "--out", "__DIR__"), "is a folder"),
])
def test_impossible_options_are_one_line(tmp_path, capfd, args, needle):
    clip = short_clip(str(tmp_path))
    a_file = tmp_path / "a_file.txt"
    a_file.write_text("x")
    args = [clip if a == "CLIP" else a.replace("__FILE__", str(a_file)).replace("__DIR__", str(tmp_path))
            for a in args]
    if "--out" not in args:
        args += ["--out", str(tmp_path / "out" / "result.blend")]
    try:
        code, _, err = run(capfd, *args)
    except SystemExit as stop:  # argparse's errors leave through exit(2)
        code, err = stop.code, capfd.readouterr().err
    assert_refused(code, err, needle, str(tmp_path / "out" / "result.blend"))


def test_a_figure_no_unit_makes_human_is_refused_with_the_scale_to_use(tmp_path, capfd):
    def giant(text):  # every OFFSET 2.5x: a 3.6 m figure in metres, 36 cm in dm...
        out = []
        for line in text.splitlines():
            w = line.split()
            out.append(" ".join(["OFFSET"] + [repr(2.5 * float(v)) for v in w[1:]]) if w and w[0] == "OFFSET" else line)
        return "\n".join(out) + "\n"
    path = short_clip(str(tmp_path), edit=giant)
    code, _, err = run(capfd, "info", path)
    assert_refused(code, err, "file units tall")
    assert "--scale 0.4" in err
    code, out, err = run(capfd, "info", path, "--scale", "0.4")
    assert code == 0, err
    assert "figure height: 1.4" in out  # 3.5 file units at 0.4 m each


def test_tab_separated_centimetre_clip_is_read_at_its_size(tmp_path, capfd):
    def centimetres_with_tabs(text):
        head, motion = text.split("MOTION")
        lines = []
        for line in head.splitlines():
            w = line.split()
            lines.append("\t".join(["OFFSET"] + [repr(100 * float(v)) for v in w[1:]]) if w and w[0] == "OFFSET"
                         else line.replace(" ", "\t"))
        rows = motion.splitlines()
        scaled = rows[:3] + ["\t".join(repr(float(v) * (100 if i < 3 else 1)) for i, v in enumerate(r.split()))
                             for r in rows[3:]]
        return "\r\n".join(lines) + "\r\nMOTION" + "\r\n".join(scaled) + "\r\n"
    path = short_clip(str(tmp_path), edit=centimetres_with_tabs)
    assert "\tOFFSET" not in open(path).read() and "OFFSET\t" in open(path).read()
    code, out, err = run(capfd, "info", path, "--json")
    assert code == 0, err
    info = json.loads(out)
    assert info["bvh_unit"] == "cm"
    assert 1.3 < info["figure_height_m"] < 1.6  # not 100x
    assert info["qa"]["measures"]["figure_height"]["passed"] is True


def test_bone_names_with_colons_in_impulses(tmp_path, capfd):
    path = short_clip(str(tmp_path), rename=lambda n: "mixamorig:" + n)
    out = tmp_path / "colon.blend"
    code, stdout, err = run(capfd, "control", path, "--frames", "1", "20", "--json", "--out", out,
                            "--impulse", "10:mixamorig:Chest:0,-20,0",
                            "--impulse", '12:"mixamorig:Chest":0,-20,0:0.1')
    assert code == 0, err
    summary = json.loads(stdout)
    assert summary["impulses"] == 2 and out.exists()
    assert "qa" in summary and summary["qa"]["measures"]


class _Bones(dict):
    pass


class _Obj:
    def __init__(self, *names):
        self.data = type("D", (), {"bones": _Bones({n: None for n in names})})()


@pytest.mark.parametrize("text,expected", [
    ("10:Spine:0,0,30", (10, "Spine", (0, 0, 30), 0.0)),
    ("10:Spine:0,0,30:0.2", (10, "Spine", (0, 0, 30), 0.2)),
    ("10:mixamorig:Spine2:0,-30,0", (10, "mixamorig:Spine2", (0, -30, 0), 0.0)),
    ("10:mixamorig:Spine2:0,-30,0:0.5", (10, "mixamorig:Spine2", (0, -30, 0), 0.5)),
    ('10:"mixamorig:Spine2":0,-30,0', (10, "mixamorig:Spine2", (0, -30, 0), 0.0)),
    ("10:a:b:c:1,2,3:1", (10, "a:b:c", (1, 2, 3), 1.0)),
    ("10:Left Arm.001:1,2,3", (10, "Left Arm.001", (1, 2, 3), 0.0)),
])
def test_arrow_parsing_takes_any_bone_name(text, expected):
    obj = _Obj("Spine", "mixamorig:Spine2", "a:b:c", "Left Arm.001")
    frame, bone, vector, seconds = cli.parse_arrow(text, obj, "--impulse", 0.0)
    assert (frame, bone, tuple(vector), seconds) == expected


@pytest.mark.parametrize("text", ["10", "10:Spine", "x:Spine:0,0,1", "10:Spine:0,0", "10:Spine:0,0,1:x"])
def test_arrow_parsing_refuses_what_is_not_an_arrow(text):
    with pytest.raises(cli.UsageError):
        cli.parse_arrow(text, _Obj("Spine"), "--impulse", 0.0)


def test_one_frame_clips_are_refused_by_simulate_and_compress(tmp_path, capfd):
    path = short_clip(str(tmp_path), frames=1)
    out = tmp_path / "o" / "r.blend"
    code, _, err = run(capfd, "simulate", path, "--out", out)
    assert_refused(code, err, "at least", str(out))
    code, _, err = run(capfd, "compress", path, "--out", out)
    assert_refused(code, err, "at least 2 are needed", str(out))


def test_a_failed_save_leaves_the_old_file_and_no_temporary(tmp_path, capfd, monkeypatch):
    path = short_clip(str(tmp_path))
    out = tmp_path / "r.blend"
    out.write_bytes(b"an earlier result")

    def failing_save(path):
        with open(path, "wb") as f:
            f.write(b"half")
        raise RuntimeError("Error: disk full\nmore lines")
    monkeypatch.setattr(cli, "_save_mainfile", failing_save)
    code, _, err = run(capfd, "compress", path, "--out", out)
    assert_refused(code, err, "cannot write")
    assert out.read_bytes() == b"an earlier result"
    assert [p.name for p in tmp_path.iterdir() if ".tmp" in p.name] == []


def test_every_command_reports_the_qa_in_text_and_json(tmp_path, capfd):
    path = short_clip(str(tmp_path))
    out = tmp_path / "c.blend"
    code, stdout, err = run(capfd, "compress", path, "--out", out, "--json")
    assert code == 0, err
    qa = json.loads(stdout)["qa"]
    assert qa["passed"] is True and qa["sources"] == ["clip"] and qa["action"] != "clip"
    assert set(qa["measures"]) >= {"slide", "penetration", "pop_velocity", "pop_acceleration", "bone_length",
                                   "figure_height", "nonfinite", "source_untouched"}
    assert qa["measures"]["source_untouched"]["passed"] is True
    code, stdout, err = run(capfd, "compress", path, "--out", out)
    assert code == 0 and "QA passed" in stdout


def test_a_result_beyond_the_thresholds_warns_naming_frames_and_bones(tmp_path, capfd):
    path = short_clip(str(tmp_path))
    out = tmp_path / "w.blend"
    # squeeze frames 10-30 into two frames: every joint turns several frames' worth at once
    code, stdout, err = run(capfd, "warp", path, "--map", "10:10,30:12", "--out", out, "--json")
    assert code == 0, err
    qa = json.loads(stdout)["qa"]
    assert qa["passed"] is False
    assert qa["measures"]["pop_velocity"]["passed"] is False
    warning = [line for line in err.splitlines() if "warning: QA:" in line]
    assert warning and any("at frame" in w and "'" in w for w in warning)
    code, stdout, err = run(capfd, "warp", path, "--map", "10:10,30:12", "--out", out, "--strict")
    assert code == 3 and "WARNING" in stdout
