"""The thesis's load experiments (Oshita 2003, sec. 2.6, fig. 2.7-2.8) on its squat: a figure
squatting with a box held forward in both hands (squat_scene.box_squat, on the Rigify metarig
fixture, 30 fps), with the default strength model.

  (a) no load: the input is tracked, nothing acts;
  (b) 8 kg: "the arms were slightly controlled ... to reduce the stress on the back when raising
      the back": shoulders and lower back are over strength under pure tracking; with control the
      arms and the back deviate from the input to relieve them, and fewer frames are over strength;
  (c) 15 kg: "the back was forced to bend. Subsequently, the figure recovered to the input motion
      by swinging the arms": the back bends far more than with 8 kg, no fall, and the figure is
      back within 2 deg of the input once the squat is over (the load stays in the hands, as in
      the thesis).

Measured (the same on numpy 2 and 1.26): no load: nothing over strength, nothing acts, 0.00 deg;
8 kg: pure tracking over strength on 23 of 136 frames (shoulders on 5, lower back on 18, at the
bottom and as the back rises), with control on none; the arms deviate 25 deg, the back 7.9 deg
(comfort and passive control), end error 0.00 deg; 15 kg: 66 -> 33 frames, the back bends 51 deg,
every joint within 0.01 deg of the input at the end (two seconds of standing after the squat), no
fall, the feet do not slide.

On the CMU walk (131_01, loads in both hands from the first frame) the same three experiments:
no diverging with 6 and 8 kg, the arms and back relieving the stress under 8 kg, and the back
bending under 15 kg and recovering while the walk goes on (the test_*_cmu_walk_* tests).

Rounding (fixed 2026-11-23): (c) used to pass or fail with the last bits (gravity scaled by
1 + 1e-14 failed it; the numpy version moved the bend from 25 to 72 deg). The cause was a tie: a
part's comfort and balance candidates were each capped at max_part_acceleration before "the larger
one acts" compared them, so two saturated candidates both measured 20 rad/s^2 and the last bit
chose. The larger demand now acts, capped after the choice; the perturbed runs agree with the
unperturbed one to 1e-9 rad (test_c_15kg_recovery_does_not_hang_on_rounding). Near the strength
limit the outcome still depends on the load itself: with the same scene, 14.5 and 15.5 kg leave
the back bent after the squat (measured; 14, 14.8, 15.2 and 16 kg recover).

The 15 kg run is sensitive to the scene: with the hands 5 cm higher at the bottom (drop 0.25)
the back bends past 80 deg and does not come back within the clip (comfort control relieves the
back's static overload by accelerations, which the tracking cannot undo once the bent back's
torque-angle factor has fallen); see the report.
"""

from pathlib import Path

import numpy as np
import pytest

from humananim.solver import bvh, rotations
from humananim.solver.dynamics import motion_floor
from humananim.solver.motion_control import ControlSettings, Impulse, Load, control
from humananim.solver.trajectories import Trajectories

from squat_scene import box_squat, hand_loads


@pytest.fixture(scope="module")
def squat():
    return box_squat(rest=2.0)  # two seconds standing after the squat: time to recover


@pytest.fixture(scope="module")
def runs(squat):
    """control() results per (kg, tracking_only), computed once."""
    sk, tr = squat
    cache = {}

    def run(kg, tracking_only=False):
        key = (kg, tracking_only)
        if key not in cache:
            cache[key] = control(sk, tr, ControlSettings(loads=hand_loads(sk, kg) if kg else (),
                                                         tracking_only=tracking_only))
        return cache[key]
    return run


def deviation(tr, res):
    """(F, J) degrees between output and input local rotations."""
    return np.degrees(rotations.angle_between(res.trajectories.rotations, tr.rotations))


def over_strength_frames(res, bones=None):
    """Frames on which some joint torque (of `bones`) is over strength."""
    stress = res.stress if bones is None else res.stress[:, bones]
    return int((np.abs(stress).max(axis=(1, 2)) > 0).sum())


def arms(sk):
    return [sk.role_index(f"upper_arm.{s}") for s in "LR"]


def back(sk):
    return sk.index(sk.roles.chain("spine")[0])  # the back of the thesis's control (3 DOF)


def test_scene_is_balanced_and_within_strength_unloaded(squat, runs):
    sk, tr = squat
    res = runs(0.0, tracking_only=True)
    assert over_strength_frames(res) == 0 and np.all(res.balance_error == 0.0)
    assert np.all(res.support) and res.foot_slide.max() < 0.002


def test_a_no_load_is_tracked(squat, runs):
    sk, tr = squat
    res = runs(0.0)
    e = deviation(tr, res)[:, sk.mass > 0]
    assert np.sqrt(np.mean(e ** 2)) < 1.0 and e.max() < 1.5
    assert np.all(res.control == 0) and not res.falling.any()


def test_b_8kg_arms_and_back_relieve_the_stress(squat, runs):
    sk, tr = squat
    tracked, res = runs(8.0, tracking_only=True), runs(8.0)
    # pure tracking: shoulders and lower back over strength
    assert over_strength_frames(tracked, arms(sk)) >= 3 and over_strength_frames(tracked, [back(sk)]) >= 10  # measured 5, 18
    assert over_strength_frames(res) < over_strength_frames(tracked) / 4  # measured 23 -> 0
    e = deviation(tr, res)
    arm_dev, back_dev = e[:, arms(sk)].max(), e[:, back(sk)].max()
    assert arm_dev > 10.0 and back_dev > 3.0  # measured 25 and 7.9 deg
    # by comfort control (the overlay's blue) and passive control (yellow), not balance
    assert (res.control[:, arms(sk)] == 2).any() and np.isin(res.control[:, back(sk)], (1, 2)).any()
    assert not res.falling.any() and res.foot_slide.max() < 0.002
    assert e[-1, sk.mass > 0].max() < 2.0
    print(f"8 kg: over strength {over_strength_frames(tracked)} -> {over_strength_frames(res)} frames; "
          f"arms {arm_dev:.1f} deg, back {back_dev:.2f} deg")


def test_c_15kg_the_back_bends_and_recovers(squat, runs):
    sk, tr = squat
    tracked, res, light = runs(15.0, tracking_only=True), runs(15.0), runs(8.0)
    assert over_strength_frames(res) < 0.75 * over_strength_frames(tracked)  # measured 66 -> 28 (numpy 2), 24 (1.26)
    e = deviation(tr, res)
    bent = e[:, back(sk)].max()
    assert bent > 15.0 and bent > 2.5 * deviation(tr, light)[:, back(sk)].max()  # measured 72 (25) vs 7.9 deg
    assert not res.falling.any() and res.foot_slide.max() < 0.002
    # back to the input once the squat is over (the box still in the hands)
    end = int(round((0.5 + 3.0) * tr.fps))
    worst = e[:, sk.mass > 0].max(axis=1)
    assert worst[end:].min() < 2.0 and worst[-1] < 2.0
    print(f"15 kg: over strength {over_strength_frames(tracked)} -> {over_strength_frames(res)} frames; "
          f"back bends {bent:.1f} deg; end error {worst[-1]:.2f} deg")


def test_c_15kg_recovery_does_not_hang_on_rounding(squat, runs):
    """(c) must hold on any machine, so it may not depend on rounding: gravity scaled by
    (1 + eps), eps far below any physical meaning, must give the same motion as the unperturbed
    run (measured: within 1e-9 rad) and so the same outcome (back bent and recovered, no fall, feet
    planted). Before the fix of the candidates' tie (module docstring) 6 of these 8 runs failed
    with numpy 1.26, 4 with numpy 2, and the motions parted by up to 1 rad."""
    sk, tr = squat
    unperturbed = runs(15.0).trajectories.rotations
    for eps in (1e-14, -1e-14, 1e-13, -1e-13, 3e-12, -3e-12, 1e-11, -1e-11):
        res = control(sk, tr, ControlSettings(loads=hand_loads(sk, 15.0), gravity=(0.0, 0.0, -9.81 * (1 + eps))))
        apart = np.abs(res.trajectories.rotations - unperturbed).max()
        assert apart < 1e-6, f"the motion parts by {apart:.2g} with gravity scaled by 1 + {eps:g}"
        worst = deviation(tr, res)[:, sk.mass > 0].max(axis=1)
        assert not res.falling.any(), f"falls with gravity scaled by 1 + {eps:g}"
        assert res.foot_slide.max() < 0.002, f"feet slide with gravity scaled by 1 + {eps:g}"
        assert worst[-1] < 2.0, f"{worst[-1]:.0f} deg from the input at the end with gravity scaled by 1 + {eps:g}"


CLIP = Path(__file__).resolve().parents[2] / "humananim_addon" / "data" / "mocap" / "cmu_131_01.bvh"


@pytest.fixture(scope="module")
def walk():
    clip = bvh.read(CLIP)
    sk = bvh.skeleton(clip)
    return sk, bvh.trajectories(clip, sk)


@pytest.fixture(scope="module")
def walk_runs(walk):
    """control() results on the CMU walk per (kg in each hand, tracking_only), computed once, on the
    ground these experiments were measured on: the clip's lowest point (closed_loop.motion_floor).
    The default ground (contacts.contact_floor) is 7.7 mm higher here: a rolled left sole corner
    reaches 3.3 cm below zero during frames 355-421 while the body rests 2.5 cm above it elsewhere;
    test_motion_control_floor tests that default."""
    sk, tr = walk
    cache = {}
    ground = motion_floor(sk, tr)

    def run(kg, tracking_only=False):
        if (kg, tracking_only) not in cache:
            loads = tuple(Load(sk.roles.bone(f"hand.{s}"), kg) for s in "LR")
            cache[kg, tracking_only] = control(sk, tr, ControlSettings(loads=loads, tracking_only=tracking_only,
                                                                       ground_height=ground))
        return cache[kg, tracking_only]
    return run


def spine(sk):
    return [sk.index(n) for n in sk.roles.chain("spine")]


@pytest.mark.parametrize("kg", [6.0, 8.0])
def test_loads_in_the_hands_on_the_cmu_walk(walk, walk_runs, kg):
    """The bundled CMU 131_01 (995 frames at 120 Hz: start, walk, stop) with kg in each hand: the
    controller does not diverge. Before the legs' control through the pelvis was kept to double
    support (comfort_control.comfort_candidates), 6 kg per hand collapsed the supporting knee in
    single support (85 deg off the input). Measured: 38 deg (6 kg) and 36 deg (8 kg) at most, a
    knee in the double support around frame 449; no fall; planted feet within 1.6 mm; frames with a
    joint over strength 539 -> 222 (6 kg), 648 -> 243 (8 kg) against pure tracking."""
    sk, tr = walk
    tracked, res = walk_runs(kg, tracking_only=True), walk_runs(kg)
    assert np.all(np.isfinite(res.trajectories.rotations)) and not res.falling.any()
    e = deviation(tr, res)[:, sk.mass > 0]
    assert e.max() < 60.0 and res.foot_slide.max() < 0.002
    assert over_strength_frames(res) < 0.6 * over_strength_frames(tracked)
    print(f"CMU {kg} kg per hand: max deviation {e.max():.1f} deg, over strength "
          f"{over_strength_frames(tracked)} -> {over_strength_frames(res)} frames, slide {res.foot_slide.max() * 1e3:.2f} mm")


def test_b_8kg_on_the_cmu_walk_arms_and_back_relieve_the_stress(walk, walk_runs):
    """(b) on the capture: 8 kg in each hand. Pure tracking has the shoulders over strength on 295
    frames and the back on 28; with control the arms deviate up to 31 deg and the back 7 deg (numpy
    2: 9) from the input, and they are over strength on 2 and 1 frames (measured)."""
    sk, tr = walk
    tracked, res = walk_runs(8.0, tracking_only=True), walk_runs(8.0)
    for bones, moved in ((arms(sk), 10.0), (spine(sk), 3.0)):
        assert over_strength_frames(tracked, bones) > 20
        assert over_strength_frames(res, bones) < 0.1 * over_strength_frames(tracked, bones)
        assert deviation(tr, res)[:, bones].max() > moved
    print(f"CMU 8 kg: arms over strength {over_strength_frames(tracked, arms(sk))} -> "
          f"{over_strength_frames(res, arms(sk))} frames, back {over_strength_frames(tracked, spine(sk))} -> "
          f"{over_strength_frames(res, spine(sk))}; arms move {deviation(tr, res)[:, arms(sk)].max():.1f} deg, "
          f"back {deviation(tr, res)[:, spine(sk)].max():.1f} deg")


def test_c_15kg_on_the_cmu_walk_the_back_bends_and_recovers(walk, walk_runs):
    """(c) on the capture: 15 kg in each hand. The back bends far more than under 8 kg (at least
    twice: measured 22 deg against 9.4, the same on both numpys) and comes back within 2 deg of the
    input soon after its deepest bend, while the walk goes on with the load; no fall, feet planted."""
    sk, tr = walk
    res = walk_runs(15.0)
    bend = deviation(tr, res)[:, spine(sk)].max(axis=1)
    deepest = int(np.argmax(bend))
    assert bend[deepest] > 15.0 and bend[deepest] > 2.0 * deviation(tr, walk_runs(8.0))[:, spine(sk)].max()
    back_within = np.flatnonzero(bend[deepest:] < 2.0)
    assert len(back_within) and back_within[0] / tr.fps < 1.5
    assert np.all(np.isfinite(res.trajectories.rotations)) and not res.falling.any()
    assert res.foot_slide.max() < 0.002
    print(f"CMU 15 kg: the back bends {bend[deepest]:.1f} deg at {deepest / tr.fps:.2f} s, within 2 deg "
          f"{back_within[0] / tr.fps:.2f} s later")


@pytest.mark.parametrize("at", [1.0, 4.0])
def test_d_a_frontal_push_on_the_cmu_walk_recovers(walk, walk_runs, at):
    """A 10 N s push on the chest while standing (1 s) and mid-walk (4 s): pure tracking would need
    the ZMP outside the support; with control it stays inside (no balance error beyond the
    unpushed walk's own) and every joint is back within 2 deg of the unpushed controlled walk
    within 1 s (the legs are compared with that, not the capture, whose foot skate the planted
    feet remove). Measured: moved 4.2 and 3.6 deg, back after 0.29 and 0.26 s (6 N s moved 2.5 and
    1.9 deg since the joints' servo takes part of a push, pushes.servoed_inertia)."""
    sk, tr = walk
    chest = sk.roles.chain("spine")[-1]
    push = (Impulse(at, chest, (0.0, 0.1, 0.0), (0.0, 1.0, 0.0), 10.0),)
    calm = walk_runs(0.0)
    ground = motion_floor(sk, tr)  # walk_runs' ground
    res = control(sk, tr, ControlSettings(impulses=push, ground_height=ground))
    tracked = control(sk, tr, ControlSettings(impulses=push, tracking_only=True, ground_height=ground))
    hit, second = int(round(at * tr.fps)), int(round(tr.fps))
    assert np.nan_to_num(tracked.balance_error[hit:hit + second]).max() > 0.01
    excess = np.nan_to_num(res.balance_error) - np.nan_to_num(calm.balance_error)
    assert excess[hit:hit + second].max() < 1e-3 and not res.falling.any()
    e = np.degrees(rotations.angle_between(res.trajectories.rotations, calm.trajectories.rotations))[:, sk.mass > 0]
    worst = e.max(axis=1)
    late = np.flatnonzero(worst[hit:] > 2.0)
    assert worst[hit:hit + second].max() > 3.0 and len(late) and (late.max() + 1) / tr.fps < 1.0
    assert res.foot_slide.max() < 0.002
    print(f"CMU push at {at} s: moved {worst[hit:hit + second].max():.1f} deg, back within 2 deg after "
          f"{(late.max() + 1) / tr.fps:.2f} s")


def test_recorded_controls_do_not_depend_on_rounding(walk, walk_runs):
    """The baked control codes (the overlay's colours) mark the DOFs a control moved by more than
    rounding: the comfort candidate's pseudo-inverse leaves 1e-16..1e-15 rad/s^2 on DOFs it does
    not move, and gravity x (1 + 1e-14) flipped 25-32 recorded codes of the 15 kg walk while the
    motion stayed within 5e-12 (measured before the threshold, comfort_control.ACTED)."""
    sk, tr = walk
    calm = walk_runs(15.0)
    loads = tuple(Load(sk.roles.bone(f"hand.{s}"), 15.0) for s in "LR")
    g = np.array(ControlSettings().gravity) * (1.0 + 1e-14)
    res = control(sk, tr, ControlSettings(loads=loads, gravity=tuple(g), ground_height=motion_floor(sk, tr)))
    assert np.abs(res.trajectories.rotations - calm.trajectories.rotations).max() < 1e-9
    assert np.array_equal(res.control, calm.control)
    assert np.count_nonzero(calm.control) > 0


def test_a_foot_landing_turned_by_a_push_does_not_slide(walk):
    """A 15 N s push on the chest at 0.99 s, while the left foot swings: the foot lands turned
    from the capture's, and its first target turns it to the capture's rotation at once. That turn
    is about the contact point (feet.PlantedFeet.landing), not the ankle, which slid the
    contact 1.4 mm in one step (measured before the pivot; 2.4 mm in the demo, with 5 kg in each
    hand, on Blender's import). Measured now: 0.23 mm."""
    sk, tr = walk
    n = int(2.5 * tr.fps)
    tr = Trajectories(tr.frames[:n], tr.fps, tr.rotations[:n], tr.translations[:n], tr.armature_to_world)
    chest = sk.roles.chain("spine")[-1]
    res = control(sk, tr, ControlSettings(impulses=(Impulse(0.99, chest, (0.0, 0.1, 0.0), (0.0, 1.0, 0.0), 15.0),)))
    hit = int(round(0.99 * tr.fps))
    landing = hit + np.flatnonzero(res.support[hit:, 0] & ~res.support[hit - 1:-1, 0])
    assert len(landing) and not res.falling.any()
    assert res.foot_slide.max() < 0.001
    print(f"landing at frame {landing[0]}: slide {res.foot_slide.max() * 1e3:.2f} mm")


@pytest.mark.parametrize("direction", [1.0, -1.0])
def test_d_a_huge_push_on_the_cmu_walk_knocks_the_figure_over(walk, direction):
    """150 N s on the chest while standing, from the front and from behind: the figure is knocked
    over (the impulse carries its capture point far beyond the feet) and falls without exploding.
    Before the knock-over test, the planted feet took the momentum back and the upper body spun
    175 deg and came back, standing."""
    sk, tr = walk
    n = int(round(2.5 * tr.fps))  # 1.5 s of falling: a ragdoll on the ground is the slow part
    tr = Trajectories(tr.frames[:n], tr.fps, tr.rotations[:n], tr.translations[:n], tr.armature_to_world)
    chest = sk.roles.chain("spine")[-1]
    hit = int(round(1.0 * tr.fps))
    res = control(sk, tr, ControlSettings(impulses=(Impulse(1.0, chest, (0.0, 0.1, 0.0), (0.0, direction, 0.0), 150.0),)))
    assert np.all(np.isfinite(res.trajectories.rotations)) and np.all(np.isfinite(res.trajectories.translations))
    assert res.falling[hit + 1:].all() and not res.falling[:hit].any()
    print(f"CMU 150 N s ({direction:+.0f}): falls from frame {np.argmax(res.falling)}")
