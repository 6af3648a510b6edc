"""Keyframe sequence manipulation (Huang 1996 chapter 5): frequency bands, multiresolution
blending, key compression, time warping, on any animated channel. numpy and scipy only."""

from . import (channels, equalizer, error_measures, key_reduction, multiresolution_blend, pyramid,
               pyramid_compression, time_warp)

__all__ = ["channels", "equalizer", "error_measures", "key_reduction", "multiresolution_blend",
           "pyramid", "pyramid_compression", "time_warp"]
