"""Glove sensors to finger joint angles: per-sensor gain and offset, solved from two poses
the performer holds (a flat hand and a fist), for any glove whose sensors are described by a
layout of (finger, bone index along the finger's role chain, axis) entries.

angle = gain * (raw - offset); the flat hand gives every sensor its zero (offset), the fist
gives the flexion sensors their gain (fist angle / (fist raw - flat raw)). Sensors a fist does
not move (abduction, roll, palm arch, wrist) keep the nominal gain. On gloves without distal
sensors (the 18-sensor CyberGlove) the distal joint follows the middle one by the usual
coupling, two thirds of its flexion."""

from dataclasses import dataclass, field

import numpy as np

from ...solver.body_roles import FINGERS
from .device import DeviceError

# Flexion of a fist, degrees, by (finger, bone index along its chain)
FIST_DEGREES = {("thumb", 1): 50.0, ("thumb", 2): 70.0}
FIST_DEGREES.update({(f, 0): 85.0 for f in FINGERS[1:]})
FIST_DEGREES.update({(f, 1): 100.0 for f in FINGERS[1:]})
FIST_DEGREES.update({(f, 2): 70.0 for f in FINGERS[1:]})
DIP_COUPLING = 2.0 / 3.0
NOMINAL_GAIN_DEG = 0.6  # degrees per sensor count when no pose pins the gain


@dataclass
class GloveCalibration:
    layout: tuple
    offsets: np.ndarray
    gains: np.ndarray  # radians per count
    extra: dict = field(default_factory=dict)

    @classmethod
    def nominal(cls, layout, flat=None):
        n = len(layout)
        offsets = np.zeros(n) if flat is None else np.asarray(flat, float)
        return cls(tuple(layout), offsets, np.full(n, np.radians(NOMINAL_GAIN_DEG)))

    @classmethod
    def from_poses(cls, layout, flat, fist, resolution=1.0):
        """`resolution`: one step of the glove's raw values (1 count for the CyberGlove's bytes,
        1/4096 for the 5DT's 12-bit values); a flexion sensor must move by more than two."""
        flat, fist = np.asarray(flat, float), np.asarray(fist, float)
        if flat.shape != (len(layout),) or fist.shape != flat.shape:
            raise DeviceError(f"calibration poses need {len(layout)} sensor values each")
        cal = cls.nominal(layout, flat)
        for i, (finger, bone, axis) in enumerate(layout):
            target = FIST_DEGREES.get((finger, bone)) if axis == "flex" else None
            if target is None:
                continue
            span = fist[i] - flat[i]
            if abs(span) <= 2 * resolution:
                raise DeviceError(f"sensor {i} ({finger} {bone} {axis}) hardly changed between the flat hand "
                                  "and the fist: hold each pose and calibrate again")
            cal.gains[i] = np.radians(target) / span
        return cal

    def angles(self, raw):
        """{(finger, bone index, axis): radians} for one record."""
        values = self.gains * (np.asarray(raw, float) - self.offsets)
        out = {}
        for (finger, bone, axis), v in zip(self.layout, values):
            out[(finger, bone, axis)] = out.get((finger, bone, axis), 0.0) + float(v)
        for finger in FINGERS[1:]:
            if (finger, 1, "flex") in out and (finger, 2, "flex") not in out:
                out[(finger, 2, "flex")] = DIP_COUPLING * out[(finger, 1, "flex")]
        return out

    def to_dict(self):
        return {"layout": [list(x) for x in self.layout], "offsets": self.offsets.tolist(),
                "gains": self.gains.tolist()}

    @classmethod
    def from_dict(cls, d):
        return cls(tuple(tuple(x) for x in d["layout"]), np.asarray(d["offsets"], float),
                   np.asarray(d["gains"], float))


AXES = {"flex": 0, "arch": 0, "roll": 1, "abduct": 2, "spread": 2}


def joint_rotations(angles, side="R"):
    """Joint angles to quaternions (w, x, y, z) per (finger or 'hand'/'palm', bone index), in the
    bone's local frame: flexion about X, roll about Y (along the bone), spread about Z, with Z
    mirrored on the left hand."""
    eulers = {}
    for (finger, bone, axis), v in angles.items():
        e = eulers.setdefault((finger, bone), np.zeros(3))
        k = AXES[axis]
        e[k] += -v if (k == 2 and side == "L") else v
    if not eulers:
        return {}
    from ...solver import rotations
    keys = list(eulers)
    quats = rotations.from_euler(np.array([eulers[k] for k in keys]), "XYZ")
    return dict(zip(keys, quats))
