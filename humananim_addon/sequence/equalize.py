"""The multiresolution equalizer (Huang 1996 §5.2) on an action's channels."""

import time

import numpy as np

from ...solver.errors import MotionError
from ...solver.sequence import equalizer, pyramid
from ..actions import scene_fps
from .channels import action_frames, from_working, sample_group, to_working, working_kinds
from .measures import _base_summary, _ms, group_errors
from .writing import Output, write_groups


MAX_LEVELS = 8


def default_levels(frame_count, levels=None):
    full = pyramid.max_levels(frame_count)
    return int(min(full, MAX_LEVELS if levels is None or levels <= 0 else levels))


def band_labels(fps, levels):
    limits = pyramid.band_limits_hz(fps, levels)
    return [f"{lo:.3g}-{hi:.3g} Hz" for lo, hi in limits[:-1]] + [f"< {limits[-1][1]:.3g} Hz (mean)"]


def equalize(obj, scene, source, sel, gains=None, levels=None, cutoff_hz=None, replace=False):
    """Band gains (finest band first, the top last) on the selected channels, or with cutoff_hz
    a low-pass at that frequency of the clip's frame rate (equalizer.denoise); all gains 1 gives
    the source back."""
    t0 = time.perf_counter()
    frames = action_frames(source)
    if len(frames) < 3:
        raise MotionError(f"'{source.name}' is too short to filter ({len(frames)} frames)")
    fps = scene_fps(scene)
    levels = default_levels(len(frames), levels)
    if cutoff_hz is not None:
        equalizer.check_cutoff(fps, cutoff_hz)  # before anything is written
        gains = None
    else:
        gains = list(gains if gains is not None else [1.0] * (levels + 1))[:levels + 1]
        gains += [1.0] * (levels + 1 - len(gains))
    samples = [sample_group(g, frames) for g in sel.groups]
    work, layout = to_working(sel.groups, samples)
    result = equalizer.denoise(work, fps, cutoff_hz) if gains is None else equalizer.equalize(work, gains, levels)
    values = from_working(sel.groups, result, layout)
    out = Output(obj, source, f"{source.name}.eq", replace)
    write_groups(out, sel.groups, frames, values)
    out.copy_unprocessed(sel.others)
    out.finish()
    changes = group_errors(sel.groups, samples, values)
    summary = _base_summary(obj, source, sel, out)
    summary.update(command="filter", frames=len(frames), levels=levels,
                   gains=None if gains is None else [float(g) for g in gains],
                   bands=band_labels(fps, levels), cutoff_hz=cutoff_hz, fps=fps,
                   largest_change_deg=round(changes["deg"][0], 4), largest_change_cm=round(changes["cm"][0], 4),
                   ms=_ms(t0))
    return summary


def band_energies(obj, scene, action, group, levels=None):
    """RMS of each band of one group's curve over the clip (degrees for rotations as tangent
    vectors, cm for locations, units otherwise), finest first, the top (mean pose) last."""
    frames = action_frames(action)
    levels = default_levels(len(frames), levels)
    work, layout = to_working([group], [sample_group(group, frames)])
    pyr = pyramid.laplacian_pyramid(work, levels)
    kind = working_kinds([group], layout)[0]
    unit = {"rotation": np.degrees(1.0), "location": 100.0 * group.scale}.get(kind, 1.0)
    energies = [float(np.sqrt((b ** 2).sum(axis=1).mean())) * unit for b in pyr.bands]
    energies.append(float(np.sqrt((pyr.top ** 2).sum(axis=1).mean())) * unit)
    units = {"rotation": "deg", "location": "cm"}.get(kind, "")
    return band_labels(scene_fps(scene), levels), energies, units
