"""The planted legs' predicted position re-solve (the default, ControlSettings.foot_iterations = 0,
feet.PlantedFeet.predicted_resolve): each planted foot's pose at the end of the step is predicted
from the frames at the step's start to second order (the velocity-product acceleration of the
integration's constant-velocity step, and the root's straight-line translation), so the re-solve
needs no forward kinematics at the integrated configuration. Its residual must be third order in
the step, and on the CMU clip it must keep the feet planted as the exact re-solve does."""

import numpy as np

from humananim.solver import rotations
from humananim.solver.dynamics import kinematics
from humananim.solver.motion_control import ControlSettings, control
from humananim.solver.motion_control import controller as ctl

from test_dynamics_closed_loop_rigs import load


def feet_poses(body, q):
    m = body.model
    d = m.create_data()
    kinematics.update_frames(m, d, q)
    return [d.frames[b] @ off for b, off in zip(body.foot_body, body.foot_offset)]


def test_the_prediction_is_second_order():
    """With targets at the feet's true poses after the step, the predicted correction is the
    prediction's own error: it falls by ~8 when the step halves (third-order residual)."""
    sk, tr = load("cmu_131_01", frames=60)
    loop = ctl.ControlLoop(sk, tr, ControlSettings(foot_iterations=0))
    for f in range(40):
        loop.frame(f)
    body, q = loop.body, loop.q
    rng = np.random.default_rng(3)
    v = loop.v + rng.normal(0.0, 1.0, loop.v.shape)  # joints turning ~1-3 rad/s
    feet = np.array([True, True])
    sizes = []
    for dt in (1.0 / 120.0, 0.5 / 120.0):
        after = feet_poses(body, kinematics.integrate(body.model, q, v * dt))
        targets = [(p[:3, :3], p[:3, 3].copy(), None, None) for p in after]
        loop.t = (40 + 0.25) * loop.dt_frame  # within the frame: no foot lifts at the step's end
        step = loop.feet.predicted_resolve(body, q, v, feet, targets, dt)
        assert step is not None
        sizes.append(np.abs(step).max())
    assert sizes[0] < 1e-4 and 6.0 < sizes[0] / sizes[1] < 10.0, sizes


def test_the_predicted_resolve_keeps_the_cmu_feet_planted():
    """As test_motion_control_controller.test_1_no_input_tracks_cmu with the predicted re-solve:
    it serves nearly every step (violent steps re-solve after the step), the
    feet land within micrometres of their targets, and they do not slide (under 2 mm)."""
    sk, tr = load("cmu_131_01")
    settings = ControlSettings(foot_iterations=0)
    loop = ctl.ControlLoop(sk, tr, settings)
    exact = [0]
    project = loop.feet.project_position

    def counted(*args):
        exact[0] += 1
        return project(*args)

    loop.feet.project_position = counted
    errors = []
    for f in range(loop.tr.frame_count):
        loop.frame(f)
        planted = [p is not None for p in loop.feet.planted]
        if f + 1 < loop.tr.frame_count and any(planted):  # the feet against their targets after the step
            targets = loop.feet.targets_at(loop.body, planted, loop.t)
            for s, pose in enumerate(feet_poses(loop.body, loop.q)):
                if targets[s] is not None:
                    errors.append(np.linalg.norm(pose[:3, 3] - targets[s][1]))
    res = loop.result()
    assert exact[0] < 0.05 * (loop.tr.frame_count - 1)  # measured 3 of 199
    assert np.median(errors) < 1e-5  # measured 0.4 um
    assert res.foot_slide.max() < 0.002 and not res.falling.any()  # measured 1.14 mm
    e = np.degrees(rotations.angle_between(res.trajectories.rotations, tr.rotations))
    reference = control(sk, tr, ControlSettings(foot_iterations=1))  # the exact re-solve
    e0 = np.degrees(rotations.angle_between(reference.trajectories.rotations, tr.rotations))
    tracked = sk.mass > 0
    assert abs(np.sqrt(np.mean(e[:, tracked] ** 2)) - np.sqrt(np.mean(e0[:, tracked] ** 2))) < 0.05
