"""Every batch command on motion nobody tuned for: a sample of the Bandai Namco corpus covering
every motion type, and the bundled CMU clips, each result held to the motion QA's thresholds.

The sample is one clip of every motion type (18 clips with the two CMU clips); every command runs
on a third of them in rotation (and `info` on all), so every command sees clips of six motion types
and every motion type goes through three commands, in a few minutes. benchmarks/quality.py runs
every command on every clip. A failure that comes from a solver method being fixed is listed in
KNOWN with its reason (docs/qa.md says the same): the threshold stays, the case is an expected
failure until the method is fixed."""

import pytest

import corpus_runs

pytestmark = pytest.mark.slow
pytest.importorskip("bpy")

SAMPLE = corpus_runs.sample(1)
PAIRS = [(clip, command) for i, clip in enumerate(SAMPLE) for k, command in enumerate(corpus_runs.COMMANDS)
         if command == "info" or (i + k) % 3 == 0]

# (command, motion type or "*") -> why it fails today (the method's owner is fixing it)
KNOWN = {
    ("synthesize", "*"): "Motion Queue 'connect' turns the legs tens of degrees between single frames "
                         "(transitions, issue 23 item 3)",
    ("walk", "*"): "Walk Along Path refuses Bandai Namco's skeleton (foot bones vertical in the rest pose) "
                   "and snaps the swing thigh once per step (walk cycle law, issue 23 item 3)",
    ("control", "*"): "Dynamic Control with 3 kg per hand jerks the arms when the loads are picked up "
                      "(loads placed on the hand bones, issue 23 item 3)",
}


def known(command, clip):
    kind = corpus_runs.motion_type(clip)
    return KNOWN.get((command, kind)) or KNOWN.get((command, "*"))


def test_the_corpus_is_there_or_the_reason_is_given():
    if not corpus_runs.CORPUS.is_dir():
        pytest.skip(f"the Bandai Namco corpus is not at {corpus_runs.CORPUS} (../shared/data/mocap/bandai-namco-1 "
                    "beside the repository): only the bundled CMU clips are run")
    kinds = {corpus_runs.motion_type(c) for c in SAMPLE}
    assert {"walk", "run", "dash", "kick", "punch", "bow", "dance-short", "cmu"} <= kinds
    for command in corpus_runs.COMMANDS:  # every command sees several motion types
        assert len({corpus_runs.motion_type(c) for c, k in PAIRS if k == command}) >= 6


@pytest.mark.parametrize("clip,command", PAIRS, ids=[f"{k}-{c.stem}" for c, k in PAIRS])
def test_command_on_corpus_clip_is_within_the_thresholds(clip, command, tmp_path):
    code, summary, err, _ = corpus_runs.run(command, clip, tmp_path)
    reason = known(command, clip)
    assert "Traceback" not in err
    if code != 0:
        if reason and code == 2:
            pytest.xfail(f"{reason}: {err.strip().splitlines()[-1]}")
        pytest.fail(f"exit {code}: {err.strip()[-500:]}")
    qa = summary["qa"]
    assert qa["measures"]["nonfinite"]["passed"] is True
    assert qa["measures"]["figure_height"]["passed"] is True, qa["measures"]["figure_height"]
    if command == "info":  # raw capture against the absolute caps: the unit and height are what matters
        assert summary["bvh_unit"] in ("m", "cm") and 1.0 < summary["figure_height_m"] < 2.3
        return
    assert qa["measures"]["source_untouched"]["passed"] is True
    if qa["passed"] is False and reason:
        pytest.xfail(f"{reason}: {qa['warnings'][0]}")
    assert qa["passed"] is not False, qa["warnings"]
