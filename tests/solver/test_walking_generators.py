"""Generators on scopes with priorities default / weighted / exclusive / clearing (Huang 1996
sec. 6.4.3), several actors each with its own stack (sec. 6.4.4), a walk as a generator."""

import numpy as np
import pytest

from humananim.solver import rotations
from humananim.solver.errors import HumanAnimError
from humananim.solver.trajectories import Trajectories
from humananim.solver.walking import Actor, Stage, scope_bones, walk_generator

from walking_cases import rig, walked


def constant(sk, bones, angle, frames=11):
    """A motion turning `bones` by `angle` about their x axes, held for `frames` frames."""
    rot = np.zeros((frames, sk.joint_count, 4))
    rot[..., 0] = 1.0
    for b in bones:
        rot[:, sk.index(b)] = rotations.from_axis_angle([angle, 1.0, 0.0, 0.0])
    return Trajectories(np.arange(frames) + 1.0, 24.0, rot, np.zeros((frames, sk.joint_count, 3)), np.eye(4))


def angle_of(tr, sk, bone):
    return 2 * np.arctan2(np.linalg.norm(tr.rotations[:, sk.index(bone), 1:], axis=-1),
                          np.abs(tr.rotations[:, sk.index(bone), 0]))


def test_scopes_from_roles():
    sk = rig("metarig")
    legs, arm_r, hand_r, head = (scope_bones(sk, n) for n in ("legs", "arm.R", "hand.R", "head"))
    assert {"thigh.L", "shin.R", "foot.L", "toe.R"} <= legs and "upper_arm.L" not in legs
    assert {"upper_arm.R", "forearm.R", "hand.R"} <= arm_r and hand_r < arm_r
    assert any(b.startswith("f_index") for b in hand_r)  # fingers come with the hand
    assert not legs & arm_r and "spine.006" in head
    assert scope_bones(sk, ["thigh.L"]) == {"thigh.L"}
    with pytest.raises(HumanAnimError):
        scope_bones(sk, "tail")
    with pytest.raises(HumanAnimError):
        scope_bones(sk, ["no_such_bone"])


def test_default_waits_for_the_previous_generator_on_its_scope():
    sk = rig("metarig")
    a = Actor("A", sk)
    a.add("wave", constant(sk, ["forearm.R"], 0.5), start=1, scope="arm.R")
    a.add("wave again", constant(sk, ["forearm.R"], 1.0), start=5, scope="arm.R")
    a.add("nod", constant(sk, ["spine.006"], 0.3), start=5, scope="head")  # other scope: not delayed
    s = {x.generator.name: x for x in a.schedule()}
    assert (s["wave again"].start, s["wave again"].end) == (11.0, 21.0)
    assert s["nod"].start == 5.0
    tr = a.evaluate(np.arange(1, 22))
    ang = angle_of(tr, sk, "forearm.R")
    assert ang[:10] == pytest.approx(0.5) and ang[11:] == pytest.approx(1.0)
    assert angle_of(tr, sk, "spine.006")[4:15] == pytest.approx(0.3)


def test_weighted_mixes_with_its_weight():
    sk = rig("metarig")
    a = Actor("A", sk)
    a.add("base", constant(sk, ["forearm.R"], 1.0), start=1, scope="arm.R")
    a.add("mix", constant(sk, ["forearm.R"], 0.0), start=3, scope="arm.R", priority="weighted", weight=0.25)
    s = {x.generator.name: x for x in a.schedule()}
    assert s["mix"].start == 3 and s["base"].end == 11
    ang = angle_of(a.evaluate(np.arange(1, 12)), sk, "forearm.R")
    assert ang[0] == pytest.approx(1.0)
    assert ang[5] == pytest.approx(0.75, abs=0.02)  # nlerp of 1 rad towards 0 by a quarter


def test_exclusive_stops_others_on_its_scope_only():
    sk = rig("metarig")
    a = Actor("A", sk)
    a.add("reach", constant(sk, ["forearm.R"], 1.0, 21), start=1, scope="arm.R")
    a.add("look", constant(sk, ["spine.006"], 0.4, 21), start=1, scope="head")
    a.add("grasp", constant(sk, ["hand.R"], 0.6), start=8, scope="arm.R", priority="exclusive")
    s = {x.generator.name: x for x in a.schedule()}
    assert s["reach"].bone_end("forearm.R") == 8 and s["reach"].stopped_by == ["grasp"]
    assert s["look"].end == 21 and s["look"].stopped_by == []
    tr = a.evaluate(np.arange(1, 22))
    fore = angle_of(tr, sk, "forearm.R")
    assert fore[:7] == pytest.approx(1.0) and fore[8:17] == pytest.approx(0.0)  # the grasp owns the arm
    assert angle_of(tr, sk, "hand.R")[8:17] == pytest.approx(0.6)
    assert angle_of(tr, sk, "spine.006")[15] == pytest.approx(0.4)


def test_clearing_stops_everything():
    sk = rig("metarig")
    a = Actor("A", sk)
    a.add("reach", constant(sk, ["forearm.R"], 1.0, 21), start=1, scope="arm.R")
    a.add("look", constant(sk, ["spine.006"], 0.4, 21), start=1, scope="head")
    a.add("fall", constant(sk, ["thigh.L"], 0.7), start=6, scope="legs", priority="clearing")
    s = {x.generator.name: x for x in a.schedule()}
    assert s["reach"].bone_end("forearm.R") == 6 and s["look"].bone_end("spine.006") == 6
    assert s["reach"].pieces() == [(s["reach"].scope, 1.0, 6.0)]
    tr = a.evaluate(np.arange(1, 22))
    assert angle_of(tr, sk, "spine.006")[10] == pytest.approx(0.0)
    assert angle_of(tr, sk, "thigh.L")[10] == pytest.approx(0.7)


def test_a_walk_under_a_wave_on_the_right_arm():
    r = walked("metarig", "straight")
    sk = r.body.skeleton
    a = Actor("walker", sk)
    walk_generator(a, r)
    wave = constant(sk, ["forearm.R", "upper_arm.R"], 1.2, 30)
    a.add("wave", wave, start=60, scope="arm.R", priority="exclusive")
    frames = r.trajectories.frames
    tr = a.evaluate(frames, r.trajectories.fps)
    on = (frames >= 60) & (frames <= 89)
    legs = [sk.index(b) for b in scope_bones(sk, "legs")]
    np.testing.assert_allclose(tr.rotations[:, legs], r.trajectories.rotations[:, legs], atol=1e-12)
    assert angle_of(tr, sk, "forearm.R")[on] == pytest.approx(1.2)
    assert not np.allclose(angle_of(tr, sk, "forearm.R")[~on & (frames > 30)], 1.2)
    walk_s = a.schedule()[0]
    # the walk loses the right arm from the wave's start, and keeps the rest: two NLA pieces
    (all_bones, a0, a1), (rest, b0, b1) = walk_s.pieces()
    assert (a0, a1) == (frames[0], 60) and all_bones == walk_s.scope
    assert rest == walk_s.scope - scope_bones(sk, "arm.R") and b1 == frames[-1]


def test_several_actors_each_with_its_own_stack():
    stage = Stage()
    m, c = rig("metarig"), rig("cmu")
    stage.actor("anna", m).add("wave", constant(m, ["forearm.R"], 0.5), start=1, scope="arm.R")
    stage.actor("ben", c).add("kick", constant(c, ["RightHip"], 0.8), start=1, scope="legs")
    out = stage.evaluate(np.arange(1, 11))
    assert set(out) == {"anna", "ben"}
    assert angle_of(out["anna"], m, "forearm.R") == pytest.approx(0.5)
    assert angle_of(out["ben"], c, "RightHip") == pytest.approx(0.8)
    assert out["anna"].rotations.shape[1] == m.joint_count and out["ben"].rotations.shape[1] == c.joint_count
    with pytest.raises(HumanAnimError):
        stage.actor("nobody")
