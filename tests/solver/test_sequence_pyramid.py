import numpy as np
import pytest

from humananim.solver.sequence import equalizer, pyramid, pyramid_compression

import sequence_data as data

RNG = np.random.default_rng(3)


def cmu_channels(name="cmu_131_01.bvh"):
    """Raw CMU channels (F, C): unrolled Euler angles (degrees) and the root position (metres)."""
    bvh = data.load(name)
    euler, orders = data.euler(bvh)
    from humananim.solver.sequence import channels
    euler = np.degrees(channels.unroll_euler(euler, orders))
    return np.concatenate((data.root_position(bvh), euler.reshape(len(euler), -1)), axis=1)


def test_kernel_is_normalised_and_equal_contribution():
    for a in (0.3, 0.4, 0.5, 0.6):
        w = pyramid.kernel(a)
        assert w.sum() == pytest.approx(1.0)
        assert w[2] + 2 * w[0] == pytest.approx(2 * w[1])


def test_reduce_expand_sizes_and_end_samples_copied():
    x = RNG.normal(size=(17, 3))
    g1 = pyramid.reduce(x)
    assert g1.shape == (9, 3)
    assert np.allclose(g1[[0, -1]], x[[0, -1]])  # "the two first and final samples are copied"
    e = pyramid.expand(g1)
    assert e.shape == (17, 3)
    assert np.allclose(e[[0, -1]], g1[[0, -1]])
    with pytest.raises(ValueError):
        pyramid.reduce(x[:16])


def test_ramps_have_no_band_energy_even_at_the_ends():
    t = np.linspace(0.0, 1.0, 100)
    x = np.stack((3 * t + 1, -2 * t), axis=1)
    p = pyramid.laplacian_pyramid(x)
    assert max(np.abs(b).max() for b in p.bands) < 1e-12


@pytest.mark.parametrize("n", [2, 3, 4, 5, 9, 17, 18, 100, 995])
@pytest.mark.parametrize("levels", [None, 1, 3])
def test_reconstruction_is_exact_for_any_length(n, levels):
    x = RNG.normal(size=(n, 4)) * 50.0
    p = pyramid.laplacian_pyramid(x, levels)
    assert len(p.bands[0]) == pyramid.dyadic_length(n, p.levels) and len(p.bands[0]) >= n
    assert np.abs(pyramid.reconstruct(p) - x).max() < 1e-9


@pytest.mark.parametrize("clip", data.CLIPS)
def test_reconstruction_of_cmu_clips_is_exact(clip):
    x = cmu_channels(clip)
    for levels in (None, 4):
        p = pyramid.laplacian_pyramid(x, levels)
        assert np.abs(pyramid.reconstruct(p) - x).max() < 1e-9
        assert np.abs(equalizer.equalize(x, [1.0] * (p.levels + 1)) - x).max() < 1e-9


def test_gaussian_levels_follow_eq_5_6():
    x = RNG.normal(size=(33, 2))
    g = pyramid.gaussian_pyramid(x, 5)
    p = pyramid.laplacian_pyramid(x, 5)
    assert np.allclose(g[-1], p.top)
    assert [len(v) for v in g] == [33, 17, 9, 5, 3, 2]


def test_equalizer_damps_jitter_and_boosts_mid_bands():
    fps = 120.0
    t = np.arange(600) / fps
    smooth = 20.0 * np.sin(2 * np.pi * 0.8 * t)
    noisy = smooth + RNG.normal(scale=0.5, size=t.shape)
    clean = equalizer.denoise(noisy[:, None], fps, cutoff_hz=10.0)[:, 0]
    assert np.abs(clean - smooth).std() < 0.4 * np.abs(noisy - smooth).std()
    levels = pyramid.max_levels(len(t))
    gains = [1.0] * (levels + 1)
    band = next(l for l, (lo, hi) in enumerate(pyramid.band_limits_hz(fps, levels)) if lo <= 0.8 < hi)
    gains[band] = gains[band - 1] = 2.0
    boosted = equalizer.equalize(smooth[:, None], gains)[:, 0]
    assert np.ptp(boosted) > 1.3 * np.ptp(smooth)


def test_per_channel_gains_and_dict_gains():
    x = cmu_channels()[:300]
    levels = 5
    zero = [np.ones(x.shape[1]) for _ in range(levels + 1)]
    zero[0] = np.zeros(x.shape[1])
    zero[0][0] = 1.0  # keep channel 0 untouched
    out = equalizer.equalize(x, zero, levels)
    assert np.abs(out[:, 0] - x[:, 0]).max() < 1e-9
    assert np.abs(out[:, 1:] - x[:, 1:]).max() > 1e-3
    assert np.allclose(equalizer.equalize(x, {0: 0.0}, levels), equalizer.equalize(x, [0.0] + [1.0] * levels, levels))


def test_low_pass_has_no_edge_artefacts():
    t = np.linspace(0.0, 1.0, 203)
    x = (np.sin(2.0 + 3.0 * t) + t ** 2)[:, None]  # smooth, non-periodic, non-zero at the ends
    y = pyramid_compression.compress(x, 4)
    err = np.abs(y - x)[:, 0]
    interior = err[30:-30].max()
    assert err.max() < 3.0 * interior + 1e-6


def test_pyramid_compression_keys_meet_the_tolerance_on_every_frame():
    from humananim.solver.sequence import key_reduction
    x = cmu_channels()
    times = np.arange(len(x), dtype=float)
    tol = np.full(x.shape[1], 1.0)  # degrees
    tol[:3] = 0.01  # metres
    keys, drop = pyramid_compression.pyramid_keys(times, x, tol, max_drop=6)
    got = key_reduction.evaluate_channels(keys, times)
    assert np.all(np.abs(got - x).max(axis=0) <= tol + 1e-12)
    assert drop.max() >= 2  # smooth channels keep one key in 4 frames or fewer
    assert sum(len(k) for k in keys) < 0.7 * x.size
