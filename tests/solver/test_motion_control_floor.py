"""The default ground of Dynamic Control and Simulate (contacts.contact_floor) is where the soles
rest, a robust statistic of the contact frames: one foot dipping through a capture's floor for a
few frames, or a made-up bone tail reaching below it, does not lower it. Taking the lowest point
any contact sphere reaches (closed_loop.motion_floor) lifted every sole off that ground, so no foot
was found supporting the body and none was held in place. Real clips of the Bandai Namco corpus."""

from dataclasses import replace

import numpy as np
import pytest

from humananim.solver import rotations
from humananim.solver.dynamics import motion_floor
from humananim.solver.motion_control import control
from humananim.solver.motion_control.contacts import contact_floor, foot_point_tracks, support_intervals
from humananim.solver.motion_control.controller import ControlSettings

from corpus_clips import load

CLIPS = ("walk_normal_001", "bow_normal_001", "guide_normal_001", "kick_normal_001")


def dipped(skeleton, traj, degrees=60.0):
    """The clip with the left foot turned 60 deg about its bone's Z for three frames while it stands
    (around its lowest frame): its sole dips 3-6 cm through the floor (a bad solve, as captures
    have)."""
    lowest = int(np.argmin(foot_point_tracks(skeleton, traj, 0.0)[0]["L"].min(axis=1)))
    frames = np.clip(lowest + np.arange(-1, 2), 0, traj.frame_count - 1)
    rot = traj.rotations.copy()
    j = skeleton.index(skeleton.roles.bone("foot.L"))
    rot[list(frames), j] = rotations.multiply(rot[list(frames), j],
                                              rotations.axis_rotation(2, np.radians(degrees)))
    return replace(traj, rotations=rot)


@pytest.mark.parametrize("clip", CLIPS)
def test_a_dip_of_three_frames_does_not_move_the_floor(clip):
    sk, tr = load(clip)
    bad = dipped(sk, tr)
    assert motion_floor(sk, bad) < motion_floor(sk, tr) - 0.02  # the dip reaches well below
    assert abs(contact_floor(sk, bad) - contact_floor(sk, tr)) < 0.005


@pytest.mark.parametrize("clip", CLIPS)
def test_the_soles_rest_on_the_floor(clip):
    """Whatever the clip, some sole is within 2 cm of the floor in most frames where a foot is slow."""
    sk, tr = load(clip)
    heights, speeds = foot_point_tracks(sk, tr, contact_floor(sk, tr))
    low = np.min([h.min(axis=1) for h in heights.values()], axis=0)
    slow = np.any([s.min(axis=1) < 0.4 for s in speeds.values()], axis=0)
    assert np.mean(np.abs(low[slow]) < 0.02) > 0.6


def test_a_made_up_hand_tail_below_the_feet_is_not_the_floor():
    """The dance clip's right hand reaches down; Blender's importer continues the zero-length hand
    bone 22 cm along the forearm, and that made-up tip goes 10 cm below the soles. Feet are found
    on the floor all the same."""
    sk, tr = load("dance-short_normal_001")
    old, new = motion_floor(sk, tr), contact_floor(sk, tr)
    assert new - old > 0.08
    support = support_intervals(sk, tr, floor=new)
    assert not any(v.any() for v in support_intervals(sk, tr, floor=old).values())
    assert np.mean(support["L"] | support["R"]) > 0.5


def test_control_holds_the_feet_of_a_clip_with_a_dip():
    """With the default ground the controller plants the feet of the dipped walk as of the clean
    one (with the lowest point as ground it found them on the ground in 1 % of the frames)."""
    sk, tr = load("walk_normal_001")
    clean = control(sk, tr, ControlSettings())
    bad = control(sk, dipped(sk, tr), ControlSettings())
    assert abs(bad.ground_height - clean.ground_height) < 0.005
    assert clean.support.mean() > 0.5
    assert abs(bad.support.mean() - clean.support.mean()) < 0.03
