"""Self-collision of the legs (Huang 1996 sec. 4.6, table 4-1 on the chain thigh-shin-foot): in a
crossed-legs motion on the metarig the left knee and shin pass through the right thigh and knee;
after the correction no leg sensor is inside the body on any frame and the feet keep their goals
(the secondary task moves the knee in the null space of the foot's goal). A foot whose goal is
inside the other leg gets a temporary goal outside it (sec. 4.6.3). The arms are corrected as
before, whatever the legs do."""

import numpy as np
import pytest

from hands_cases import crossed_legs, metarig
from humananim.solver.hands import self_collision as SC
from humananim.solver.hands.body import body_sensors, body_volumes, collisions
from test_hands_self_collision import crossing_reach

TOL = 0.001  # metres: the foot on its goal


@pytest.fixture(scope="module")
def rig():
    return metarig()


def leg_depths(sk, frames, a2w):
    """Per frame, the deepest leg sensor inside the body (the other leg's thigh and shin, the
    trunk), with the volumes where the legs are on that frame; and the sensors that were inside."""
    sens = [s for s in body_sensors(sk, sk.world_frames(frames[0], a2w)) if s.limb == "leg"]
    per, names = [], set()
    for f in frames:
        w = sk.world_frames(f, a2w)
        hits = collisions(sk, sens, w, [v for v in body_volumes(sk, w) if v.name != "head"])
        per.append(max([d for _, _, d, _ in hits], default=0.0))
        names |= {sens[i].name for i, *_ in hits}
    return np.array(per), names


def feet(sk, frames, a2w):
    return np.array([[sk.world_frames(f, a2w)[sk.role_index(f"foot.{s}")][:3, 3] for s in "LR"] for f in frames])


def test_crossed_legs_are_corrected_and_feet_keep_their_goals(rig):
    sk, basis, a2w = rig
    frames = crossed_legs(sk, basis)
    before, names = leg_depths(sk, frames, a2w)
    assert before.max() > 0.05 and {"knee.L", "shin.L.1"} <= names  # the knee goes through the other leg
    out, report = SC.remove_self_collisions(sk, frames, a2w, sides=())
    after, left = leg_depths(sk, out, a2w)
    assert after.max() == 0.0, left  # no leg sensor inside the body on any frame
    assert report.max_depth_after == 0.0 and report.leg_frames_corrected > 0
    # the feet stay on their goals on every frame, the knee moved out
    assert np.abs(feet(sk, out, a2w) - feet(sk, frames, a2w)).max() < TOL
    assert report.max_foot_error < TOL
    knee = sk.role_index("shin.L")
    moved = [np.linalg.norm(sk.world_frames(o, a2w)[knee][:3, 3] - sk.world_frames(f, a2w)[knee][:3, 3])
             for o, f in zip(out, frames)]
    assert max(moved) > 0.05


def test_a_foot_goal_inside_the_other_leg_takes_a_temporary_goal(rig):
    """The left shin hangs straight down onto the right ankle: the foot's own goal is inside the
    other leg, so the foot is moved out (sec. 4.6.3) and nothing is left inside."""
    sk, basis, a2w = rig
    frames = crossed_legs(sk, basis, extend=0.0)
    before, names = leg_depths(sk, frames, a2w)
    assert {"ankle.L", "foot.L"} & names
    out, report = SC.remove_self_collisions(sk, frames, a2w, sides=())
    after, left = leg_depths(sk, out, a2w)
    assert after.max() == 0.0, left
    # on the frames where the goal is clear the foot is on it; where not, it left it
    assert report.max_foot_error < TOL
    assert np.abs(feet(sk, out, a2w) - feet(sk, frames, a2w)).max() > 0.01


def test_arms_unchanged_by_the_leg_correction(rig):
    """The reach across the chest together with the crossed legs: the arm comes out exactly as
    when the legs are not corrected, and the legs are corrected."""
    sk, basis, a2w = rig
    arm, path = crossing_reach(sk, basis, a2w)
    legs = crossed_legs(sk, basis, frames=len(arm))
    both = arm.copy()
    leg_joints = [j for s in "LR" for j in SC.leg_chain_joints(sk, s)]
    both[:, leg_joints] = legs[:, leg_joints]
    targets = {"R": (path, None)}
    out, report = SC.remove_self_collisions(sk, both, a2w, sides=("R",), targets=targets)
    arms_only, _ = SC.remove_self_collisions(sk, both, a2w, sides=("R",), targets=targets, legs=())
    other = [j for j in range(sk.joint_count) if j not in leg_joints]
    assert np.array_equal(out[:, other], arms_only[:, other])
    assert leg_depths(sk, out, a2w)[0].max() == 0.0
    assert leg_depths(sk, arms_only, a2w)[0].max() > 0.05
