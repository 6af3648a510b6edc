"""Footsteps along a path: when each foot lands and leaves (eq. 2-5 and 2-6 at the speed the body
has over each cycle) and where (under the body at mid-stance, beside the path, turned along it,
on the ground). Starts and ends standing, feet side by side."""

from dataclasses import dataclass, field

import numpy as np

from . import model
from .body import rot_x, rot_z

STEP_WIDTH = 0.6  # share of the hip width between the feet while walking (they come closer)
PLACED = 0.5  # share of a support at which the body is over the ankle (0.4 lowered the strike's snap
# but raised the loading one)
TOE_ROLL = 0.4  # share of a support from heel rise to toe off (a slower rise moved an ankle 2 cm
# over the ground while it was still down)


@dataclass
class Footprint:
    side: str
    t_on: float  # heel strike (-inf: standing from the start)
    t_off: float  # toe off (inf: standing at the end)
    sole: np.ndarray  # (4, 4) world sole frame: origin under the heel, columns right, forward, up
    heading: float  # radians, of the forward axis about world Z
    ground_pitch: float  # toe-up slope of the ground along the foot
    heel: float = 0.0  # foot pitch at heel strike (radians, toe up)
    toe_off: float = 0.0  # foot pitch at toe off (radians, heel up)
    heel_roll: float = 0.0  # seconds from strike to foot flat
    toe_roll: float = 0.0  # seconds from heel rise to toe off
    rv: float = 0.0
    dc: float = 0.0
    running: bool = False
    final: bool = False
    stopping: bool = False  # a step of the stop, its cycle held at the walk's rhythm (not eq. 2-5)
    slowed: bool = False  # the body slows within its cycle, which keeps its mid-stance speed's rhythm


@dataclass
class StepPlan:
    footprints: dict  # side -> [Footprint] in time order
    strikes: list  # (time, side, rv, dc, running) of every step, in order
    t_end: float  # time the walk is over (both feet down, body at the end of the path)
    first_side: str = "R"
    gait_window: tuple = field(default=(0.0, 0.0))  # (first strike, last strike)


def heading_angle(h):
    return float(np.arctan2(h[1], h[0]))


def sole_frame(body, side, ankle_xy, heading, ground):
    """A footprint's sole frame with its ankle over `ankle_xy`, turned to `heading` (unit 2-vector
    of the forward direction), pitched to the ground between heel and ball."""
    foot = body.feet[side]
    psi = heading_angle(heading) - heading_angle(body.forward[:2])
    rot = rot_z(psi) @ foot.rest_sole[:3, :3]
    origin_xy = np.asarray(ankle_xy, float) - (rot @ foot.ankle_local)[:2]
    ball_xy = origin_xy + (rot @ foot.ball_sole_local)[:2]
    z = ground(np.array([origin_xy[0], ball_xy[0]]), np.array([origin_xy[1], ball_xy[1]]))
    pitch = float(np.arctan2(z[1] - z[0], max(foot.ball_sole_local[1], 1e-3)))
    m = np.eye(4)
    m[:3, :3] = rot @ rot_x(pitch)
    m[:3, 3] = [origin_xy[0], origin_xy[1], z[0]]
    return m, psi, pitch


def cycle_at(body, progress, style, t, o_now, o_next, dc0=1.0, with_slowing=False):
    """The cycle of a footprint struck at t and placed where the body is at t + o_now (its
    mid-stance); the same foot's next one is struck at t + Dc and placed at t + Dc + o_next. Dc is
    the fixed point of Dc = 1.346 / sqrt(RV) with RV the body's mean speed between the two
    placements over Dc, so the distance between the footprints is exactly RLc Ht (eq. 2-5)."""
    ht, dc = body.ht, dc0

    def rv_of(dc):
        return float(max(mean_rv(dc), progress.speed(t + o_now) / ht, model.RV_MIN))

    def mean_rv(dc):
        return (progress(t + dc + o_next) - progress(t + o_now)) / (dc * ht)

    for _ in range(80):
        new = model.durations(rv_of(dc), ht, style)[0]
        if abs(new - dc) < 1e-9:
            break
        dc = 0.5 * (dc + new)
    rv = rv_of(dc)
    if with_slowing:  # the body slows within the cycle: it keeps the rhythm of its mid-stance speed
        return rv, model.durations(rv, ht, style), bool(mean_rv(dc) < 0.95 * rv)
    return rv, model.durations(rv, ht, style)


def support_of_cycle(dc, rv, ht, style):
    """Support duration of a cycle that actually lasted dc seconds: eq. 2-6 (or the run's duty)."""
    if model.is_running(rv, ht, style):
        return model.run_duty(rv, ht, style) * dc
    return model.walk_durations(dc)[0]


def plan(body, path, progress, style, ground, first_side="R", fps=None, passes=5):
    """Footprints of both feet. With `fps`, heel strikes fall on frames, so each support lasts
    eq. 2-6's Ds of its cycle to within a frame when counted in frames. Each footprint sits where
    the body is at its mid-stance, which depends on the next cycles: a few passes settle it."""
    offsets = None
    for _ in range(passes):
        result, new = _plan_pass(body, path, progress, style, ground, first_side, fps, offsets)
        if offsets is not None and len(new) == len(offsets) and np.allclose(new, offsets, atol=1e-6):
            break
        offsets = new
    return result


def _plan_pass(body, path, progress, style, ground, first_side, fps, offsets):
    snap = (lambda t: round(t * fps) / fps) if fps else (lambda t: t)
    ht = body.ht
    other = {"L": "R", "R": "L"}
    width = {s: STEP_WIDTH * body.hip_offset[s] for s in "LR"}
    stand_width = {s: body.hip_offset[s] for s in "LR"}

    def place(side, s, lateral):
        h = path.heading(s)
        right = np.array([h[1], -h[0]])
        return sole_frame(body, side, path.at(s)[:2] + lateral[side] * right, h, ground)

    def offset(n, fallback):
        known = offsets is not None and n < len(offsets) and np.isfinite(offsets[n])
        return offsets[n] if known else fallback

    prints = {s: [Footprint(s, -np.inf, np.inf, *place(s, 0.0, stand_width))] for s in "LR"}
    # the first swing starts as the body starts moving (t = 0): the first strike is one balance
    # phase later
    t, ds = 0.5, 0.6
    for _ in range(80):
        _, (dc, ds, db, dds) = cycle_at(body, progress, style, t, offset(0, PLACED * ds), offset(2, PLACED * ds))
        if abs(db - t) < 1e-9:
            break
        t = 0.5 * (t + db)
    t = snap(t)
    strikes, side, dc, new_offsets = [], first_side, 1.0, []
    steady = None  # the last cycle before the stop: the closing steps keep its rhythm
    next_strike = {}  # side -> its next strike, ending the cycle its last footprint began

    def lift(prev, t_strike, db, osc, ds):
        """The previous footprint of a side leaves one balance phase before the side's next strike:
        its support then lasts Dc - Db = Ds of the cycle it actually had (eq. 2-6)."""
        prev.t_off = t_strike - db if not np.isfinite(prev.t_on) else \
            prev.t_on + support_of_cycle(t_strike - prev.t_on, prev.rv, ht, style)
        prev.toe_off = osc.toe_off
        # standing, the heel rises no earlier than a quarter second before the body moves
        prev.toe_roll = TOE_ROLL * (prev.t_off - prev.t_on) if np.isfinite(prev.t_on) else \
            min(TOE_ROLL * ds, max(prev.t_off + 0.25, 0.1 * ds))

    n, top = 0, 0.0
    while True:
        o_now = offset(n, PLACED * ds)
        rv, (dc, ds, db, dds), slowed = cycle_at(body, progress, style, t, o_now, offset(n + 2, o_now), dc,
                                                 with_slowing=True)
        s_mid = float(progress(t + o_now))
        final = bool(s_mid >= path.length - 0.25 * rv * ht * dc or t + o_now >= progress.duration)
        top = max(top, rv)
        slowing = bool(steady is not None and progress.speed(t + o_now) < progress.speed(t) - 1e-6)
        stopping = bool(slowing and rv < 0.6 * top)
        if (final or stopping or (slowing and rv < steady)) and steady is not None:
            # the last steps of a stop keep the rhythm of the walk (the body slows to a halt
            # under them) rather than stretching into ever slower cycles
            rv, (dc, ds, db, _) = steady, model.durations(steady, ht, style)
        steady = rv if rv > 0.6 * top or steady is None else steady
        new_offsets.append(np.nan if final else PLACED * ds)  # a final footprint is not placed by time
        running = bool(model.is_running(rv, ht, style))
        osc = model.oscillations(rv, ht, style, running)
        lift(prints[side][-1], t, db, osc, ds)
        sole, psi, pitch = place(side, path.length if final else s_mid, stand_width if final else width)
        prints[side].append(Footprint(side, t, np.inf, sole, psi, pitch, heel=osc.heel, heel_roll=0.15 * ds,
                                      rv=rv, dc=dc, running=running, final=final, stopping=stopping,
                                      slowed=slowed))
        strikes.append((t, side, rv, dc, running))
        # each foot's next strike ends the cycle its last strike began (snapped per cycle, so a
        # cycle is off its model duration by half a frame at most)
        next_strike[side] = snap(t + dc)
        side, n = other[side], n + 1
        t = snap(t + dc / 2) if final or side not in next_strike else \
            max(next_strike[side], t + (1 / fps if fps else 1e-3))
        if final:  # the closing step: the other foot comes beside it
            lift(prints[side][-1], t, db, osc, ds)
            sole, psi, pitch = place(side, path.length, stand_width)
            prints[side].append(Footprint(side, t, np.inf, sole, psi, pitch, heel=0.5 * osc.heel,
                                          heel_roll=0.15 * ds, rv=rv, dc=dc, running=running, final=True))
            strikes.append((t, side, rv, dc, running))
            break
    t_end = max(progress.duration, strikes[-1][0] + 0.5 * strikes[-1][3])
    return StepPlan(prints, strikes, t_end, first_side, (strikes[0][0], strikes[-1][0])), new_offsets
