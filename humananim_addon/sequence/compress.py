"""Key compression to a tolerance (Huang 1996 §5.4)."""

import time

import numpy as np

from ...solver.progress import run_to_end
from ...solver.sequence import key_reduction, pyramid_compression
from .channels import Group, action_frames, sample_group, unrolled
from ...solver.qa.thresholds import SLIDE_MARGIN_MM
from .measures import (_base_summary, _ms, _tail_measure, foot_chains, group_errors, planted_feet_measure,
                       source_motion, tail_errors)
from .writing import Output, set_keys


def component_tolerances(group, degrees, centimetres, value_tolerance):
    """Per-component tolerances so the whole property stays within the animator's figure: an
    Euler triple within d degrees when each angle is within d/3; a quaternion within d degrees
    when each component is within rad(d)/4 (|dq| <= 2 e, angle <= 2 |dq|); an axis-angle with
    its angle within d/2 and its axis within rad(d)/4; a location within c cm when each
    component is within c/sqrt(3)."""
    rad = np.radians(degrees)
    n = len(group.fcurves)
    if group.kind == "euler":
        return np.full(n, rad / 3.0)
    if group.kind == "quaternion":
        return np.full(n, rad / 4.0)
    if group.kind == "axis_angle":
        return np.array([rad / 2.0, rad / 4.0, rad / 4.0, rad / 4.0])
    if group.kind == "location":
        return np.full(n, 0.01 * centimetres / group.scale / (np.sqrt(3.0) if n > 1 else 1.0))
    return np.full(n, float(value_tolerance))


# a planted foot point may move this far from the source (mm): each contact's slide then stays
# within the source's own plus twice this, the motion QA's margin (SLIDE_MARGIN_MM)
FEET_MM = 0.5 * SLIDE_MARGIN_MM


def iter_compress(obj, scene, source, sel, degrees=0.5, centimetres=0.5, value_tolerance=1e-3,
                  method="HERMITE", replace=False, tail_cm=0.0, feet_mm=FEET_MM):
    """Fewer keys within the tolerances on every frame (Hermite key reduction, or pyramid levels),
    as steps yielding progress; returns the summary with keys before/after and the largest errors.
    `tail_cm` > 0 also bounds the largest error at any bone's tail and 10 cm beyond it: the
    channel tolerances are scaled down until it holds. `feet_mm` > 0 keeps the feet the body
    roles name within that many mm over the ground of the source wherever the source plants them:
    the channel errors of the root, hips and legs add up at the foot, so those channels' tolerances
    (only those) are scaled down until it holds."""
    t0 = time.perf_counter()
    frames = action_frames(source)
    keys_before = sum(len(fc.keyframe_points) for fc in sel.fcurves)
    samples = unrolled(sel.groups, [sample_group(g, frames) for g in sel.groups])
    tols = [component_tolerances(g, degrees, centimetres, value_tolerance) for g in sel.groups]

    def reduce_group(g, x, tol):
        if method == "PYRAMID":
            return pyramid_compression.pyramid_keys(frames, x, tol)[0]
        return key_reduction.reduce_channels(frames, x, tol)

    def reduce(scale):
        return [reduce_group(g, x, tol * scale) for g, x, tol in zip(sel.groups, samples, tols)]

    results = reduce(1.0)
    yield 0.5
    # the source's motion, read before anything is written (replace rewrites the source)
    motion = source_motion(obj, scene, source, frames)
    feet_scale, feet_error = 1.0, None
    if feet_mm > 0.0 and motion is not None:
        results, feet_scale, feet_error = _keep_planted_feet(motion, sel.groups, frames, samples, tols, results,
                                                             reduce_group, feet_mm)
    if tail_cm > 0.0 and motion is not None:
        measure = _tail_measure(motion, sel.groups, frames)
        kept = results  # the scales below multiply the feet's
        results, _, _ = key_reduction.fit_to_error(
            lambda scale: kept if scale == 1.0 else _rescaled(kept, sel.groups, samples, tols, reduce_group,
                                                              scale, lambda g: scale * _leg_scale(g, motion, feet_scale)),
            measure, tail_cm)
    yield 0.9
    out = Output(obj, source, f"{source.name}.compressed", replace)
    for g, keys in zip(sel.groups, results):
        for i, k in enumerate(keys):
            set_keys(out.fcurve(g.data_path, i, g.group_name), k)
    out.copy_unprocessed(sel.others)
    action = out.finish()
    yield 0.95
    keys_after = sum(len(k) for keys in results for k in keys)
    new_groups = [Group(g.data_path, g.kind, [out.fcurve(g.data_path, i, g.group_name) for i in g.indices],
                        g.defaults, g.bone, g.order, g.scale, g.group_name) for g in sel.groups]
    played = [sample_group(g, frames) for g in new_groups]
    errors = group_errors(sel.groups, samples, played)
    summary = _base_summary(obj, source, sel, out)
    summary.update(command="compress", method=method.lower(), frames=len(frames),
                   tolerance_deg=degrees, tolerance_cm=centimetres, tolerance_tail_cm=tail_cm, keys_before=keys_before, keys_after=keys_after,
                   ratio=round(keys_before / max(keys_after, 1), 2),
                   max_error_deg=round(errors["deg"][0], 4), max_error_deg_at=errors["deg"][1],
                   max_error_cm=round(errors["cm"][0], 4), max_error_cm_at=errors["cm"][1],
                   max_error_value=round(errors["value"][0], 6))
    if feet_error is not None:
        summary.update(tolerance_feet_mm=feet_mm, feet_error_mm=round(feet_error, 3),
                       feet_tolerance_scale=round(feet_scale, 4))
    tail = tail_errors(obj, scene, motion, action, frames)
    if tail is not None:
        summary.update(tail_error_cm=round(tail.tail_cm, 4), tail_error_bone=tail.tail_bone,
                       tail_10cm_error_cm=round(tail.point_cm, 4), tail_10cm_error_bone=tail.point_bone)
    summary["ms"] = _ms(t0)
    return summary


def _leg_scale(group, motion, feet_scale):
    """The tolerance scale of a group: `feet_scale` on the foot chains' bones, 1 elsewhere."""
    skeleton, _ = motion
    _, chain = foot_chains(skeleton)
    j = skeleton.find(group.bone) if group.bone else None
    return feet_scale if j is not None and j in chain else 1.0


def _rescaled(results, groups, samples, tols, reduce_group, scale, scale_of):
    """`results` with every group whose tolerance scale (scale_of(group)) is not 1 reduced again."""
    return [keys if scale_of(g) == 1.0 else reduce_group(g, x, tol * scale_of(g))
            for g, x, tol, keys in zip(groups, samples, tols, results)]


# how the legs' tolerance scale is searched for the planted feet: on the measured errors (a
# reduction or two); benchmarks/compression.py times it beside key_reduction.fit_to_error's halving
FEET_SEARCH = key_reduction.scale_to_error


def _keep_planted_feet(motion, groups, frames, samples, tols, results, reduce_group, feet_mm):
    """(keys, scale of the foot chains' tolerances, planted-foot error mm) with the feet within
    `feet_mm` of the source where it plants them (the legs' scale searched on the errors, to 1/32)."""
    measure = planted_feet_measure(motion, groups, frames)
    if measure is None:
        return results, 1.0, None
    keys, scale, error = FEET_SEARCH(
        lambda s: results if s == 1.0 else _rescaled(results, groups, samples, tols, reduce_group, s,
                                                      lambda g: _leg_scale(g, motion, s)),
        measure, feet_mm, 5)
    return keys, scale, error


def compress(*args, **kw):
    return run_to_end(iter_compress(*args, **kw))
