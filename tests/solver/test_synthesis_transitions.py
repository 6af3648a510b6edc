"""Motion synthesis (Oshita 2003, sec. 3.3-3.4; issue 5): action constraints, blending, connection,
inertialization and the synthesizer queue, on CMU 131_01 and on keyframed still/step/kick actions
of the Rigify metarig. Proof: a supporting foot moves less than 2 mm during a transition, no
acceleration spike above the clips' own 99th percentile, rejections say why."""

import numpy as np
import pytest

from humananim.solver.synthesis import (SPATIAL, SUPPORT, Synthesizer, TransitionRejected, TransitionSettings,
                                        from_trajectories, keyframed, transition)
from humananim.solver.synthesis.action import sliced
from humananim.solver.synthesis.metrics import foot_points, planted_slide, spike_ratio
from humananim.solver.synthesis.transitions import decay

from test_dynamics_closed_loop_rigs import load

SLIDE = 0.002  # m


@pytest.fixture(scope="module")
def metarig_actions():
    sk, tr = load("metarig_legs", frames=1)
    return sk, keyframed.still(sk, tr), keyframed.step_forward(sk, tr), keyframed.kick(sk, tr)


@pytest.fixture(scope="module")
def cmu_actions():
    sk, tr = load("cmu_131_01")
    # the source has a 45000 rad/s^2 ankle glitch at frames 117-118 (its own p99 would hide spikes)
    return sk, from_trajectories("a", sk, sliced(tr, 0, 100)), from_trajectories("b", sk, sliced(tr, 60, 115)), \
        from_trajectories("c", sk, sliced(tr, 50, 115))


def check(sk, result, sources):
    assert result.held, "a transition between supported poses holds a foot"
    slide = planted_slide(sk, result.trajectories, result.held, result.window)
    assert max(slide.values()) < SLIDE, slide
    ang, lin = spike_ratio(sk, result.trajectories, result.window, [s.trajectories for s in sources])
    assert ang <= 1.0 and lin <= 1.0, (ang, lin)
    assert np.isfinite(result.trajectories.rotations).all()


def test_constraints_are_detected_from_the_motion_and_editable(metarig_actions):
    sk, still, step, kick = metarig_actions
    assert (still.constraints["foot.L"] == SUPPORT).all() and (still.constraints["foot.R"] == SUPPORT).all()
    r = step.constraints["foot.R"]
    assert r[0] == SUPPORT and r[-1] == SUPPORT and (r[20:28] != SUPPORT).all()  # the swing
    ee = step.end_effectors()["foot.R"]  # forward kinematics: the foot travels the step length
    assert np.linalg.norm(ee[-1, :2, 3] - ee[0, :2, 3]) == pytest.approx(step.meta["length"], abs=0.01)
    edited = keyframed.still(sk, load("metarig_legs", frames=1)[1])
    edited.edit("hand.L", edited.trajectories.frames[0], edited.trajectories.frames[-1], "spatial")
    assert (edited.constraints["hand.L"] == SPATIAL).all()


@pytest.mark.parametrize("pair", [("still", "step"), ("step", "still"), ("still", "kick")])
def test_blend_keyframed(metarig_actions, pair):
    sk, still, step, kick = metarig_actions
    acts = {"still": still, "step": step, "kick": kick}
    a, b = acts[pair[0]], acts[pair[1]]
    check(sk, transition(a, b, "blend"), [a, b])


def test_blend_of_spatial_hands_follows_the_blended_hand_trajectories(cmu_actions):
    from humananim.solver.synthesis.transitions import _align, smootherstep
    sk, a0, b0, c0 = cmu_actions
    a = from_trajectories("a", sk, a0.trajectories)
    c = from_trajectories("c", sk, c0.trajectories)
    for act in (a, c):
        act.edit("hand.L", act.trajectories.frames[0], act.trajectories.frames[-1], "spatial")
    r = transition(a, c, "blend")
    hand = sk.role_index("hand.L")
    lo, hi = r.window
    got = r.trajectories.world_frames(sk)[lo:hi + 1, hand]
    # eq. 3.2 per axis with the smootherstep weight, on the next action as placed at the join
    w = smootherstep(np.arange(hi - lo + 1) / (hi - lo))[:, None]
    e1 = a.end_effectors()["hand.L"][lo:hi + 1]
    e2 = _align(a, lo, c, 0).world_frames(sk)[:hi - lo + 1, hand]
    assert np.abs(e1[:, :3, 3] - e2[:, :3, 3]).max() > 0.02  # the two hands differ
    assert np.abs(got[:, :3, 3] - ((1 - w) * e1[:, :3, 3] + w * e2[:, :3, 3])).max() < 1e-3
    # orientation by slerp: halfway between the two at mid-window, within the IK's accuracy
    from humananim.solver import rotations
    from humananim.solver.skeleton import decompose
    q1, q2, qg = (decompose(x)[1] for x in (e1, e2, got))
    total = rotations.angle_between(q1, q2)
    assert np.abs(rotations.angle_between(q1, qg) - w[:, 0] * total).max() < 0.01


def test_blend_rejected_when_constraints_differ_then_connect(metarig_actions):
    sk, still, step, kick = metarig_actions
    long_blend = TransitionSettings(blend_duration=0.8)  # the step has lifted its right foot by then
    with pytest.raises(TransitionRejected) as e:
        transition(still, step, "blend", long_blend)
    assert "foot.R is supporting at the end of 'still' but angular at the start of 'step'" in e.value.reason
    check(sk, transition(still, step, "connect", long_blend), [still, step])


def test_connect_rejected_without_a_shared_supporting_foot(metarig_actions):
    sk, still, step, kick = metarig_actions
    a = keyframed.still(sk, load("metarig_legs", frames=1)[1])
    f = a.trajectories.frames
    a.edit("foot.L", f[-3], f[-1], "angular").edit("foot.R", f[-3], f[-1], "angular")
    with pytest.raises(TransitionRejected, match="no foot supports the body both at the end of 'still'"):
        transition(a, kick, "connect")
    a.edit("root", f[-1], f[-1], "supporting")
    with pytest.raises(TransitionRejected, match="connect rejected: the root is supporting"):
        transition(a, kick, "connect")


def test_connective_action_fixes_base_foot_and_moves_the_flying_foot_through_keyframes(metarig_actions):
    sk, still, step, kick = metarig_actions
    fwd = keyframed.forward_of(sk, still.trajectories)
    split = keyframed.stance(sk, load("metarig_legs", frames=1)[1], {"R": 0.25 * fwd}, name="split")
    r = transition(kick, split, "connect")  # the right foot must step forward
    check(sk, r, [kick, split])
    assert r.info["flying"] == "foot.R" and r.info["base"] == "foot.L"
    moved = split
    s = TransitionSettings()
    pts = foot_points(sk, r.trajectories, "R")[r.window[0]:r.window[1] + 1]
    assert pts[:, 0, 2].max() - pts[0, 0, 2] > 0.5 * s.lift_height  # lifted through keyframe 2
    assert np.linalg.norm(pts[-1, 0] - pts[0, 0]) == pytest.approx(0.25, abs=0.01)
    # keyframe 1: the root over the base (left) foot before the flying foot leaves
    k1 = r.window[0] + int(round(r.info["keyframe_times"][1] * r.trajectories.fps))
    root = r.trajectories.root_pose(sk)[0][k1]
    left = foot_points(sk, r.trajectories, "L")[k1]
    assert np.linalg.norm(root[:2] - left[:, :2].mean(axis=0)) < 0.12
    # eq. 3.5: no joint turns faster than the largest of the bounds (C, outgoing, next action's peak)
    q = r.trajectories.rotations[r.window[0]:r.window[1] + 1]
    from humananim.solver import rotations
    speed = rotations.angle_between(q[:-1], q[1:]) * r.trajectories.fps
    peak_next = rotations.angle_between(moved.trajectories.rotations[:-1], moved.trajectories.rotations[1:]).max() \
        * moved.fps
    assert speed.max() <= 1.6 * max(s.angular_speed, peak_next)


def test_inertialization_decays_the_offset(metarig_actions):
    sk, still, step, kick = metarig_actions
    r = transition(step, still, "inertialize")
    check(sk, r, [still, step])
    # after the window the next action plays as it is (its own, aligned, pose)
    a, b = r.trajectories.rotations[r.window[1] + 2:], still.trajectories.rotations[r.window[1] + 2 - r.next_start:]
    heavy = sk.mass > 0.01 * sk.total_mass
    legs = [sk.role_index(f"{p}.{s}") for p in ("thigh", "shin", "foot") for s in "LR"]
    heavy[legs] = False  # the legs are held by the support rule
    from humananim.solver import rotations
    assert rotations.angle_between(a[:, heavy], b[:len(a), heavy]).max() < 1e-6


def test_decay_matches_offset_and_velocity_and_ends_at_rest():
    x0, v0, T = np.array([0.3, -0.2]), np.array([-1.0, -0.5]), 0.5
    c = decay(x0, v0, T)
    t = np.linspace(0, 0.6, 601)[:, None]
    x = c(t)
    assert np.allclose(x[0], x0)
    assert np.allclose((x[1] - x[0]) / 1e-3, [v0[0], 0.0], atol=0.01)  # moving away: no overshoot
    assert np.abs(x[t[:, 0] >= T]).max() < 1e-9


@pytest.mark.parametrize("mode", ["connect", "inertialize"])
def test_cmu_connect_and_inertialize(cmu_actions, mode):
    sk, a, b, c = cmu_actions
    check(sk, transition(a, b, mode), [a, b])


def test_cmu_blend_and_its_rejection(cmu_actions):
    sk, a, b, c = cmu_actions
    lifted = from_trajectories("a", sk, sliced(load("cmu_131_01")[1], 0, 120))  # left foot in the air at its end
    with pytest.raises(TransitionRejected, match="foot.L is angular at the end of 'a' but supporting"):
        transition(lifted, b, "blend")
    check(sk, transition(a, c, "blend"), [a, c])


def test_synthesizer_queue_after_now_and_rejections(metarig_actions):
    sk, still, step, kick = metarig_actions
    syn = Synthesizer(still, TransitionSettings(blend_duration=0.8))
    n0 = syn.motion.frame_count
    r = syn.queue(step, "blend")
    assert not r.accepted and "foot.R is supporting" in r.reason
    assert syn.motion.frame_count == n0  # a rejected request changes nothing
    r = syn.queue(step, "connect")
    assert r.accepted and r.start > n0 - 1
    n1 = syn.motion.frame_count
    r = syn.queue(kick, "inertialize", when="now", at=n1 - 30)  # interrupts the step's end
    assert r.accepted and r.start == n1 - 30 + 1
    assert syn.motion.frame_count == n1 - 30 + 1 + kick.frame_count
    assert [q.accepted for q in syn.requests] == [True, False, True, True]
    with pytest.raises(Exception, match="unknown transition mode"):
        syn.queue(kick, "crossfade")


def test_held_foot_rejoins_the_next_action_smoothly_when_it_lifts(cmu_actions):
    """Fig. 3.3 (b): the held foot blends into the next action's trajectory once that lifts it,
    and is on it by the time the next action lands it again."""
    from humananim.solver.synthesis.transitions import _align
    sk, a, b, c = cmu_actions
    longer = from_trajectories("c", sk, sliced(load("cmu_131_01")[1], 50, 170))  # lifts and lands the left foot
    r = transition(a, longer, "blend")
    aligned = _align(a, r.window[0], longer, 0)
    lift = int(np.flatnonzero(r.held["L"])[-1]) + 1
    sup = longer.constraints["foot.L"] == SUPPORT
    land = r.next_start + int(np.flatnonzero(sup & (np.arange(len(sup)) > lift - r.next_start))[0])
    pts = foot_points(sk, r.trajectories, "L")[:, 0]
    own = foot_points(sk, aligned, "L")[:, 0]
    after = np.arange(land, r.trajectories.frame_count)
    assert np.abs(pts[after] - own[after - r.next_start]).max() < 1e-3  # on its own trajectory again
    # no jump on the way: the foot speeds up and slows down gradually (it also makes up the
    # distance between where it was held and where the next action has it)
    step = np.linalg.norm(np.diff(pts[lift - 2:land + 1], axis=0), axis=-1)
    assert step.max() < 0.03 and np.abs(np.diff(step)).max() < 0.2 * step.max()
