"""The cost of a bake does not depend on falls: a fallen body takes as many steps a frame as its
contact spheres' speed needs (none travels more than 1 cm a step), not fall_rate's 16 a frame
at 30 fps whatever it does; lying on the ground it takes one, as a standing body. Bandai's walk
knocked over by a 400 N s push sideways (falling on 134 of 195 frames): every step counted
(unit tests assert no time), the body kept out of the ground."""

import numpy as np

from humananim.solver.motion_control import Impulse, control
from humananim.solver.motion_control import controller as ctl
from humananim.solver.motion_control.controller import ControlSettings

from corpus_clips import load
from test_motion_control_ground import depth_below_ground


def test_a_fallen_body_takes_the_steps_its_speed_needs(monkeypatch):
    sk, tr = load("walk_normal_001")
    steps = []
    original = ctl.ControlLoop.step

    def counted(self, f, *args, **kw):
        steps.append(f)
        return original(self, f, *args, **kw)

    monkeypatch.setattr(ctl.ControlLoop, "step", counted)
    push = (Impulse(2.0, sk.roles.bone("chest"), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), 400.0),)
    res = control(sk, tr, ControlSettings(impulses=push))
    fallen = np.flatnonzero(res.falling)
    assert len(fallen) > 100
    per_frame = np.bincount(steps, minlength=tr.frame_count)
    # before: 16 steps in every falling frame (2,144 in all); lying still at the end: 1 a frame
    assert per_frame[fallen].sum() < 0.25 * 16 * len(fallen)
    assert np.all(per_frame[-20:] <= 2) and per_frame.max() <= 16
    assert depth_below_ground(sk, res.trajectories, res.ground_height).max() < 0.01
