"""Dynamic reactions (Oshita 2003, sec. 3.5; issue 5) on the Rigify metarig standing still: a push
sweep gives pure balance control, then a protective step, then a fall; no NaN, no bone more than
1 cm below the ground; recovery when a joint cannot follow its target. The reactions are
re-tracked by the controller (ReactionResult.target is the generated reaction it followed).

The sweep is 3, 20 and 40 N s on the root: the pelvis's peak speed 0.10, 0.63 and 3.6 m/s against
eq. 3.6's 0.5-1.0 m/s for a step. It was 3, 10 and 40 (0.22, 0.74, 3.0 m/s) while a push met a
floating body with free joints; since the planted feet hold and the joints' servo acts during a
push (motion_control.controller._Loop._through_feet, _servoed_inertia) 10 N s moves the pelvis
0.32 m/s and the figure keeps standing."""

import numpy as np
import pytest

from humananim.solver import rotations
from humananim.solver.dynamics import motion_floor
from humananim.solver.motion_control import ControlSettings, Impulse, Load
from humananim.solver.synthesis import keyframed
from humananim.solver.synthesis.action import Action
from humananim.solver.synthesis.metrics import foot_points
from humananim.solver.synthesis.reactions import ReactionSettings, fallen_pose, react, segment_heights

from test_dynamics_closed_loop_rigs import load


@pytest.fixture(scope="module")
def standing():
    sk, tr = load("metarig_legs", frames=1)
    return sk, keyframed.still(sk, tr, seconds=1.5)


def push(sk, still, magnitude, direction=-1.0, settings=None, **kw):
    fwd = keyframed.forward_of(sk, still.trajectories)
    cs = ControlSettings(impulses=(Impulse(0.3, sk.names[sk.root], (0, 0, 0), tuple(direction * fwd), magnitude),))
    return react(still, cs, settings, **kw)


def check_ground(sk, still, r):
    floor = motion_floor(sk, still.trajectories)
    assert np.isfinite(r.trajectories.rotations).all() and np.isfinite(r.trajectories.translations).all()
    assert segment_heights(sk, r.trajectories).min() > floor - 0.01
    return floor


@pytest.fixture(scope="module")
def sweep(standing):
    sk, still = standing
    return {m: push(sk, still, m) for m in (3.0, 20.0, 40.0)}


def test_push_sweep_balance_then_step_then_fall(standing, sweep):
    sk, still = standing
    kinds = [sweep[m].kind for m in sorted(sweep)]
    assert kinds == ["none", "step", "fall"]
    for r in sweep.values():
        check_ground(sk, still, r)
    small = sweep[3.0]  # the dynamic controller alone: the push moves the body, which keeps standing
    moved = small.control.trajectories.root_pose(sk)[0] - still.trajectories.root_pose(sk)[0]
    assert np.linalg.norm(moved, axis=-1).max() > 0.005
    assert not small.control.falling.any()


def test_protective_step_follows_eq_3_6_to_3_8(standing, sweep):
    sk, still = standing
    r = sweep[20.0]
    s = ReactionSettings()
    f = r.frame
    assert s.step_speed[0] < r.root_speed[f] < s.step_speed[1] and r.root_acceleration[f] > s.step_acceleration
    assert (r.root_speed[:f] <= s.step_speed[0]).all() | (r.root_acceleration[:f] <= s.step_acceleration).all()
    # the flying foot is the one nearer the ZMP
    world = r.control.trajectories.world_frames(sk)[f]
    zmp = r.control.zmp[f]
    d = {k: np.linalg.norm(world[sk.role_index(k)][:2, 3] - zmp) for k in ("foot.L", "foot.R")}
    assert r.info["flying"] == min(d, key=d.get) and r.info["base"] != r.info["flying"]
    # eq. 3.7 and 3.8 (horizontal), and the flying foot lands there
    p0 = r.control.trajectories.root_pose(sk)[0][f]
    v = np.array(r.info["root_terminal"]) - p0
    base = world[sk.role_index(r.info["base"])][:3, 3]
    fly = np.array(r.info["flying_terminal"])
    assert np.allclose(fly[:2], s.k_foot * (np.array(r.info["root_terminal"])[:2] - base[:2])
                       + np.array(r.info["root_terminal"])[:2])
    assert np.linalg.norm(v[:2]) == pytest.approx(s.k_root * r.root_speed[f], rel=0.05)
    # the generated step lands there; the controller tracking it lands the foot on the way there
    # (it carries the push's momentum and its own lag) and keeps the base foot planted
    end = r.target.world_frames(sk)[-1]
    assert np.linalg.norm(end[sk.role_index(r.info["flying"])][:2, 3] - fly[:2]) < 0.01
    pts = foot_points(sk, r.target, r.info["base"][-1])[f:]
    assert np.linalg.norm(pts - pts[0], axis=-1).max() < 0.002
    assert r.info["retracked"]
    start = r.trajectories.world_frames(sk)[f][sk.role_index(r.info["flying"])][:2, 3]
    landed = r.trajectories.world_frames(sk)[-1][sk.role_index(r.info["flying"])][:2, 3]
    assert (landed - start) @ (fly[:2] - start) > 0.5 * np.linalg.norm(fly[:2] - start) ** 2
    base = "LR".index(r.info["base"][-1])
    assert r.reaction_control.foot_slide[f:, base].max() < 0.002


def test_step_threshold_is_exposed(standing):
    sk, still = standing
    r = push(sk, still, 10.0, settings=ReactionSettings(step_speed=(0.9, 1.0)))
    assert r.kind == "none"


def test_falls_end_on_the_ground(standing, sweep):
    sk, still = standing
    back = sweep[40.0]
    floor = check_ground(sk, still, back)
    assert back.info["direction"] == "back"
    end = back.trajectories.world_frames(sk)[-1]
    hands = [end[sk.role_index(f"hand.{s}")][2, 3] for s in "LR"]
    assert max(hands) - floor < 0.12 and end[sk.root][2, 3] - floor < 0.3  # hips and hands down
    fwd = push(sk, still, 40.0, direction=1.0)
    assert fwd.kind == "fall" and fwd.info["direction"] == "forward"
    floor = check_ground(sk, still, fwd)
    end = fwd.trajectories.world_frames(sk)[-1]
    knees = [end[sk.role_index(f"shin.{s}")][2, 3] for s in "LR"]
    hands = [end[sk.role_index(f"hand.{s}")][2, 3] for s in "LR"]
    assert max(knees) - floor < 0.12 and max(hands) - floor < 0.12


def test_animators_fall_action_is_used(standing):
    sk, still = standing
    floor = motion_floor(sk, still.trajectories)
    from humananim.solver.synthesis.action import sliced
    pose = fallen_pose(sk, sliced(still.trajectories, 0, 1), "back", floor)
    n = 10
    from humananim.solver.trajectories import Trajectories
    tr = Trajectories(np.arange(n) + 1.0, still.fps, np.repeat(pose.rotations, n, axis=0),
                      np.repeat(pose.translations, n, axis=0), pose.armature_to_world)
    cons = {k: np.zeros(n, np.int8) for k in still.constraints}
    mine = Action("my fall back", sk, tr, cons, fall=True)
    r = push(sk, still, 40.0, fall_actions={"back": mine})
    assert r.kind == "fall" and r.info["fall_action"] == "my fall back"
    check_ground(sk, still, r)
    # the animator's action is what the controller tracked: it ends in it; the body ends on the ground
    assert rotations.angle_between(r.target.rotations[-1], mine.trajectories.rotations[-1]).max() < 1e-3
    assert r.info["retracked"]
    end = r.trajectories.world_frames(sk)[-1]
    assert end[sk.root][2, 3] - floor < 0.3


def test_recovery_when_a_joint_cannot_follow(standing):
    sk, still = standing
    light = react(still, ControlSettings(loads=(Load(sk.roles.bone("hand.L"), 1.0, 0.2),)))
    assert light.kind == "none"
    heavy = react(still, ControlSettings(loads=(Load(sk.roles.bone("hand.L"), 20.0, 0.2),), strength_scale=0.3))
    s = ReactionSettings()
    assert heavy.kind == "recovery"
    assert heavy.frame >= int(round((0.2 + s.recovery_time) * still.fps)) - 1
    # back to the stable (initial) posture of the action: the controller's new input (the load
    # still weighs on the weakened arm it tracks)
    heavy_bones = sk.mass > 0.01 * sk.total_mass
    err = rotations.angle_between(heavy.target.rotations[-1][heavy_bones],
                                  still.trajectories.rotations[0][heavy_bones])
    assert err.max() < 0.05 and heavy.info["retracked"]


def test_captured_motion_without_a_push_needs_no_reaction():
    """CMU 131_01 (120 fps): capture noise and the controller's foot-skate offset are not pushes."""
    from humananim.solver.synthesis import from_trajectories
    sk, tr = load("cmu_131_01")
    r = react(from_trajectories("walk", sk, tr))
    assert r.kind == "none" and r.root_speed.max() < 0.2
