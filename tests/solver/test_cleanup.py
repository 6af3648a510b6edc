"""Clean Up Capture's repairs (solver/cleanup) on hand-made faults injected into the bundled CMU
walk at known frames, and on the clean clip (nothing changes beyond the tolerances)."""

import functools
from pathlib import Path

import numpy as np
import pytest

from humananim.solver import bvh, rotations
from humananim.solver.cleanup import Options, clean_up, feet, glitches, jitter
from humananim.solver.trajectories import Trajectories

CMU = Path(__file__).resolve().parents[2] / "humananim_addon" / "data" / "mocap" / "cmu_131_01.bvh"


@functools.lru_cache(maxsize=None)
def _clip():
    raw = bvh.read(CMU)
    b = bvh.read(CMU, scale=1.7 / bvh.figure_height(raw))
    sk = bvh.skeleton(b)
    return sk, bvh.trajectories(b, sk)


def clip(step=1):
    """The CMU walk (120 fps, or every `step`-th frame) with its own glitches (the right wrist's
    turn, the thumb's flips) repaired: the clean original the faults are injected into."""
    sk, tr = _clip()
    q, p, _ = glitches.repair(tr.rotations[::step], tr.translations[::step, :1], tr.fps / step)
    t = tr.translations[::step].copy()
    t[:, :1] = p
    return sk, Trajectories(np.arange(1, len(q) + 1.0), tr.fps / step, q, t, np.eye(4))


def turned(q, angle_deg, axis):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    return rotations.multiply(q, rotations.from_axis_angle(np.concatenate(([np.radians(angle_deg)], axis))))


def deg(a, b):
    return np.degrees(rotations.angle_between(a, b))


def test_the_clip_own_glitches_are_found():
    sk, tr = _clip()
    q, _, events = glitches.repair(tr.rotations, tr.translations[:, :1], tr.fps)
    bones = {sk.names[ch[1]] for _, ch, _, _ in events if ch}
    assert {"RightWrist", "RThumb"} <= bones
    wrist = [(kind, a, b) for kind, ch, a, b in events if ch and sk.names[ch[1]] == "RightWrist"]
    assert any(a <= 236 <= b for _, a, b in wrist)  # the 55 deg turn in one frame near frame 236
    for name in ("RightWrist", "RThumb"):
        j = sk.names.index(name)
        assert deg(q[:-1, j], q[1:, j]).max() < deg(tr.rotations[:-1, j], tr.rotations[1:, j]).max() / 2
    untouched = [j for j, n in enumerate(sk.names) if n not in bones]
    assert deg(q[:, untouched], tr.rotations[:, untouched]).max() < 1e-6


@pytest.mark.parametrize("step, angle", [(1, 150.0), (4, 90.0), (4, 180.0)])
def test_single_frame_flip_repaired_within_2_deg(step, angle):
    sk, tr = clip(step)
    j, f = sk.names.index("LeftElbow"), len(tr.frames) // 2
    bad = tr.rotations.copy()
    bad[f, j] = turned(bad[f, j], angle, (0.3, -0.5, 0.8))
    q, _, events = glitches.repair(bad, tr.translations[:, :1], tr.fps)
    assert ("spike", ("rotation", j), f, f) in events
    assert deg(q[f, j], tr.rotations[f, j]) < 2.0
    assert deg(q, tr.rotations).max() < 2.0


@pytest.mark.parametrize("kind", ["held", "zero"])
def test_five_frame_dropout_filled(kind):
    sk, tr = clip()
    f = 500
    q, t = tr.rotations.copy(), tr.translations.copy()
    if kind == "held":
        q[f:f + 5], t[f:f + 5] = q[f - 1], t[f - 1]
    else:
        q[f:f + 5], t[f:f + 5] = [1.0, 0.0, 0.0, 0.0], 0.0
    out_q, out_p, events = glitches.repair(q, t[:, :1], tr.fps)
    assert ("dropout", None, f, f + 4) in events
    assert deg(out_q, tr.rotations).max() < 2.0
    assert np.abs(out_p[:, 0] - tr.translations[:, 0]).max() < 0.01


def test_position_spike_repaired():
    sk, tr = clip()
    p = tr.translations[:, :1].copy()
    p[300, 0] += [0.0, 0.25, 0.1]
    _, out, events = glitches.repair(tr.rotations, p, tr.fps)
    assert ("spike", ("position", 0), 300, 300) in events
    assert np.abs(out - tr.translations[:, :1]).max() < 0.002


def test_small_one_frame_position_spike_found_by_its_change_of_velocity():
    """5.5 cm out and straight back in one frame at 30 fps: each step is under the 5 g limit,
    the change of velocity (twice the jump) is not."""
    sk, tr = clip(4)
    p = tr.translations[:, :1].copy()
    p[60, 0] += [0.0, 0.055, 0.0]
    _, out, events = glitches.repair(tr.rotations, p, tr.fps)
    assert ("spike", ("position", 0), 60, 60) in events
    assert np.abs(out - tr.translations[:, :1]).max() < 0.002


def test_noise_size_from_alternation_white_noise_and_motion():
    """White noise alternates from frame to frame (its size is found); a fast smooth motion does
    not (next to nothing is taken for noise)."""
    rng = np.random.default_rng(3)
    noise = 0.01 * rng.standard_normal((600, 1, 3))
    size = jitter.alternating_size(noise)[0]
    median_length = 0.01 * np.median(np.linalg.norm(rng.standard_normal((20000, 3)), axis=1))
    assert size == pytest.approx(median_length, rel=0.15)
    t = np.arange(600) / 30.0
    wave = 0.3 * np.stack((np.sin(2 * np.pi * 3 * t), np.cos(2 * np.pi * 3 * t), 0 * t), axis=1)[:, None]
    assert jitter.alternating_size(wave)[0] < 0.05 * median_length


def test_quaternion_signs_made_continuous():
    sk, tr = clip()
    q = tr.rotations.copy()
    q[::7, 3] *= -1.0
    out, _, events = glitches.repair(q, tr.translations[:, :1], tr.fps)
    assert not events
    assert ((out[1:] * out[:-1]).sum(axis=-1) > 0).all()
    assert deg(out, tr.rotations).max() < 1e-6


def test_clean_clip_left_alone():
    sk, tr = clip()
    q, p, events = glitches.repair(tr.rotations, tr.translations[:, :1], tr.fps)
    assert not events and deg(q, tr.rotations).max() < 1e-6
    out, report = clean_up(sk, tr, Options(floor=False, skate=False))
    rms = np.sqrt(np.mean(deg(out.rotations, tr.rotations) ** 2))
    assert rms < 0.5
    assert report["repairs"][1]["rms_change_deg"] < 0.5


def kick(fps=30.0, seconds=4.0, noise_deg=1.0, seed=1):
    """One joint: a slow sway and a fast kick (90 deg out and back in 0.2 s), with jitter."""
    t = np.arange(0.0, seconds, 1.0 / fps)
    clean = np.radians(10 * np.sin(2 * np.pi * 0.5 * t) + 90 * np.exp(-0.5 * ((t - 2.0) / 0.04) ** 2))
    noisy = clean + np.radians(noise_deg) * np.random.default_rng(seed).standard_normal(len(t))
    to_q = lambda a: np.stack([np.cos(a / 2), np.sin(a / 2), 0 * a, 0 * a], axis=-1)[:, None]
    return t, to_q(clean), to_q(noisy)


@pytest.mark.parametrize("fps", [30.0, 120.0])
def test_jitter_removed_kick_kept(fps):
    t, clean, noisy = kick(fps)
    out = jitter.smooth_rotations(noisy, fps)
    calm = np.abs(t - 2.0) > 0.3
    before, after = deg(noisy, clean)[calm], deg(out, clean)[calm]
    assert np.sqrt(np.mean(after ** 2)) < 0.6 * np.sqrt(np.mean(before ** 2))
    peak = np.argmax(np.abs(t - 2.0) < 0.5 / fps)
    assert deg(out, clean)[peak] < 3.0  # the kick's peak kept
    plain = rotations.normalize(jitter.low_pass(rotations.make_continuous(noisy), fps, jitter.DEFAULT_CUTOFF_HZ))
    assert deg(plain, clean)[peak] > 10.0  # where a plain low-pass cuts the kick short


def test_floor_offset_removed():
    sk, tr = clip()
    position, orientation = tr.root_pose(sk)
    lifted = tr.with_root_pose(sk, position + [0.0, 0.0, 0.08], orientation)
    out, report = clean_up(sk, lifted, Options(glitches=False, jitter=False, skate=False))
    points = feet.foot_points(sk, tr.world_frames(sk))
    original_floor = feet.find_floor(points, feet.find_contacts(points, tr.fps))
    assert report["floor_m"] == pytest.approx(original_floor + 0.08, abs=0.005)
    after = feet.foot_points(sk, out.world_frames(sk))
    lowest = np.min([p[..., 2].min(axis=1) for p in after.values()], axis=0)
    assert lowest.min() > -0.001  # no point below the floor
    planted = feet.find_contacts(feet.foot_points(sk, lifted.world_frames(sk)), tr.fps)
    # the 8 cm offset gone: the planted feet where the same repair puts them on the clean capture
    # (each contact's lowest point on the floor; one through it lifted; one far above it, on
    # something else, left and counted)
    same, same_report = clean_up(sk, tr, Options(glitches=False, jitter=False, skate=False))
    own = feet.foot_points(sk, same.world_frames(sk))
    for side, p in after.items():
        low = p[planted[side]][..., 2].min(axis=1)
        assert low.min() > -0.001  # no sinking
        assert np.abs(low - own[side][planted[side]][..., 2].min(axis=1)).max() < 0.002
    assert report["repairs"][2]["hovering_contacts"] == same_report["repairs"][2]["hovering_contacts"]


def test_skate_removed_under_2_mm():
    sk, tr = clip()
    position, orientation = tr.root_pose(sk)
    drift = np.zeros_like(position)
    drift[:, 0] = 0.05 * np.sin(2 * np.pi * 0.3 * tr.times)  # the root drifts: the feet skate
    skating = tr.with_root_pose(sk, position + drift, orientation)
    planted = feet.planted_points(feet.foot_points(sk, skating.world_frames(sk)), tr.fps)
    assert feet.planted_slide(sk, skating, planted) > 0.02
    out, report = clean_up(sk, skating, Options(glitches=False, jitter=False, floor=False))
    assert feet.planted_slide(sk, out, planted) < 0.002
    # the body on its path over the ground; lowered a little where a straight stance leg can't reach
    before, after = skating.root_pose(sk)[0], out.root_pose(sk)[0]
    np.testing.assert_allclose(after[:, :2], before[:, :2], atol=1e-9)
    assert 0.0 <= (before[:, 2] - after[:, 2]).min() and (before[:, 2] - after[:, 2]).max() < 0.01
    entry = report["repairs"][3]
    assert entry["qa_after"]["slide"]["value"] < entry["qa_before"]["slide"]["value"]
    legs = {sk.roles.bone(f"{r}.{s}") for r in ("thigh", "shin", "foot", "toe") for s in "LR"}
    assert set(entry["bones"]) <= legs | {sk.names[sk.root]}  # the legs, and the pelvis lowered


def test_report_lists_every_repair_with_qa():
    sk, tr = clip(4)
    _, report = clean_up(sk, tr, Options(jitter=False))
    assert [r["repair"] for r in report["repairs"]] == ["glitches", "jitter", "floor", "skate", "physics"]
    assert report["repairs"][1] == {"repair": "jitter", "enabled": False}
    assert report["repairs"][4] == {"repair": "physics", "enabled": False}  # optional: off by default
    for r in (report["repairs"][0], report["repairs"][2], report["repairs"][3]):
        assert {"frames", "bones", "max_change_deg", "qa_before", "qa_after"} <= set(r)
        assert "penetration" in r["qa_after"]


def wave(fps=30.0, seconds=6.0, hz=2.0):
    """One joint waving (60 deg at `hz`) about a slowly turning axis: repeated fast motion."""
    t = np.arange(0.0, seconds, 1.0 / fps)
    angle = np.radians(60.0) * np.sin(2 * np.pi * hz * t)
    return t, np.stack([np.cos(angle / 2), np.sin(angle / 2), 0 * t, 0 * t], axis=-1)[:, None]


def test_dropout_in_repeated_motion_filled_from_the_clip():
    # a 10-frame gap in a 2 Hz wave at 30 fps: a spline through its ends cuts the wave short; the
    # same stretch elsewhere in the clip, warped onto the gap's ends, restores it
    t, q = wave()
    bad = np.zeros(len(t), bool)
    bad[80:90] = True
    spline = glitches._spline_fill(rotations.make_continuous(q), bad)
    assert deg(rotations.normalize(spline[80:90]), q[80:90]).max() > 10.0
    filled = glitches.fill(q, bad)
    assert deg(filled[80:90], q[80:90]).max() < 2.0


def test_smooth_motion_gap_keeps_the_spline():
    # a gap in motion that never repeats (a slow accelerating turn): the spline wins the check
    t = np.arange(0.0, 4.0, 1.0 / 30)
    angle = np.radians(20.0) * t ** 2
    q = np.stack([np.cos(angle / 2), 0 * t, np.sin(angle / 2), 0 * t], axis=-1)[:, None]
    bad = np.zeros(len(t), bool)
    bad[50:56] = True
    assert deg(glitches.fill(q, bad)[50:56], q[50:56]).max() < 0.5


def test_clean_fast_motion_is_not_taken_for_jitter():
    # a clean 2 Hz wave with still moments: its fast parts are motion, not noise
    t, q = wave(seconds=6.0)
    q = q.copy()
    still = (t > 2.0) & (t < 4.0)
    q[still] = q[np.argmax(t > 2.0)]
    out = jitter.smooth_rotations(q, 30.0)
    assert np.sqrt(np.mean(deg(out, q) ** 2)) < 0.5


def test_no_knee_pop_when_feet_are_held_and_put_on_the_floor():
    # the root drifting and lifted: the stance legs would have to stretch straight; the pelvis eases
    # down instead, so no leg bone turns faster than in the capture
    sk, tr = clip()
    position, orientation = tr.root_pose(sk)
    moved = position + [0.0, 0.0, 0.03]
    moved[:, 0] += 0.05 * np.sin(2 * np.pi * 0.3 * tr.times)
    bad = tr.with_root_pose(sk, moved, orientation)
    out, report = clean_up(sk, bad, Options(glitches=False, jitter=False, ground=None))
    legs = [sk.role_index(f"{r}.{s}") for r in ("thigh", "shin", "foot") for s in "LR"]
    step = lambda t: deg(t.rotations[:-1, legs], t.rotations[1:, legs])
    assert step(out).max() <= 1.1 * step(tr).max()
    assert np.abs(np.diff(step(out), axis=0)).max() <= 1.6 * np.abs(np.diff(step(tr), axis=0)).max()
    assert report["repairs"][3]["pelvis_lowered_cm"] <= 100 * feet.MAX_PELVIS_DROP


def test_physical_pass_tracks_the_cleaned_motion_and_reports_balance():
    sk, tr = clip(4)
    cleaned, _ = clean_up(sk, tr, Options())
    out, report = clean_up(sk, tr, Options(physics=True))
    entry = report["repairs"][4]
    assert entry["repair"] == "physics" and entry["enabled"]
    assert entry["balance_error_max_cm"] >= entry["balance_error_median_cm"] >= 0.0
    assert entry["out_of_balance_frames"] <= len(tr.frames) and entry["ground_m"] == pytest.approx(0.0)
    assert {"qa_before", "qa_after", "max_change_deg"} <= set(entry)
    np.testing.assert_array_equal(out.frames, tr.frames)
    # tracking only: the body follows the cleaned motion (no step, no fall, no reaction added)
    path = lambda t: t.root_pose(sk)[0]
    assert np.linalg.norm(path(out) - path(cleaned), axis=1).max() < 0.1
    assert np.sqrt(np.mean(deg(out.rotations, cleaned.rotations) ** 2)) < 5.0
