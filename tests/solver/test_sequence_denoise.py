"""Denoise's cut-off is a frequency of the clip's own frame rate: on Bandai's 30 fps clips 8 Hz
removes what lies above 8 Hz (the pyramid's finest band there is 7.5-15 Hz, and removing only
bands wholly above the cut-off changed nothing), on the CMU clip at its own rate the same; a
cut-off at or above Nyquist is a message, not silence."""

from pathlib import Path

import numpy as np
import pytest
from scipy import signal

from humananim.solver import bvh
from humananim.solver.errors import HumanAnimError
from humananim.solver.sequence import equalizer

from corpus_clips import path

CMU = Path(__file__).resolve().parents[2] / "humananim_addon" / "data" / "mocap" / "cmu_131_01.bvh"


def channels(file):
    clip = bvh.read(str(file), 0.01)
    rot = [i for i, c in enumerate(c for chans in clip.channels for c in chans) if c.endswith("rotation")]
    return np.unwrap(clip.values[:, rot], period=360.0, axis=0), 1.0 / clip.frame_time


def spectrum(x):
    return np.fft.rfft(signal.detrend(x, axis=0) * np.hanning(len(x))[:, None], axis=0)


def power_above(x, fps, hz):
    """Share and sum of the curves' power above `hz` (detrended, Hann window: no leakage from the
    clip's ends)."""
    spec = np.abs(spectrum(x)) ** 2
    freq = np.fft.rfftfreq(len(x), 1.0 / fps)
    return spec[freq > hz].sum() / max(spec.sum(), 1e-12), spec[freq > hz].sum()


@pytest.mark.parametrize("clip", ("walk_normal_001", "dash_normal_001", "bow_happy_001", "cmu"))
def test_8_hz_removes_what_lies_well_above_8_hz(clip):
    x, fps = channels(CMU if clip == "cmu" else path(clip))
    assert fps == pytest.approx(120.0 if clip == "cmu" else 30.0, rel=1e-3)
    y = equalizer.denoise(x, fps, cutoff_hz=8.0)
    before, after = power_above(x, fps, 12.0)[1], power_above(y, fps, 12.0)[1]
    assert after < 0.05 * before  # measured 0.2 % at most (the pyramid bands: 100 % on 30 fps clips)
    slow = np.fft.rfftfreq(len(x), 1.0 / fps) < 3.0
    sx, sy = (np.abs(spectrum(v))[slow] for v in (x, y))
    assert np.abs(sy - sx).sum() < 0.02 * sx.sum()  # the motion itself is kept
    assert np.abs(y - x).max() > 0.1  # degrees: something changed


@pytest.mark.parametrize("cutoff", (15.0, 20.0, 60.0))
def test_a_cutoff_at_or_above_nyquist_is_a_message(cutoff):
    x, fps = channels(path("walk_normal_001"))
    with pytest.raises(HumanAnimError, match="Nyquist"):
        equalizer.denoise(x, fps, cutoff_hz=cutoff)


@pytest.mark.parametrize("cutoff", (0.0, -1.0, float("nan")))
def test_a_cutoff_that_is_no_frequency_is_a_message(cutoff):
    with pytest.raises(HumanAnimError, match="positive"):
        equalizer.denoise(np.zeros((10, 2)), 30.0, cutoff_hz=cutoff)
