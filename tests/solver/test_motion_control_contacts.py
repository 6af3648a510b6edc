"""Foot support intervals (motion_control.contacts) on the real-rig fixtures.

CMU 131_01 is not a plain walk: the subject stands on both feet, shuffles the left foot in (0.07-
0.25 s), stands (0.25-0.85 s), steps back with the left foot (0.85-1.03 s), stands, then kicks the
right leg high (from 1.1 s) while spinning on the left heel. Measured intervals (frames at 120 fps):
left on 0-7, 30-101, 123-199; right on 0-131; double support 44.5 % of the clip, no flight."""

import numpy as np
import pytest

from humananim.solver.motion_control import Contact, remove_short_runs, runs, support_intervals, support_phases
from humananim.solver.trajectories import Trajectories

from test_dynamics_closed_loop_rigs import load


@pytest.fixture(scope="module")
def cmu():
    return load("cmu_131_01")


def seconds(mask, fps):
    return [(b - a) / fps for on, a, b in runs(mask) if on]


def test_cmu_support_phases(cmu):
    sk, tr = cmu
    sup = support_intervals(sk, tr)
    phases = support_phases(sup)
    assert phases[0] == 2  # standing on both feet at the start
    assert (phases > 0).all()  # no flight: the heel spin during the kick still supports
    assert 0.35 < np.mean(phases == 2) < 0.55  # measured 0.445
    # the left foot's two steps: single support on the right for 0.15-0.25 s each
    single_r = [(b - a) / tr.fps for v, a, b in runs(sup["R"] & ~sup["L"]) if v]
    assert len(single_r) == 2 and all(0.12 < d < 0.3 for d in single_r)
    # the kick: the right foot leaves at ~1.1 s and stays up to the end
    assert not sup["R"][int(1.15 * tr.fps):].any() and sup["R"][:int(1.05 * tr.fps)].all()
    assert 0.7 < sup["L"].mean() < 0.85 and 0.6 < sup["R"].mean() < 0.72  # measured 0.79, 0.66


def test_hysteresis_suppresses_flicker(cmu):
    """Random jitter of the whole body (1 cm up and down, 3 mm sideways): the raw thresholds flicker, the
    default settings give no interval (on or off) shorter than the minimum inside the clip."""
    sk, tr = cmu
    trans = tr.translations.copy()
    rng = np.random.default_rng(1)
    trans[:, sk.root] += rng.uniform(-0.01, 0.01, (tr.frame_count, 3)) * [0.0, 0.0, 1.0]
    trans[:, sk.root, 0] += rng.uniform(-0.003, 0.003, tr.frame_count)  # ~0.3 m/s of jitter
    noisy = Trajectories(tr.frames, tr.fps, tr.rotations, trans, tr.armature_to_world)
    raw = support_intervals(sk, noisy, v_off=0.4, h_off=0.05, min_duration=0.0)
    assert any(len(runs(v)) > 8 for v in raw.values())  # flicker without hysteresis and minimum
    sup = support_intervals(sk, noisy)
    min_frames = int(round(0.08 * tr.fps))
    for v in sup.values():
        assert all(b - a >= min_frames for _, a, b in runs(v)[1:-1])


def test_remove_short_runs_and_overrides(cmu):
    m = np.array([1, 1, 0, 1, 1, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1], bool)
    out = remove_short_runs(m, 2)
    assert [r for r in runs(out)] == [(True, 0, 6), (False, 6, 15), (True, 15, 16)]
    sk, tr = cmu
    f0 = tr.frames[0]
    sup = support_intervals(sk, tr, overrides=[Contact("R", f0 + 150, f0 + 160, True), ("L", f0, f0 + 9, False)])
    assert sup["R"][150:161].all() and not sup["R"][161:].any()
    assert not sup["L"][:10].any()
    with pytest.raises(ValueError):
        support_intervals(sk, tr, overrides=[Contact("X", 0, 1)])
