import numpy as np
import pytest

import sequence_data as data
from humananim.solver.sequence import key_reduction as kr, time_warp as tw


def test_warp_hits_constraints_and_is_monotone():
    warp = tw.TimeWarp([(0, 0), (30, 50), (90, 100), (140, 160)])  # (new, old)
    assert np.allclose(warp([0, 50, 100, 160]), [0, 30, 90, 140])
    t = np.linspace(-20, 200, 2001)
    assert np.all(np.diff(warp(t)) > 0)
    assert np.abs(warp(warp.inverse(t)) - t).max() < 1e-9
    assert np.abs(warp.inverse(warp(t)) - t).max() < 1e-9
    with pytest.raises(ValueError):
        tw.TimeWarp([(0, 0), (50, 40), (40, 60)])


def test_warp_moves_no_frame_further_than_its_constraints():
    """Frame 61 of 1,900 three frames later with both ends pinned: a cubic through the pairs
    themselves (PCHIP on f) bulged along the long interval, shifting frame 1,150 by 20 frames; the
    shifts' own shape-preserving interpolant keeps every shift between its neighbours', and the
    speed f' near one and continuous, also into the slope-one continuation past the ends."""
    warp = tw.TimeWarp([(1, 1), (64, 61), (1900, 1900)])
    t = np.linspace(1, 1900, 20001)
    shift = warp(t) - t
    assert shift.min() >= -1e-9 and shift.max() <= 3.0 + 1e-9
    assert np.abs(shift[t > 1000]).max() < 1.5
    slope = warp.slope(t)
    assert slope.min() > 0.99 and slope.max() < 1.11
    assert warp.slope(np.array([1.0, 1900.0])) == pytest.approx([1.0, 1.0], abs=1e-9)
    # a strong squeeze stays monotone (Fritsch-Carlson's limit on the slopes)
    hard = tw.TimeWarp([(0, 0), (5, 50), (6, 100), (200, 200)])
    u = np.linspace(-10, 210, 5001)
    assert np.all(np.diff(hard(u)) > 0)
    assert np.allclose(hard([0, 50, 100, 200]), [0, 5, 6, 200])


def test_warped_channels_show_the_original_at_the_constraint_times():
    bvh = data.load("cmu_131_01.bvh")
    x = bvh.values[:, 3:40]
    t = np.arange(len(x), dtype=float)
    warp = tw.TimeWarp([(0, 0), (300, 400), (994, 994)])
    y = tw.warp_channels(t, x, warp)
    assert y.shape == x.shape
    assert np.allclose(y[300], x[400]) and np.allclose(y[0], x[0]) and np.allclose(y[-1], x[-1])
    assert np.abs(tw.warp_channels(t, x, tw.TimeWarp([(0, 0), (994, 994)])) - x).max() < 1e-9


def test_warped_keys_keep_order_and_hit_constraints():
    t = np.arange(400, dtype=float)
    y = np.sin(t / 25.0)
    keys = kr.reduce_keys(t, y, 1e-3)
    warp = tw.TimeWarp([(0, 0), (100, 200), (399, 399)])
    moved = tw.warp_keys(keys, warp)
    assert np.all(np.diff(moved.times) > 0)
    assert np.all(moved.left[:, 0] <= moved.times) and np.all(moved.right[:, 0] >= moved.times)
    # the warped curve at new time t' equals the original at f^-1(t')
    tn = np.linspace(0, 399, 300)
    assert np.abs(kr.evaluate(moved, tn) - kr.evaluate(keys, warp.inverse(tn))).max() < 2e-3


def test_quaternion_warp_stays_unit():
    _, traj = data.skeleton_and_motion(frames=slice(0, 200))
    warp = tw.TimeWarp([(0, 0), (50, 100), (199, 199)])
    q = tw.warp_quaternions(traj.frames, traj.rotations, warp)
    assert np.allclose(np.linalg.norm(q, axis=-1), 1.0, atol=1e-12)
    assert np.all((q[1:] * q[:-1]).sum(-1) > 0)
    assert np.allclose(np.abs((q[50] * traj.rotations[100]).sum(-1)), 1.0, atol=1e-9)


def test_squeeze_stretch_keeps_the_ratios_and_the_order():
    keys = np.array([0.0, 10, 20, 25, 30, 40, 55, 60, 70])
    out = tw.squeeze_stretch(keys, current=30, new_time=22, left_limit=10, right_limit=60)
    assert np.all(np.diff(out) > 0)
    assert out[4] == 22 and np.all(out[[0, 1, 7, 8]] == keys[[0, 1, 7, 8]])
    left = (keys >= 10) & (keys <= 30)
    right = (keys >= 30) & (keys <= 60)
    assert np.allclose((30 - keys[left]) / 20, (22 - out[left]) / 12)
    assert np.allclose((keys[right] - 30) / 30, (out[right] - 22) / 38)
    with pytest.raises(ValueError):
        tw.squeeze_stretch(keys, 30, 65, 10, 60)
