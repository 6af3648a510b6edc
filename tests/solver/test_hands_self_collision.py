"""Self-collision (sec. 4.6): a reach across the chest that would put the elbow or hand through
the torso is corrected with no sensor inside the body on any frame, while the hand still reaches
its goal; the secondary task moves the elbow without moving the hand; the paired sensors catch a
forearm crossing the body with both ends outside (fig. 4-20)."""

import numpy as np
import pytest

from hands_cases import metarig
from humananim.solver.hands import ik
from humananim.solver.hands import self_collision as SC
from humananim.solver.hands.body import body_sensors, body_volumes, collisions


@pytest.fixture(scope="module")
def rig():
    return metarig()


def crossing_reach(sk, basis, a2w, frames=30):
    """The right hand driven along a straight line from its side to the front of the left
    shoulder: plain IK takes the arm through the torso."""
    w = sk.world_frames(basis, a2w)
    hand = sk.role_index("hand.R")
    p0, p1 = w[hand][:3, 3], np.array([0.16, -0.16, 1.38])
    path = np.array([p0 + (p1 - p0) * t / (frames - 1) for t in range(frames)])
    ch = ik.Chain.arm(sk, "R")
    out, cur = [], basis.copy()
    for p in path:
        cur = ik.solve(ch, cur, ik.chain_base(ch, sk.world_frames(cur, a2w)), p, iterations=50).basis
        out.append(cur)
    return np.array(out), path


def deepest(sk, frames, a2w, side="R"):
    w0 = sk.world_frames(frames[0], a2w)
    vols = [v for v in body_volumes(sk, w0) if v.name in ("trunk", "head")]
    sens = [s for s in body_sensors(sk, w0) if s.limb == "arm" and s.chain_side == side]
    per = []
    for f in frames:
        per.append(max([d for *_, d, _ in collisions(sk, sens, sk.world_frames(f, a2w), vols)], default=0.0))
    return np.array(per)


def deepest_by_sensor(sk, frames, a2w, side="R"):
    w0 = sk.world_frames(frames[0], a2w)
    vols = [v for v in body_volumes(sk, w0) if v.name in ("trunk", "head")]
    sens = [s for s in body_sensors(sk, w0) if s.limb == "arm" and s.chain_side == side]
    out = {}
    for f in frames:
        for i, _, d, _ in collisions(sk, sens, sk.world_frames(f, a2w), vols):
            out[sens[i].name] = max(out.get(sens[i].name, 0.0), d)
    return out


def test_reach_across_the_chest_is_corrected(rig):
    sk, basis, a2w = rig
    frames, path = crossing_reach(sk, basis, a2w)
    assert deepest(sk, frames, a2w).max() > 0.03  # the uncorrected reach goes through the torso
    out, report = SC.remove_self_collisions(sk, frames, a2w, sides=("R",), targets={"R": (path, None)})
    assert deepest(sk, out, a2w).max() == 0.0  # no sensor inside the body on any frame
    hand = sk.role_index("hand.R")
    assert np.linalg.norm(sk.world_frames(out[-1], a2w)[hand][:3, 3] - path[-1]) < 0.001
    assert report.frames_corrected > 0 and report.max_depth_after == 0.0


def test_temporary_goals_alone_leave_the_elbow_in(rig):
    """Sec. 4.6.3's alternative (temporary end-effector goals, Zhao and Badler) keeps the hand
    out but, as the thesis argues, cannot take out an elbow when the hand is not involved: the
    secondary task is needed for that."""
    sk, basis, a2w = rig
    frames, path = crossing_reach(sk, basis, a2w)
    goal, _ = SC.remove_self_collisions(sk, frames, a2w, sides=("R",), targets={"R": (path, None)}, method="GOAL")
    left = deepest_by_sensor(sk, goal, a2w)
    assert "hand.R" not in left
    assert any(k.startswith(("elbow", "forearm")) for k in left)


def test_secondary_task_moves_the_elbow_not_the_hand(rig):
    sk, basis, a2w = rig
    frames, path = crossing_reach(sk, basis, a2w)
    w0 = sk.world_frames(basis, a2w)
    vols = [v for v in body_volumes(sk, w0) if v.name == "trunk"]
    hand = sk.role_index("hand.R")
    # a frame whose hand and wrist are clear of the trunk but whose elbow is inside
    sens = [s for s in body_sensors(sk, w0) if s.limb == "arm" and s.chain_side == "R"]
    pick = None
    for t, f in enumerate(frames):
        hits = collisions(sk, sens, sk.world_frames(f, a2w), vols)
        names = {sens[i].name for i, *_ in hits}
        if "elbow.R" in names and not names & {"hand.R", "forearm.R.2"}:
            pick = t
            break
    assert pick is not None
    w = sk.world_frames(frames[pick], a2w)
    fixed, before, after, _ = SC.correct_frame(sk, frames[pick], a2w, "R", w[hand][:3, 3], None, vols,
                                               sensors=body_sensors(sk, w0))
    assert before > 0 and after == 0.0
    wf = sk.world_frames(fixed, a2w)
    assert np.linalg.norm(wf[hand][:3, 3] - w[hand][:3, 3]) < 0.001


def test_paired_sensors_catch_a_crossing_forearm(rig):
    """Fig. 4-20: the forearm passes through the trunk while the elbow and hand sensors are
    outside it; only the paired sensors along the forearm see it."""
    sk, basis, a2w = rig
    w0 = sk.world_frames(basis, a2w)
    from humananim.solver.hands.body import Capsule
    fa = sk.role_index("forearm.R")
    mid = w0[fa][:3, :3] @ [0, 0.5 * sk.lengths[fa], 0] + w0[fa][:3, 3]
    thin = Capsule("trunk", mid - [0, 0.3, 0], mid + [0, 0.3, 0], 0.03)  # a pole across the forearm's middle
    with_pairs = collisions(sk, body_sensors(sk, w0, paired=True), w0, [thin])
    without = collisions(sk, body_sensors(sk, w0, paired=False), w0, [thin])
    assert not without and with_pairs



def test_frames_near_the_body_are_corrected_together_as_one_by_one(rig):
    """On its own targets an arm's frames near the body are corrected as one batch. On a two-hand
    reach to a 20 cm cylinder at the chest (the arms brush the trunk): every sensor out on every
    frame, the hands on their targets, and each frame the pose that correcting it on its own
    gives (a frame's iterations do not depend on the others in its batch)."""
    from hands_cases import frame
    from humananim.solver.hands import grasp as G
    from humananim.solver.hands.primitives import Cylinder
    sk, basis, a2w = rig
    g = G.grasp(sk, basis, a2w, Cylinder(frame((0.0, -0.4, 1.3)), 0.1, 0.2), avoid_body=False)  # as the benchmark's
    assert len(g.hands) == 2
    frames = g.basis[:g.reach_frames + 1]
    assert deepest(sk, frames, a2w, "L").max() > 0 and deepest(sk, frames, a2w, "R").max() > 0
    out, report = SC.remove_self_collisions(sk, frames, a2w, sides=("L", "R"), legs=())
    assert report.frames_corrected > 4
    for side in ("L", "R"):
        assert deepest(sk, out, a2w, side).max() == 0.0  # no sensor inside the body on any frame
    assert report.max_goal_error < 1e-3
    world = sk.world_frames(frames, a2w)
    for side in ("L", "R"):
        hand = sk.role_index(f"hand.{side}")
        cor = SC.arm_corrector(sk, world[0], side)
        one_by_one = [cor.run(frames[t], world[t], world[t, hand, :3, 3], world[t, hand, :3, :3], 0.01, 40)[0]
                      for t in range(len(frames))]
        batch = cor.run_many(frames, world, world[:, hand, :3, 3], world[:, hand, :3, :3], 0.01, 40)[0]
        assert np.abs(np.array(one_by_one) - batch).max() < 1e-9
