"""Record the control loop's outputs for tests/solver/test_motion_control_reference.py.

reference.npz was recorded with the implementation before the speed work (commit bed5782: the
controller with swept collider contacts and leg comfort control in double support only, numpy
1.26) plus, added to that checkout in its own terms: the landing pivot (commit 0b1ab1c's
_Loop._landing_pivot; main computes it as _Loop._landing), the legs' damping near a straight knee
(_Loop._damping, ControlSettings.singular_band and singular_damping), the tracking servo's
damping and the planted feet held during an impulse (main's _Loop._servoed_inertia and
_through_feet, inlined in _apply_impulses there); bed5782.patch beside this file is that
addition (`git apply` it on that commit). The optimised loop must reproduce it within rounding.
Run from such a checkout:

    PYTHONPATH=<checkout parent> python tests/data/motion_control/make_reference.py
"""

import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent.parent / "solver"))

from humananim.solver.motion_control import ControlSettings, Impulse, Load, control  # noqa: E402
from humananim.solver.trajectories import Trajectories  # noqa: E402
from test_dynamics_closed_loop_rigs import load  # noqa: E402
from test_motion_control_controller import squat_motion  # noqa: E402

KEYS = ("rotations", "translations", "stress", "balance_error", "zmp", "control", "falling", "foot_slide")


def hand_loads(sk, kg):
    return tuple(Load(sk.roles.bone(f"hand.{s}"), kg / 2) for s in "LR")


def chest_push(sk, time, newton_seconds):
    chest = sk.roles.chain("spine")[-1]
    return (Impulse(time, chest, (0.0, 0.1, 0.0), (0.0, 1.0, 0.0), newton_seconds),)


def first_frames(tr, n):
    return Trajectories(tr.frames[:n], tr.fps, tr.rotations[:n], tr.translations[:n], tr.armature_to_world)


def cases():
    """(name, skeleton, trajectories, settings): the squat with 8 kg in the hands and a 15 N s
    push on the chest (comfort and balance control act), 15 kg (passive control too) with and
    without control (required torques against strength on most frames), and the CMU clip's first
    second with a 10 N s push."""
    sk, tr = squat_motion()
    yield "squat_8kg_push", sk, tr, ControlSettings(loads=hand_loads(sk, 8.0), impulses=chest_push(sk, 0.5, 15.0))
    yield "squat_15kg", sk, tr, ControlSettings(loads=hand_loads(sk, 15.0))
    yield "squat_15kg_tracking", sk, tr, ControlSettings(loads=hand_loads(sk, 15.0), tracking_only=True)
    sk, tr = load("cmu_131_01")
    yield "cmu_push", sk, first_frames(tr, 120), ControlSettings(impulses=chest_push(sk, 0.3, 10.0))


def outputs(res):
    return {"rotations": res.trajectories.rotations, "translations": res.trajectories.translations,
            "stress": res.stress, "balance_error": res.balance_error, "zmp": res.zmp, "control": res.control,
            "falling": res.falling, "foot_slide": res.foot_slide}


if __name__ == "__main__":
    out = {}
    for name, sk, tr, settings in cases():
        res = outputs(control(sk, tr, settings))
        out.update({f"{name}/{k}": v for k, v in res.items()})
        print(name, "control codes", np.unique(res["control"]), "stressed frames",
              int((np.abs(res["stress"]).max(axis=(1, 2)) > 0).sum()))
    np.savez_compressed(HERE / "reference.npz", **out)
