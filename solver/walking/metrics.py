"""Measurements of a generated walk, from its poses (forward kinematics), for the tests, the CLI
summary and the benchmark: cycle length against eq. 2-5, support durations against eq. 2-6,
planted feet, the root on its path, knee flexion, soles on the ground."""

import numpy as np

from . import model
from .body import KNEE_MIN
from .steps import support_of_cycle


def world(result):
    return result.trajectories.world_frames(result.skeleton)


def _point(w, joint, local):
    return w[:, joint, :3, :3] @ local + w[:, joint, :3, 3]


def sole_points(result, w=None):
    """Per side, world (F, 3) heel, ball and tip points of the sole."""
    w = world(result) if w is None else w
    out = {}
    for s, foot in result.body.feet.items():
        carrier = foot.toe if foot.toe is not None else foot.foot
        out[s] = {"heel": _point(w, foot.foot, foot.heel_in_foot), "ball": _point(w, carrier, foot.ball_in_toe),
                  "tip": _point(w, carrier, foot.tip_in_toe)}
    return out


def _stance_frames(result, fp):
    t = result.times
    return np.flatnonzero((t >= fp.t_on - 1e-9) & (t <= fp.t_off + 1e-9))


def foot_slip(result, w=None):
    """Largest movement (m) of a supporting foot: the heel from strike to heel rise, the ball from
    foot-flat to toe off (the points the foot rolls over stay put)."""
    pts = sole_points(result, w)
    worst = 0.0
    for s, prints in result.plan.footprints.items():
        for fp in prints:
            idx = _stance_frames(result, fp)
            t = result.times[idx]
            heel = idx[t <= fp.t_off - fp.toe_roll + 1e-9] if np.isfinite(fp.t_off) else idx
            ball = idx[t >= fp.t_on + fp.heel_roll - 1e-9] if np.isfinite(fp.t_on) else idx
            for name, sel in (("heel", heel), ("ball", ball), ("tip", ball)):
                if len(sel) > 1:
                    p = pts[s][name][sel]
                    worst = max(worst, float(np.linalg.norm(p - p[0], axis=1).max()))
    return worst


def sole_height_error(result, ground, w=None):
    """Largest |height above the ground| (m) of the heel and ball while the foot is flat."""
    pts = sole_points(result, w)
    worst = 0.0
    for s, prints in result.plan.footprints.items():
        for fp in prints:
            idx = _stance_frames(result, fp)
            t = result.times[idx]
            flat = idx[(t >= fp.t_on + fp.heel_roll - 1e-9) & (t <= fp.t_off - fp.toe_roll + 1e-9)]
            for name in ("heel", "ball"):
                p = pts[s][name][flat]
                if len(p):
                    worst = max(worst, float(np.abs(p[:, 2] - ground(p[:, 0], p[:, 1])).max()))
    return worst


def hip_centre(result, w=None):
    w = world(result) if w is None else w
    b = result.body
    return 0.5 * (w[:, b.thigh["L"], :3, 3] + w[:, b.thigh["R"], :3, 3])


def root_deviation(result, w=None):
    """Largest horizontal distance (m) of the hip centre from the path."""
    return float(result.path.distance_to(hip_centre(result, w)).max())


def knee_flexion(result, w=None):
    """Per side (F,) knee flexion from straight (radians); positive bends the knee the right way."""
    w = world(result) if w is None else w
    out = {}
    for s, ik in result.body.ik.items():
        ang = np.array([ik.hinge_angle(wf) for wf in w]) - result.body.straight[s]
        out[s] = (ang + np.pi) % (2 * np.pi) - np.pi
    return out


def cycles(result, w=None):
    """Each full walking cycle of each foot between two steady footprints: measured cycle length
    (m, along the path between the balls of the foot at mid-stance) and duration (s, heel strike to heel strike),
    the relative values RV = L / (Dc Ht), RLc = L / Ht and the model's 1.346 sqrt(RV) (times the
    style's stride factor)."""
    pts = sole_points(result, w)
    ht = result.body.ht
    out = []
    for s, prints in result.plan.footprints.items():
        steady = [fp for fp in prints if np.isfinite(fp.t_on) and not fp.final and not fp.stopping]
        # a cycle in which the body slows keeps its mid-stance speed's rhythm (steps.cycle_at): not eq. 2-5's
        for a, b in ((a, b) for a, b in zip(steady[:-1], steady[1:]) if not a.slowed):
            ia, ib = _stance_frames(result, a), _stance_frames(result, b)
            pa, pb = pts[s]["ball"][ia[len(ia) // 2]], pts[s]["ball"][ib[len(ib) // 2]]
            # the distance the body progressed along the path (on a straight path, the distance
            # between the footprints; on a curve, not the chord of the inner or outer foot)
            length = float(np.diff(result.path.project(np.array([pa, pb])))[0])
            dc = float(result.times[ib[0]] - result.times[ia[0]])
            rv = length / (dc * ht)
            out.append({"side": s, "start": float(result.times[ia[0]]), "length_m": length, "duration_s": dc,
                        "rv": rv, "rlc": length / ht,
                        "rlc_model": float(result.style.stride * model.relative_cycle_length(rv))})
    return sorted(out, key=lambda c: c["start"])


def support_durations(result):
    """Each steady support: its measured duration (s, frames on the ground / fps, frame-exact) and
    eq. 2-6's Ds for the cycle it belongs to (its strike to the same foot's next strike)."""
    out = []
    fps = result.trajectories.fps
    for s, prints in result.plan.footprints.items():
        for a, b in zip(prints[:-1], prints[1:]):
            if not np.isfinite(a.t_on) or a.final:
                continue
            idx = _stance_frames(result, a)
            on = result.support[s]
            first, last = idx[0], idx[-1]
            assert on[first] and on[last]
            measured = (last - first) / fps
            nxt = _stance_frames(result, b)[0]
            dc = (nxt - first) / fps
            out.append({"side": s, "measured_s": float(measured), "cycle_s": float(dc), "running": a.running,
                        "model_s": float(support_of_cycle(dc, a.rv, result.body.ht, result.style))})
    return out


def double_support_share(result):
    both = result.support["L"] & result.support["R"]
    moving = result.times > result.plan.strikes[0][0]
    moving &= result.times < result.plan.strikes[-2][0] if len(result.plan.strikes) > 2 else moving
    return float(both[moving].mean())


def flight_frames(result):
    moving = (result.times > result.plan.strikes[0][0]) & (result.times < result.plan.strikes[-1][0])
    return int((~result.support["L"] & ~result.support["R"] & moving).sum())


def summary(result, w=None):
    w = world(result) if w is None else w
    cyc = cycles(result, w)
    flex = knee_flexion(result, w)
    rel = [abs(c["rlc"] / c["rlc_model"] - 1) for c in cyc if not np.isnan(c["rlc_model"])]
    return {"thigh_height_m": result.body.ht, "steps": len(result.plan.strikes),
            "frames": int(result.trajectories.frame_count), "walk_seconds": float(result.times[-1] - result.times[0]),
            "cycles": len(cyc), "cycle_length_error_max": max(rel) if rel else 0.0,
            "max_foot_slip_mm": 1000 * foot_slip(result, w), "max_root_deviation_cm": 100 * root_deviation(result, w),
            "min_knee_flexion_deg": float(np.degrees(min(f.min() for f in flex.values()))),
            "double_support_share": double_support_share(result), "flight_frames": flight_frames(result),
            "unreached_frames": int((~result.reached).any(axis=1).sum()),
            "knee_min_allowed_deg": float(np.degrees(KNEE_MIN))}


def qa_motion(result, w=None):
    """The walk as the motion QA's Motion (bone heads and tails in the world, local rotations),
    measured as the add-on measures the action it writes."""
    from ..qa import Motion
    sk = result.skeleton
    w = world(result) if w is None else w
    heads = w[..., :3, 3]
    tails = heads + w[..., :3, 1] * sk.lengths[:, None]
    tr = result.trajectories
    return Motion(heads, tr.rotations, sk.names, tr.fps, sk.parents, tails, tr.frames)


def qa_report(result, w=None):
    """The motion QA's report of a walk (no input motion: the absolute caps), on a flat ground
    at the height of its first footprint."""
    from ..qa import feet_from_roles, measure
    sk = result.skeleton
    ground = float(result.plan.footprints["L"][0].sole[2, 3])
    return measure(qa_motion(result, w), None, feet_from_roles(sk.roles, sk.names), ground)
