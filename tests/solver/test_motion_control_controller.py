"""Oshita's dynamic motion control loop (motion_control.controller) reproducing the thesis's
experiments (2003, sec. 2.6) on a squat built on the Rigify metarig fixture, and on the CMU clip.

The squat: the metarig's first frame, arms forward holding the load in front of the chest (arm
LimbIK), trunk leaning 25 deg forward at the bottom, pelvis lowered 25 cm and moved 6 cm back, the
legs solved by LimbIK so that the feet stay on the floor (0.2 um); 0.5 s still, then one 3 s
squat, at 30 fps (106 frames, the thesis's 1/30 s step).

Measured (this machine):
  (1) no input: squat 2e-4 deg RMS (3e-3 max), ZMP inside all along, nothing acts; CMU 131_01
      (120 fps, full control): 0.35 deg RMS on the tracked joints, planted contacts drift 1.1 mm;
      the supporting legs differ by 1.3 deg RMS because the capture's own foot skate is removed;
  (2, 3) loads in the hands: test_motion_control_experiments.py, on the thesis's squat (a box
      held forward, trunk leaning over the knees: squat_scene.box_squat);
  (4) a frontal push on the chest: back within 2 deg of the input 1.2 s after 10 N s (4.1 deg
      away), 1.9 s after 15 N s (6.2 deg), with the ZMP kept inside; 150 N s: the figure falls (no NaN, lowest contact sphere
      above -1 cm);
  (5) supporting feet: 0.15 mm at most while balance control moves the pelvis;
  (6) a 5 kg, 10 cm ball moving at 3 m/s into the chest: the chest's velocity changes at impact like
      an impulse, the figure swings back and does not fall.
"""

from dataclasses import replace

import numpy as np
import pytest

from humananim.solver import rotations
from humananim.solver.dynamics import build_model, default_contacts, desired_motion, point_positions
from humananim.solver.motion_control import (Collider, ControlSettings, Impulse, LimbIK, control,
                                             iter_control)
from humananim.solver.trajectories import Trajectories

from squat_scene import hand_loads
from test_dynamics_closed_loop_rigs import load


def squat_motion(seconds=3.0, depth=0.25, back=0.06, lean=25.0, hold=0.5, reach=0.35):
    sk, tr = load("metarig_legs", frames=1)
    fps = tr.fps
    n = int(round((seconds + hold) * fps)) + 1
    t = np.maximum(np.arange(n) / fps - hold, 0.0)
    s = 0.5 * (1.0 - np.cos(2.0 * np.pi * t / seconds))
    rot = np.repeat(tr.rotations[:1], n, axis=0)
    trans = np.repeat(tr.translations[:1], n, axis=0)
    basis0, w0 = tr.basis()[0], tr.world_frames(sk)[0]
    for side, sign in (("L", 1.0), ("R", -1.0)):  # arms forward, hands in front of the chest
        ik = LimbIK(sk, side, "arm", basis=basis0)
        target = w0[ik.end].copy()
        target[:3, 3] = w0[ik.upper][:3, 3] + np.array([-sign * 0.08, -reach, -0.25])
        q, _, _ = ik.solve(ik.parent_frame(w0), target, ik.swivel(w0))
        rot[:, [ik.upper, ik.lower, ik.end]] = q
    spine = sk.index(sk.roles.chain("spine")[0])
    for f in range(n):  # +X of the lowest spine bone leans the trunk forward (-Y)
        rot[f, spine] = rotations.multiply(rot[0, spine], rotations.axis_rotation(0, np.radians(lean) * s[f]))
    base = Trajectories(np.arange(n) + tr.frames[0], fps, rot, trans, tr.armature_to_world)
    pos, ori = base.root_pose(sk)
    pos = pos.copy()
    pos[:, 2] -= depth * s
    pos[:, 1] += back * s
    base = base.with_root_pose(sk, pos, ori)
    rot, basis, worlds = base.rotations.copy(), base.basis(), base.world_frames(sk)
    for f in range(n):  # legs by LimbIK: the feet stay where frame 0 has them
        for side in "LR":
            ik = LimbIK(sk, side, basis=basis[f])
            q, _, reached = ik.solve(ik.parent_frame(worlds[f]), w0[ik.end], ik.swivel(w0))
            assert reached
            rot[f, [ik.upper, ik.lower, ik.end]] = q
    return sk, Trajectories(base.frames, fps, rot, base.translations, tr.armature_to_world)


@pytest.fixture(scope="module")
def squat():
    return squat_motion()


def errors(sk, tr, res):
    """(F, bones with mass) degrees between output and input local rotations."""
    return np.degrees(rotations.angle_between(res.trajectories.rotations, tr.rotations))[:, sk.mass > 0]


def rms(x):
    return float(np.sqrt(np.mean(np.square(x))))


def lowest_sphere(sk, tr, res):
    m = build_model(sk, reference_basis=tr.basis()[0])
    d, c = m.create_data(), default_contacts(m)
    qs = desired_motion(m, sk, res.trajectories)[0]
    return min((point_positions(m, d, q, c.joints, c.points)[:, 2] - c.radii).min() for q in qs)


@pytest.fixture(scope="module")
def no_input(squat):
    return control(*squat)


def test_interface_and_progress(squat):
    sk, tr = squat
    steps = iter_control(sk, tr, ControlSettings(tracking_only=True))
    progress = []
    while True:
        try:
            progress.append(next(steps))
        except StopIteration as done:
            res = done.value
            break
    assert progress[-1] == 1.0 and np.all(np.diff(progress) > 0)
    nf, J = tr.frame_count, sk.joint_count
    assert res.stress.shape == (nf, J, 3) and res.control.shape == (nf, J) and res.control.dtype == np.int8
    assert res.zmp.shape == res.mmp.shape == res.support.shape == res.foot_slide.shape == (nf, 2)
    assert res.balance_error.shape == res.falling.shape == (nf,) and len(res.polygon) == nf
    assert res.trajectories.rotations.shape == tr.rotations.shape


def test_1_no_input_tracks_the_squat(squat, no_input):
    sk, tr = squat
    e = errors(sk, tr, no_input)
    assert rms(e) < 0.2 and e.max() < 1.5
    assert not no_input.falling.any() and np.all(no_input.balance_error == 0.0)
    assert np.all(no_input.control == 0) and np.all(no_input.support)
    print("squat RMS", rms(e), "max", e.max())


def leg_bones(sk):
    return {sk.role_index(f"{r}.{s}") for s in "LR" for r in ("thigh", "shin", "foot", "toe")} - {None}


def test_1_no_input_tracks_cmu():
    """Full control, no input: the tracked joints follow the capture; the supporting legs are the
    limb IK's (sec. 2.4.2), and they differ from the capture by its own foot skate (up to 10 cm of
    travel of a planted foot in 131_01), which the planted feet remove."""
    sk, tr = load("cmu_131_01")
    res = control(sk, tr)
    e = np.degrees(rotations.angle_between(res.trajectories.rotations, tr.rotations))
    tracked = np.array([sk.mass[j] > 0 and j not in leg_bones(sk) for j in range(sk.joint_count)])
    assert rms(e[:, tracked]) < 1.0  # measured 0.35 deg
    assert res.foot_slide.max() < 0.002  # measured 1.1 mm
    assert not res.falling.any()
    print("CMU RMS tracked joints", rms(e[:, tracked]), "legs", rms(e[:, sorted(leg_bones(sk))]),
          "slide", res.foot_slide.max())


def push(sk, newton_seconds):
    chest = sk.roles.chain("spine")[-1]
    return ControlSettings(impulses=(Impulse(0.5, chest, (0.0, 0.1, 0.0), (0.0, 1.0, 0.0), newton_seconds),))


def recovery_seconds(sk, tr, res, hit_time=0.5, tolerance=2.0):
    e = errors(sk, tr, res).max(axis=1)
    hit = int(round(hit_time * tr.fps))
    return (np.flatnonzero(e[hit:] > tolerance).max() + 1) / tr.fps, e[hit + 3]


@pytest.mark.parametrize("newton_seconds, within", [(10.0, 1.5), (15.0, 2.5)])
def test_4_5_frontal_impulse_recovers_and_feet_stay(squat, newton_seconds, within):
    """A frontal push on the chest: the ZMP leaves the support polygon under pure tracking, balance
    control keeps it in (arms, back), and every joint is back within 2 deg of the input. How soon
    depends on the push: measured 1.2 s at 10 N s, 1.9 at 15 (a
    0.2 m/s push on a 70 kg figure: the pelvis can only be stopped as fast as the ZMP at the heel
    allows; the thesis's figure recovers "while maintaining balance", without a time). The push
    moves some joint well beyond the 2 deg band (4.1 and 6.2 deg; the joints' servo takes part of
    it, pushes.servoed_inertia: 6 N s moved 2.5 deg, 7 before it)."""
    sk, tr = squat
    tracked = control(sk, tr, replace(push(sk, newton_seconds), tracking_only=True))
    assert tracked.balance_error.max() > 0.01  # pure tracking would need the ZMP outside
    res = control(sk, tr, push(sk, newton_seconds))
    seconds, moved = recovery_seconds(sk, tr, res)
    assert moved > 3.0 and seconds < within
    assert (res.control == 3).any() and res.balance_error.max() < 1e-3 and not res.falling.any()
    assert res.foot_slide.max() < 0.002  # (5)
    print(newton_seconds, "N s: recovered after", seconds, "s; slide", res.foot_slide.max())


def test_a_chosen_substep_keeps_the_frame_rate_and_the_experiments(squat):
    """Two Euler steps a frame (ControlSettings.substeps, the panel's Substeps): the result has the
    input's frames; no input is still tracked, and the 10 N s push still moves a joint beyond the
    2 deg band and comes back within it as at one step a frame, feet planted."""
    sk, tr = squat
    settings = replace(push(sk, 10.0), substeps=2)
    calm = control(sk, tr, replace(settings, impulses=()))
    assert np.array_equal(calm.trajectories.frames, tr.frames) and calm.trajectories.fps == tr.fps
    e = errors(sk, tr, calm)
    assert rms(e) < 0.2 and e.max() < 1.5 and not calm.falling.any()
    res = control(sk, tr, settings)
    seconds, moved = recovery_seconds(sk, tr, res)
    assert moved > 3.0 and seconds < 1.5
    assert res.foot_slide.max() < 0.002 and not res.falling.any()
    one_step = control(sk, tr, push(sk, 10.0)).trajectories.rotations
    assert np.abs(res.trajectories.rotations - one_step).max() > 1e-6  # the steps were taken
    print("two substeps: moved", moved, "deg, back after", seconds, "s; slide", res.foot_slide.max())


def test_a_load_from_a_chosen_time_changes_nothing_before_it(squat, no_input):
    """15 kg in the hands from 1.5 s (the panel's Load From): the frames before are the unloaded
    run's (within 1e-9: nothing of the load acts before it), with no control acting; from then on dynamic control carries it (comfort
    control acts and the body moves away from the input, measured 20 deg at most)."""
    sk, tr = squat
    res = control(sk, tr, ControlSettings(loads=hand_loads(sk, 15.0, start_time=1.5)))
    start = int(round(1.5 * tr.fps))
    assert np.abs(res.trajectories.rotations[:start] - no_input.trajectories.rotations[:start]).max() < 1e-9
    assert np.all(res.control[:start] == 0)
    assert (res.control[start:] == 2).any()  # comfort control
    assert errors(sk, tr, res)[start:].max() > 5.0 and not res.falling.any()


def test_a_force_over_an_interval_pushes_like_its_impulse(squat, no_input):
    """100 N on the chest for 0.1 s (an Impulse with a duration: an external force in inverse
    dynamics, over the steps it spans) against 10 N s at once: nothing before it, then the same
    push: joints moved beyond the 2 deg band, back within it, feet planted."""
    sk, tr = squat
    chest = sk.roles.chain("spine")[-1]
    force = Impulse(0.5, chest, (0.0, 0.1, 0.0), (0.0, 1.0, 0.0), 100.0, duration=0.1)
    res = control(sk, tr, ControlSettings(impulses=(force,)))
    hit = int(round(0.5 * tr.fps))
    assert np.abs(res.trajectories.rotations[:hit] - no_input.trajectories.rotations[:hit]).max() < 1e-9
    seconds, _ = recovery_seconds(sk, tr, res)
    moved = errors(sk, tr, res).max(axis=1)
    at_once = errors(sk, tr, control(sk, tr, push(sk, 10.0))).max(axis=1)
    assert moved.max() > 3.0 and 0.3 < moved.max() / at_once.max() < 3.0
    assert seconds < 1.5 and res.foot_slide.max() < 0.002 and not res.falling.any()
    print("100 N for 0.1 s: moved", moved.max(), "deg (10 N s at once:", at_once.max(), "), back after", seconds)


def test_4_huge_impulse_falls_without_exploding(squat):
    sk, tr = squat
    chest = sk.roles.chain("spine")[-1]
    res = control(sk, tr, ControlSettings(impulses=(Impulse(0.5, chest, (0.0, 0.1, 0.0), (0.0, 1.0, 0.0), 150.0),)))
    assert res.falling.any() and np.all(np.isfinite(res.trajectories.rotations))
    low = lowest_sphere(sk, tr, res) - lowest_sphere(sk, tr, control(sk, tr, ControlSettings(tracking_only=True)))
    assert low > -0.01
    print("fell at", np.argmax(res.falling), "lowest sphere", low)


def test_6_collider_hits_the_chest(squat, no_input):
    sk, tr = squat
    nf = tr.frame_count
    chest = sk.index(sk.roles.chain("spine")[-1])
    w = tr.world_frames(sk)[:, chest, :3, 3]
    speed, radius, hit = 3.0, 0.1, int(round(1.0 * tr.fps))
    times = (np.arange(nf) - hit) / tr.fps
    # a fist from the front (-Y): reaches the chest just after 1 s, goes on 5 cm, retracts
    reach = 0.05 / speed + 0.04 / speed
    y = np.where(times <= reach, times, 2 * reach - times) * speed - 0.25
    vy = np.where(times <= reach, speed, -speed)
    pos = w[hit] + np.outer(y, [0.0, 1.0, 0.0])
    vel = np.outer(vy, [0.0, 1.0, 0.0])
    col = Collider(pos[:, None, :], np.array([radius]), vel[:, None, :], mass=5.0)
    res = control(sk, tr, ControlSettings(colliders=(col,)))
    e = errors(sk, tr, res).max(axis=1)
    assert e[:hit - 3].max() < 1.0 and e[hit:hit + 15].max() > 3.0
    assert not res.falling.any() and np.all(np.isfinite(res.trajectories.rotations))
    print("collider reaction max", e.max(), "at", np.argmax(e))
