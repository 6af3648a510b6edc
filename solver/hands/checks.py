"""Measures of a grasp, as the issue's proof states them: every finger the type uses touches the
surface (within 2 mm), no sensor penetrates the object by more than 1 mm on any frame, and the
arm does not pass through the body while reaching."""

import numpy as np

from .body import body_sensors, body_volumes, collisions
from .grasp import TYPE_FINGERS
from .sensors import sensor_centres


def grasp_measures(skeleton, result, shape, armature_to_world):
    out = {"type": result.gtype, "hands": len(result.hands), "primitive": result.primitive}
    worst, gaps = -np.inf, {}
    for h in result.hands:
        radii = np.array([s.radius for s in h.sensors])
        for t in range(result.frame_count):
            w = skeleton.world_frames(result.basis[t], armature_to_world)
            worst = max(worst, float(np.max(radii - shape.distance(sensor_centres(h.sensors, w, skeleton)))))
        gap = shape.distance(sensor_centres(h.sensors, result.world, skeleton)) - radii
        for f in TYPE_FINGERS[result.gtype]:
            sel = [k for k, s in enumerate(h.sensors) if s.finger == f]
            if sel:
                gaps[f"{h.side}.{f}"] = float(gap[sel].min())
    out["max_penetration_m"] = max(worst, 0.0)
    out["finger_gaps_m"] = gaps
    out["max_finger_gap_m"] = max(gaps.values()) if gaps else np.inf
    # the reach does not pass through the body (the arms' sensors against the trunk and head)
    rest_world = skeleton.world_frames(result.basis[0], armature_to_world)
    vols = [v for v in body_volumes(skeleton, rest_world) if v.name in ("trunk", "head")]
    sens = [s for s in body_sensors(skeleton, rest_world) if s.limb == "arm"
            and any(s.chain_side == h.side for h in result.hands)]
    body = 0.0
    for t in range(result.frame_count):
        w = skeleton.world_frames(result.basis[t], armature_to_world)
        for _, _, d, _ in collisions(skeleton, sens, w, vols):
            body = max(body, d)
    out["max_body_penetration_m"] = body
    out["reach_error_m"] = max(h.reach_error for h in result.hands)
    return out
