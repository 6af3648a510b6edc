"""Boulic's normalised model (eq. 2-5, 2-6), personification presets, speeds along the path, keyed
root positions, running."""

import numpy as np
import pytest

from humananim.solver.errors import HumanAnimError
from humananim.solver.walking import PRESETS, Path, Style, from_keys, metrics, model, preset, speed_profile, walk

from walking_cases import FPS, rig, walked


def test_equations_2_5_and_2_6():
    rv = 1.5
    assert model.relative_cycle_length(rv) == pytest.approx(1.346 * np.sqrt(1.5))
    dc = model.cycle_duration(rv)
    assert dc == pytest.approx(1.346 / np.sqrt(1.5))
    ds, db, dds = model.walk_durations(dc)
    assert (ds, db, dds) == pytest.approx((0.752 * dc - 0.143, 0.248 * dc + 0.143, 0.252 * dc - 0.143))
    assert ds + db == pytest.approx(dc)
    assert 2 * ds - dc == pytest.approx(2 * dds)  # the two feet's supports overlap twice a cycle
    assert model.durations(rv, 0.9) == pytest.approx((dc, ds, db, dds))


def test_personification_defaults_and_presets():
    assert Style() == PRESETS["neutral"]
    assert Style().to_dict() == {"stride": 1.0, "pelvis_rotation": 1.0, "pelvis_tilt": 1.0, "arm_swing": 1.0,
                                 "knee_flexion": 1.0, "heel_strike": 1.0, "torso_lean": 0.0, "run_froude": 0.6}
    assert set(PRESETS) == {"neutral", "brisk", "tired", "sneaking"}
    assert preset("tired", arm_swing=0.1).arm_swing == 0.1
    with pytest.raises(HumanAnimError):
        preset("moonwalk")
    n, s = model.oscillations(1.2, 0.9), model.oscillations(1.2, 0.9, PRESETS["sneaking"])
    assert s.knee > n.knee and s.arm < n.arm and s.heel < n.heel


def _walk_style(name):
    return walk(rig("cmu"), Path.from_points([[0, 0, 0], [5, 0, 0]]), speed=1.0, style=PRESETS[name], fps=FPS)


def test_styles_change_the_walk():
    neutral, sneaking, brisk = (_walk_style(n) for n in ("neutral", "sneaking", "brisk"))
    hip = {k: metrics.hip_centre(r)[:, 2] for k, r in (("n", neutral), ("s", sneaking))}
    assert np.median(hip["s"]) < np.median(hip["n"]) - 0.03  # bent knees: lower pelvis
    assert metrics.knee_flexion(sneaking)["L"].mean() > metrics.knee_flexion(neutral)["L"].mean() + np.radians(5)
    # a longer stride at the same speed: fewer, longer cycles
    assert np.mean([c["length_m"] for c in metrics.cycles(brisk)]) > \
        1.05 * np.mean([c["length_m"] for c in metrics.cycles(neutral)])
    # torso lean: the head goes forward of the hips
    for r in (neutral, sneaking):
        assert metrics.foot_slip(r) < 0.002 and r.reached.all()
    sk = neutral.body.skeleton
    chest = sk.role_index("head")
    lean = {}
    for k, r in (("n", neutral), ("s", sneaking)):
        w = metrics.world(r)
        mid = len(w) // 2
        lean[k] = w[mid, chest, 0, 3] - metrics.hip_centre(r, w)[mid, 0]
    assert lean["s"] > lean["n"] + 0.05


def test_speed_profile_starts_and_stops_at_rest_within_acceleration():
    path = Path.from_points([[0, 0, 0], [3, 0, 0], [6, 0, 0]], corners=[0.0, 3.0, 6.0])
    s, v = speed_profile(path, segments=[1.0, 1.6])
    assert v[0] == 0 and v[-1] == 0
    assert np.abs(np.diff(v ** 2) / np.diff(s)).max() <= 2 * 0.8 + 1e-9
    assert v[(s > 1.0) & (s < 2.9)].max() == pytest.approx(1.0)
    assert v[(s > 3.5) & (s < 4.0)].max() == pytest.approx(1.6)
    with pytest.raises(HumanAnimError):
        speed_profile(path, segments=[1.0])
    with pytest.raises(HumanAnimError):
        speed_profile(path, speed=-1.0)


def test_per_segment_speeds_set_the_cadence():
    path = Path.from_points([[0, 0, 0], [6, 0, 0], [12, 0, 0]], corners=[0.0, 6.0, 12.0])
    r = walk(rig("metarig"), path, segment_speeds=[0.8, 1.6], fps=FPS)
    cyc = metrics.cycles(r)
    slow = [c for c in cyc if c["start"] < 3.5]
    fast = [c for c in cyc if 7.5 < r.progress(c["start"]) < 10.0]
    assert slow and fast
    assert np.mean([c["duration_s"] for c in fast]) < np.mean([c["duration_s"] for c in slow]) - 0.15
    for c in cyc:
        assert c["rlc"] == pytest.approx(c["rlc_model"], rel=0.05)


def test_keyed_root_positions_drive_the_walk():
    # Huang's Global_motion: keyed positions, eased in and out as Blender's default keys are;
    # the hip centre follows them at their times
    t = np.linspace(0.0, 6.0, 145)
    u = t / 6.0
    u = u * u * (3 - 2 * u)
    keyed = np.column_stack((6.0 * u, 1.0 * np.sin(np.pi * u), np.zeros_like(u)))
    path, progress = from_keys(t, keyed)
    r = walk(rig("cmu"), path, progress=progress, fps=FPS)
    hip = metrics.hip_centre(r)
    on = (r.times >= 0) & (r.times <= 6.0)
    want = np.column_stack([np.interp(r.times[on], t, keyed[:, k]) for k in range(2)])
    assert np.linalg.norm(hip[on, :2] - want, axis=1).max() < 0.03
    assert metrics.foot_slip(r) < 0.002 and metrics.root_deviation(r) < 0.032 * r.body.ht + 0.01 and r.reached.all()


def test_running_has_a_flight_phase_and_no_double_support():
    path = Path.from_points([[0, 0, 0], [25, 0, 0]])
    sk = rig("cmu")
    r = walk(sk, path, speed=3.5, fps=FPS)
    steady = [fp for prints in r.plan.footprints.values() for fp in prints if fp.running and not fp.final]
    assert len(steady) >= 6
    assert metrics.flight_frames(r) > 5
    for s in metrics.support_durations(r):
        if s["running"]:
            assert s["measured_s"] < s["cycle_s"] / 2  # each foot on the ground under half the cycle
    mid = (r.times > 5.0) & (r.times < 6.5)
    assert r.running[mid].all()
    assert not (r.support["L"] & r.support["R"])[mid].any()
    assert metrics.foot_slip(r) < 0.002 and r.reached.all()
    walking = walked("cmu", "straight")
    assert metrics.flight_frames(walking) == 0 and not walking.running.any()


def test_speeds_beyond_the_model_are_refused():
    with pytest.raises(HumanAnimError, match="beyond the gait model"):
        walk(rig("cmu"), Path.from_points([[0, 0, 0], [30, 0, 0]]), speed=6.0, fps=FPS)


def test_the_armature_object_may_stand_anywhere():
    # the walk is in the world: a turned, moved armature object walks the same path
    from humananim.solver import rotations
    from walking_cases import s_curve
    a2w = np.eye(4)
    a2w[:3, :3] = rotations.to_matrix(rotations.from_axis_angle([1.1, 0.0, 0.0, 1.0]))
    a2w[:3, 3] = [2.0, -1.0, 0.5]
    r = walk(rig("metarig"), Path.from_points(s_curve(6.0)), speed=1.2, fps=FPS, armature_to_world=a2w)
    assert metrics.foot_slip(r) < 0.002 and metrics.root_deviation(r) < 0.032 * r.body.ht + 0.01 and r.reached.all()
    assert abs(metrics.sole_points(r)["L"]["heel"][0, 2]) < 1e-6  # standing on z = 0, not on the object
