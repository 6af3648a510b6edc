"""Boulic's normalised walking model (Boulic, Magnenat-Thalmann and Thalmann 1990, as summarised by
Huang 1996, sec. 2.6): every spatial value is a multiple of the thigh height Ht of the rig, every
temporal value follows from the relative velocity RV = V / Ht (1/s).

  relative cycle length   RLc = 1.346 sqrt(RV)                      (eq. 2-5, Inman)
  cycle duration          Dc  = RLc / RV = 1.346 / sqrt(RV)
  support                 Ds  = 0.752 Dc - 0.143                    (eq. 2-6)
  balance (swing)         Db  = 0.248 Dc + 0.143
  double support          Dds = 0.252 Dc - 0.143

A cycle is two steps; its phase runs from 0 at the right heel strike to 1 at the next one.

Running (not in eq. 2-6): above a Froude number V^2 / (g Ht) of `Style.run_froude` (0.6 by
default, the walk-run transition of human gait is near 0.5) the gait becomes a run: the support
shrinks to a duty factor below one half, so double support vanishes and a flight phase of
Dc/2 - Ds appears in every step; the cycle length keeps eq. 2-5. Supported range: RV from 0.375
(a slow walk, 0.34 m/s for Ht = 0.9 m) to 5 (a run of about 4.5 m/s for Ht = 0.9 m).

Personification (Boulic's "personification parameters"): scale factors of the model's normal
values, 1 by default (the normal walk the model was fitted to), and a torso lean in degrees (0).
"""

from dataclasses import asdict, dataclass, replace

import numpy as np

from ..errors import HumanAnimError

GRAVITY = 9.81
RV_MIN, RV_MAX = 0.375, 5.0  # below RV_MIN (cycles over 2.2 s: starting, stopping) the cycle keeps 2.2 s


@dataclass(frozen=True)
class Style:
    stride: float = 1.0  # scales the cycle length (and so the cadence at a given speed)
    pelvis_rotation: float = 1.0  # amplitude of the pelvis turning about the vertical
    pelvis_tilt: float = 1.0  # amplitude of the pelvic list (side drop) and of its bounce
    arm_swing: float = 1.0
    knee_flexion: float = 1.0  # knee flexion in stance (the pelvis sinks accordingly)
    heel_strike: float = 1.0  # toe-up angle of the foot as the heel lands
    torso_lean: float = 0.0  # degrees forward
    run_froude: float = 0.6  # V^2/(g Ht) above which the walk becomes a run

    def to_dict(self):
        return asdict(self)


PRESETS = {
    "neutral": Style(),
    "brisk": Style(stride=1.1, pelvis_rotation=1.3, pelvis_tilt=0.8, arm_swing=1.6, knee_flexion=0.8,
                   heel_strike=1.3, torso_lean=4.0),
    "tired": Style(stride=0.85, pelvis_rotation=0.7, pelvis_tilt=1.4, arm_swing=0.4, knee_flexion=1.5,
                   heel_strike=0.4, torso_lean=10.0),
    "sneaking": Style(stride=0.75, pelvis_rotation=0.5, pelvis_tilt=0.5, arm_swing=0.3, knee_flexion=3.5,
                      heel_strike=0.2, torso_lean=18.0),
}


def preset(name, **overrides):
    try:
        style = PRESETS[name]
    except KeyError:
        raise HumanAnimError(f"unknown walking style {name!r} (styles: {', '.join(PRESETS)})") from None
    return replace(style, **overrides)


def relative_cycle_length(rv):
    """Eq. 2-5: RLc = 1.346 sqrt(RV)."""
    return 1.346 * np.sqrt(rv)


def cycle_duration(rv, stride=1.0):
    """Dc = RLc / RV (s); the stride factor lengthens the cycle at the same speed."""
    return stride * relative_cycle_length(rv) / rv


def walk_durations(dc):
    """Eq. 2-6: (Ds, Db, Dds) of a walking cycle of duration dc (s)."""
    return 0.752 * dc - 0.143, 0.248 * dc + 0.143, 0.252 * dc - 0.143


def is_running(rv, ht, style=Style()):
    return (rv * ht) ** 2 / (GRAVITY * ht) > style.run_froude


def run_duty(rv, ht, style=Style()):
    """Share of the cycle a foot supports in a run: 0.45 at the transition, falling with speed to 0.3."""
    rv_run = np.sqrt(style.run_froude * GRAVITY / ht)
    return float(np.clip(0.45 - 0.06 * (rv - rv_run), 0.3, 0.45))


def durations(rv, ht, style=Style()):
    """(Dc, Ds, Db, Dds) in seconds at relative velocity rv; Dds < 0 is a flight phase (a run)."""
    check_rv(rv, ht)
    dc = float(cycle_duration(rv, style.stride))
    if is_running(rv, ht, style):
        ds = run_duty(rv, ht, style) * dc
        return dc, ds, dc - ds, ds - dc / 2
    ds, db, dds = walk_durations(dc)
    return dc, ds, db, dds


def check_rv(rv, ht):
    if rv > RV_MAX:
        raise HumanAnimError(f"{rv * ht:.2f} m/s is beyond the gait model's range (at most "
                             f"{RV_MAX * ht:.2f} m/s for this rig's thigh height of {ht:.2f} m)")


@dataclass(frozen=True)
class Oscillations:
    """Amplitudes over a cycle at one RV: metres (as multiples of Ht resolved) and radians."""

    vertical: float  # pelvis bounce, twice per cycle, lowest just after each heel strike
    lateral: float  # pelvis sway towards the supporting foot, once per cycle
    forward: float  # surge about the mean forward progress, twice per cycle
    rotation: float  # pelvis turning about the vertical (the forward leg's side ahead)
    list: float  # pelvic list: the swinging side drops
    knee: float  # knee flexion at mid-stance (the pelvis sinks to give it)
    arm: float  # shoulder swing about the lateral axis, opposite to the same-side leg
    elbow: float  # mean elbow flexion
    heel: float  # foot pitch (toe up) at heel strike
    toe_off: float  # foot pitch (heel up) at toe off
    clearance: float  # lift of the swinging foot above its straight path


def oscillations(rv, ht, style=Style(), running=False):
    """Boulic's trajectories reduced to amplitudes (normalised by Ht, which they are multiplied
    by here): the pelvis bounce grows with speed (0.015 RV Ht); the lateral sway is Boulic's
    0.032 Ht above RV 0.5 (0.128 RV (1 - RV) Ht below), 5.6 cm peak to peak for Ht = 0.88 m, as
    Bandai Namco's captured walks sway (5.5-6.9 cm at 0.7-1.6 m/s; a sway shrinking with speed
    gave 3.4 cm); pelvic rotation and list follow Inman's figures (about 4 and 5 degrees at a
    normal walk)."""
    rv = float(rv)
    deg = np.radians
    if running:
        return Oscillations(vertical=0.025 * ht * style.pelvis_tilt, lateral=0.008 * ht * style.pelvis_tilt,
                            forward=0.01 * ht, rotation=deg(min(8.0, 2.5 * rv)) * style.pelvis_rotation,
                            list=deg(4.0) * style.pelvis_tilt, knee=deg(28.0) * style.knee_flexion,
                            arm=deg(min(30.0, 8.0 + 5.0 * rv)) * style.arm_swing, elbow=deg(80.0),
                            heel=deg(8.0) * style.heel_strike, toe_off=deg(35.0),
                            clearance=0.12 * ht)
    return Oscillations(
        vertical=min(0.015 * rv, 0.03) * ht * style.pelvis_tilt,
        lateral=(0.032 if rv > 0.5 else 0.128 * rv * (1 - rv)) * ht * style.pelvis_tilt,
        forward=min(0.005 * rv, 0.01) * ht,
        rotation=deg(min(8.0, 2.5 * rv)) * style.pelvis_rotation,
        list=deg(min(5.0, 1.5 + 2.5 * rv)) * style.pelvis_tilt,
        knee=deg(12.0) * style.knee_flexion,
        arm=deg(min(25.0, 6.0 + 7.0 * rv)) * style.arm_swing,
        elbow=deg(15.0 + 5.0 * rv),
        heel=deg(min(20.0, 8.0 + 6.0 * rv)) * style.heel_strike,
        toe_off=deg(min(60.0, 30.0 + 15.0 * rv)),
        clearance=0.04 * ht)
