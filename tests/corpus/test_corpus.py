"""Every batch command on motion nobody tuned for: a sample of the Bandai Namco corpus covering
every motion type, and the bundled CMU clips, each result held to the motion QA's thresholds.

The sample is one clip of every motion type (18 clips with the two CMU clips); every command runs
on a third of them in rotation (and `info` on all), so every command sees clips of six motion types
and every motion type goes through three commands, in a few minutes. benchmarks/quality.py runs
every command on every clip. A failure that comes from a solver method being fixed is listed in
KNOWN with its reason (docs/qa.md says the same): the threshold stays, the case is an expected
failure until the method is fixed."""

import os
import tempfile

import pytest

os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="humananim-user-"))
import corpus_runs  # noqa: E402

pytestmark = pytest.mark.slow
bpy = pytest.importorskip("bpy")


@pytest.fixture(scope="module", autouse=True)
def humananim_registered():
    """The batch commands run with the add-on registered (by the add-on tests' session, or here).
    A fixture of this module, not a conftest.py: a second conftest module would take the name
    `conftest` that the add-on tests import their helpers from."""
    import humananim
    if hasattr(bpy.types.Armature, "humananim"):
        yield
        return
    humananim.register()
    yield
    humananim.unregister()

SAMPLE = corpus_runs.sample(1)
PAIRS = [(clip, command) for i, clip in enumerate(SAMPLE) for k, command in enumerate(corpus_runs.COMMANDS)
         if command == "info" or (i + k) % 3 == 0]

# command -> (the measures it fails on some clips today, why): the method's owner is fixing it
# (docs/qa.md lists the clips); any other failing measure fails the test
KNOWN = {
    "simulate": ({"pop_acceleration", "slide"},
                 "the closed-loop simulation lets walk-left's planted right foot slide 21 mm (limit 20) and "
                 "accelerates CMU 131_01's right elbow at 120 fps (3.9 deg/frame^2 against 2.8 allowed); the toe "
                 "spins are gone (made-up tails lumped into their parent)"),
    "control": ({"pop_velocity", "pop_acceleration", "slide"},
                "Dynamic Control with 3 kg per hand: the loads are taken up over a 0.25 s grip, but where the "
                "loaded arm asks more of the clavicle than its strength (waving, raised arms) passive control lets "
                "it give way and it swings (bye_active Shoulder_R 24.9 deg/frame against 8.7); a planted foot "
                "slides 1-11 mm past its limit on 3 clips, with or without the loads"),
    "synthesize": ({"pop_velocity", "pop_acceleration"},
                   "Motion Queue 'connect' straightens the flying knee where its keyframed root path takes the hip "
                   "beyond the flying foot's reach (punch: 22 deg/frame against 19.7 allowed; CMU 131_03 10.6 "
                   "against 10.2; the 90-180 deg turns of the legs are gone)"),
    "walk": ({"pop_acceleration"},
             "Walk Along Path on a 3 m line at 1.3 m/s: the knee of some Bandai actors accelerates beyond the cap "
             "at a toe off (kick_normal 16.8 deg/frame^2, also in a steady walk; run_active 28.6 in the start; cap "
             "15 for a generated motion at 30 fps) and CMU 131_01 written at 120 fps has a kink in the ankle's "
             "velocity (3.2 against 0.94); the start and stop's long steps are gone (docs/walking.md)"),
    "blend": ({"slide", "pop_acceleration"},
              "blending a clip's end into its start: where holding a planted foot through the transition would "
              "pop the leg the hold is released and the foot drags (kick_normal 42 mm, slash_normal 56 mm); the "
              "blended joint angles of run_active's knee accelerate past the capture's own"),
    "filter": ({"slide", "penetration", "pop_acceleration"},
               "the low-pass denoise drags planted feet (the CMU hop's take-off smeared into the contact before "
               "it; kick, dash, dance), a toe 2.1 cm under the floor, and smooths the dance's hips' Euler angles "
               "near gimbal lock"),
    "warp": ({"pop_acceleration"}, "moved LINEAR keys of a clip keyed on every frame play between their Euler "
                                   "angles at fractional frames: near gimbal lock the hips turn off the capture's "
                                   "path (dance, kick)"),
}


def known(command, failing):
    """Why `command` fails on `failing` measures today, or None when that is not known."""
    measures, reason = KNOWN.get(command, (set(), None))
    return reason if failing and set(failing) <= measures else None


def test_the_corpus_is_there_or_the_reason_is_given():
    if not corpus_runs.CORPUS.is_dir():
        pytest.skip(f"the Bandai Namco corpus is not at {corpus_runs.CORPUS} (../shared/data/mocap/bandai-namco-1 "
                    "beside the repository): only the bundled CMU clips are run")
    kinds = {corpus_runs.motion_type(c) for c in SAMPLE}
    assert {"walk", "run", "dash", "kick", "punch", "bow", "dance-short", "cmu"} <= kinds
    assert kinds == {corpus_runs.motion_type(c) for c in corpus_runs.corpus_clips()} | {"cmu"}
    for command in corpus_runs.COMMANDS:  # every command sees several motion types
        assert len({corpus_runs.motion_type(c) for c, k in PAIRS if k == command}) >= 6


@pytest.mark.parametrize("clip,command", PAIRS, ids=[f"{k}-{c.stem}" for c, k in PAIRS])
def test_command_on_corpus_clip_is_within_the_thresholds(clip, command, tmp_path):
    code, summary, err, _ = corpus_runs.run(command, clip, tmp_path)
    assert "Traceback" not in err
    if code != 0:
        pytest.fail(f"exit {code}: {err.strip()[-500:]}")
    qa = summary["qa"]
    assert qa["measures"]["nonfinite"]["passed"] is True
    assert qa["measures"]["figure_height"]["passed"] is True, qa["measures"]["figure_height"]
    if command == "info":  # raw capture against the absolute caps: the unit and height are what matters
        assert summary["bvh_unit"] in ("m", "cm") and 1.0 < summary["figure_height_m"] < 2.3
        return
    assert qa["measures"]["source_untouched"]["passed"] is not False  # None: a walk has no source
    failing = [name for name, m in qa["measures"].items() if m["passed"] is False]
    reason = known(command, failing)
    if reason:
        pytest.xfail(f"{reason}: {qa['warnings'][0]}")
    assert qa["passed"] is not False, qa["warnings"]
