"""Time warping by markers, and squeeze/stretch of one key (Huang 1996 §5.5)."""

import re
import time

import numpy as np

from ...solver.errors import MotionError
from ...solver.sequence import key_reduction, time_warp
from .channels import action_frames, from_working, sample_group, to_working
from .measures import _base_summary, _ms
from .writing import Output, read_keys, set_keys, write_groups

WARP_MARKER = re.compile(r"^\s*warp\s*[:=]\s*(-?\d+(?:\.\d+)?)\s*$", re.IGNORECASE)


def marker_constraints(scene, action):
    """(new frame, old frame) from markers named 'warp:<old frame>' placed at the new frame:
    the action's pose markers and the scene's timeline markers."""
    found = {}
    for marker in list(action.pose_markers) + list(scene.timeline_markers):
        m = WARP_MARKER.match(marker.name)
        if m:
            found[float(m.group(1))] = float(marker.frame)
    return [(new, old) for old, new in sorted(found.items())]


def parse_map(text):
    """'OLD:NEW, OLD:NEW' -> [(new, old), ...]."""
    pairs = []
    for part in re.split(r"[,\s;]+", text.strip()):
        if not part:
            continue
        try:
            old, new = (float(v) for v in part.split(":"))
        except ValueError:
            raise MotionError(f"warp map {part!r}: expected OLD:NEW frame pairs") from None
        pairs.append((new, old))
    return pairs


def make_warp(constraints, frames, keep_ends=True):
    c = list(constraints)
    if keep_ends:
        olds = [old for _, old in c]
        if not olds or frames[0] < min(olds):
            c.append((frames[0], frames[0]))
        if not olds or frames[-1] > max(olds):
            c.append((frames[-1], frames[-1]))
    if len(c) < 2:
        raise MotionError("a time warp needs two constraints: add 'warp:<old frame>' markers at the new frames")
    try:
        return time_warp.TimeWarp(c)
    except ValueError as error:
        raise MotionError(f"time warp: {error}") from None


def warp(obj, scene, source, sel, constraints, keep_ends=True, resample=False, replace=False):
    """What happened at each constraint's old frame now happens at its new frame (monotone cubic
    warp, slope one outside). resample=False moves the keys (handles scaled by the warp's
    slope); True keys the warped curves on every new frame."""
    t0 = time.perf_counter()
    frames = action_frames(source)
    tw = make_warp(constraints, frames, keep_ends)
    out = Output(obj, source, f"{source.name}.warped", replace)
    if resample:
        new_frames = np.arange(np.ceil(tw(frames[0]) - 1e-9), np.floor(tw(frames[-1]) + 1e-9) + 1.0)
        samples = [sample_group(g, frames) for g in sel.groups]
        work, layout = to_working(sel.groups, samples)
        values = from_working(sel.groups, time_warp.warp_channels(frames, work, tw, new_frames), layout)
        write_groups(out, sel.groups, new_frames, values)
        keys_written = len(new_frames) * len(sel.fcurves)
    else:
        keys_written = 0
        for g in sel.groups:
            for i, fc in enumerate(g.fcurves):
                if fc is None:
                    continue
                k = time_warp.warp_keys(read_keys(fc), tw)
                set_keys(out.fcurve(g.data_path, i, g.group_name), k)
                keys_written += len(k)
    out.copy_unprocessed(sel.others)

    def marker_frame(marker):
        return None if WARP_MARKER.match(marker.name) else float(tw(marker.frame))
    out.finish(marker_frame)
    summary = _base_summary(obj, source, sel, out)
    summary.update(command="warp", constraints=[[float(old), float(new)] for new, old in zip(tw.new, tw.old)],
                   frames=[float(tw(frames[0])), float(tw(frames[-1]))], resampled=bool(resample),
                   keys=keys_written, ms=_ms(t0))
    return summary


def squeeze_stretch(obj, scene, source, sel, current, new_frame, left_limit, right_limit, replace=False):
    """Move the keys at `current` to `new_frame`; keys between the limits keep their ratio of
    distances (Huang's squeeze and stretch), handles scaled with them; keys outside stay."""
    t0 = time.perf_counter()
    tl, t, tr = float(left_limit), float(current), float(right_limit)
    if not (tl < t < tr and tl < new_frame < tr):
        raise MotionError(f"need left limit < frame, new frame < right limit (got {tl:g}, {t:g}, "
                          f"{new_frame:g}, {tr:g})")
    out = Output(obj, source, f"{source.name}.squeezed", replace)
    moved = 0
    for g in sel.groups:
        for i, fc in enumerate(g.fcurves):
            if fc is None:
                continue
            k = read_keys(fc)
            nt = time_warp.squeeze_stretch(k.times, t, new_frame, tl, tr)
            # a key's handles scale with its side's ratio (the key at T: each handle its side's)
            ratio_l = np.where((k.times > tl) & (k.times <= tr),
                               np.where(k.times <= t, (new_frame - tl) / (t - tl), (tr - new_frame) / (tr - t)), 1.0)
            ratio_r = np.where((k.times >= tl) & (k.times < tr),
                               np.where(k.times < t, (new_frame - tl) / (t - tl), (tr - new_frame) / (tr - t)), 1.0)
            left = np.column_stack((nt + (k.left[:, 0] - k.times) * ratio_l, k.left[:, 1]))
            right = np.column_stack((nt + (k.right[:, 0] - k.times) * ratio_r, k.right[:, 1]))
            moved += int(np.count_nonzero(np.abs(nt - k.times) > 1e-9))
            set_keys(out.fcurve(g.data_path, i, g.group_name),
                     key_reduction.Keys(nt, k.values, left, right, k.interpolation))
    out.copy_unprocessed(sel.others)
    out.finish()
    summary = _base_summary(obj, source, sel, out)
    summary.update(command="squeeze", frame=t, new_frame=float(new_frame), limits=[tl, tr], keys_moved=moved,
                   ms=_ms(t0))
    return summary
