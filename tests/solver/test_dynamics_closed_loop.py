"""Huang's closed-loop simulation: ragdoll, tracking, strength clamp, pushes and loads."""

import numpy as np
import pytest

from humananim.solver import rotations
from humananim.solver.dynamics import (GroundModel, Push, Settings, build_model, default_contacts,
                                       joint_frames, oshita_figure, point_positions, rnea, simulate)
from humananim.solver.trajectories import Trajectories

FPS = 60.0


def motion(seconds=1.0, swing=True):
    """The figure standing on z = 0, swinging its arms, bending its trunk and turning its head."""
    sk = oshita_figure()
    n = int(seconds * FPS)
    t = np.arange(n) / FPS
    rot = np.zeros((n, sk.joint_count, 4))
    rot[..., 0] = 1.0

    def turn(name, axis, angle):
        j = sk.index(name)
        rot[:, j] = rotations.multiply(rotations.axis_rotation(axis, angle), rot[:, j])

    if swing:
        turn("upper_arm.L", 0, 0.9 * np.sin(2 * np.pi * 0.8 * t))
        turn("upper_arm.R", 0, -0.9 * np.sin(2 * np.pi * 0.8 * t))
        turn("forearm.L", 0, -0.6 - 0.4 * np.sin(2 * np.pi * 1.1 * t))  # elbow flexion is -X
        turn("spine", 0, 0.25 * np.sin(2 * np.pi * 0.5 * t))
        turn("head", 2, 0.4 * np.sin(2 * np.pi * 0.7 * t))
    return sk, Trajectories(np.arange(n) + 1, FPS, rot, np.zeros((n, sk.joint_count, 3)), np.eye(4))


def errors(sk, result, tr):
    rot = rotations.angle_between(result.trajectories.rotations, tr.rotations)
    root = np.linalg.norm(result.trajectories.root_pose(sk)[0] - tr.root_pose(sk)[0], axis=1)
    return rot, root


@pytest.fixture(scope="module")
def tracked():
    sk, tr = motion()
    return sk, tr, simulate(sk, tr, Settings(tracking=1.0, root_support=1.0))


def test_full_tracking_reproduces_the_motion(tracked):
    """Stated accuracy: joints within 0.05 rad (mean 0.01), root within 5 mm, at 60 fps input."""
    sk, tr, res = tracked
    rot, root = errors(sk, res, tr)
    assert rot.max() < 0.05 and rot.mean() < 0.01
    assert root.max() < 0.005
    assert res.torques.shape == (tr.frame_count, 39) and len(res.dof_names) == 39
    assert np.abs(res.torques).max() > 1.0  # the arms really are driven


def test_strength_clamp_is_respected(tracked):
    sk, tr, full = tracked
    weak = simulate(sk, tr, Settings(tracking=1.0, root_support=1.0, strength_scale=0.03))
    low, high = weak.available[..., 0], weak.available[..., 1]
    assert np.all(weak.torques <= high + 1e-9) and np.all(weak.torques >= low - 1e-9)
    assert weak.usage.max() > 1.0  # the clamp acted
    assert errors(sk, weak, tr)[0].max() > 3 * errors(sk, full, tr)[0].max()


def test_ragdoll_falls_and_rests_on_the_ground():
    sk, tr = motion(seconds=2.5, swing=False)
    res = simulate(sk, tr, Settings(tracking=0.0))
    pos, _ = res.trajectories.root_pose(sk)
    assert np.all(np.isfinite(pos))
    assert pos[0, 2] == pytest.approx(0.95) and pos[-1, 2] < 0.3  # it fell
    speed = np.linalg.norm(np.diff(pos[-15:], axis=0), axis=1) * FPS
    assert speed.max() < 0.05  # and came to rest
    # never sinks: contact spheres enter the penalty ground less than 5 cm on impact, 1 cm at rest
    model = build_model(sk)
    data = model.create_data()
    contacts = default_contacts(model)
    from humananim.solver.dynamics import desired_motion
    qs = desired_motion(model, sk, res.trajectories)[0]
    lowest = np.array([(point_positions(model, data, q, contacts.joints, contacts.points)[:, 2]
                        - contacts.radii).min() for q in qs])
    assert lowest.min() > -0.05 and lowest[-10:].min() > -0.01
    assert res.contact_force[-1, 2] == pytest.approx(72.0 * 9.81, rel=0.05)  # resting weight


def test_push_deflects_and_the_loop_recovers(tracked):
    sk, tr, calm = tracked
    push = Push(time=0.3, joint="chest", point=(0.0, 0.15, 0.0), direction=(0, 1, 0), magnitude=400.0,
                duration=0.1)
    res = simulate(sk, tr, Settings(tracking=1.0, root_support=1.0, pushes=(push,)))
    chest = sk.index("chest")
    dev = rotations.angle_between(res.trajectories.rotations[:, chest], tr.rotations[:, chest])
    calm_dev = rotations.angle_between(calm.trajectories.rotations[:, chest], tr.rotations[:, chest])
    hit = int(0.45 * FPS)
    assert dev[hit - 3:hit + 6].max() > 5 * calm_dev.max() + 0.01
    assert dev[-5:].max() < 0.5 * dev.max()  # the feedback brings it back


def test_loads_in_the_hands():
    """10 kg in a hand held with the elbow at 90 degrees: the elbow torque holds its weight."""
    sk = oshita_figure()
    base = build_model(sk)
    loaded = build_model(sk, loads={"hand.L": 10.0})
    q = base.neutral()
    forearm = sk.index("forearm.L")
    i = base.dof_names.index("forearm.L.x")
    q[base.q_index[base.joint_body[forearm]]:][:4] = rotations.axis_rotation(0, np.pi / 2)
    z = np.zeros(base.nv)
    extra = rnea(loaded, loaded.create_data(), q, z, z) - rnea(base, base.create_data(), q, z, z)
    hand = sk.index("hand.L")
    grip = point_positions(base, base.create_data(), q, [hand], [sk.com[hand]])[0]
    frame = joint_frames(base, base.create_data(), q)[forearm]
    moment = np.cross(grip - frame[:3, 3], (0.0, 0.0, -10.0 * 9.81))  # the load's weight about the elbow
    assert np.linalg.norm(grip - frame[:3, 3]) > 0.1
    assert -extra[i] == pytest.approx(moment @ frame[:3, 0], rel=1e-9)  # the muscles hold it


def test_pd_servo_and_ground_settings(tracked):
    sk, tr, _ = tracked
    res = simulate(sk, tr, Settings(controller="pd", tracking=1.0, root_support=1.0,
                                    ground=GroundModel(height=-0.01)))
    rot, root = errors(sk, res, tr)
    assert rot.max() < 0.4 and root.max() < 0.02


def test_a_made_up_tail_is_lumped_into_its_parent():
    """A leaf whose tail the file never gave (Blender copies the parent's vector onto an End Site
    at zero offset, or leaves it a millimetre) has no segment of its own: its mass goes to its
    head in the parent, it carries no contact point, and the body keeps its mass; a leaf of its
    own length (the figure's hands, feet and head) is kept."""
    from dataclasses import replace
    from humananim.solver.dynamics.closed_loop import lump_made_up_tails, made_up_tails
    sk = oshita_figure()
    assert not made_up_tails(sk).any()
    assert lump_made_up_tails(sk) is sk
    hand, forearm = sk.index("hand.L"), sk.index("forearm.L")
    rest, lengths = sk.rest.copy(), np.asarray(sk.lengths, float).copy()
    rest[hand, :3, :3] = rest[forearm, :3, :3]  # the forearm's vector from the wrist
    lengths[hand] = lengths[forearm]
    copied = replace(sk, rest=rest, lengths=lengths)
    short = replace(sk, lengths=np.where(np.arange(sk.joint_count) == sk.index("hand.R"), 1e-3, lengths))
    assert np.flatnonzero(made_up_tails(copied)).tolist() == [hand]
    assert np.flatnonzero(made_up_tails(short)).tolist() == [sk.index("hand.R")]
    lumped = lump_made_up_tails(copied)
    assert lumped.mass[hand] == 0.0 and lumped.lengths[hand] == 0.0
    assert lumped.mass.sum() == pytest.approx(sk.mass.sum())
    assert lumped.mass[forearm] == pytest.approx(sk.mass[forearm] + sk.mass[hand])
    # the lumped centre of mass lies between the forearm's and the wrist (the hand's head)
    wrist_y = (np.linalg.inv(rest[forearm]) @ rest[hand])[1, 3]
    assert sk.com[forearm][1] < lumped.com[forearm][1] < wrist_y
    model = build_model(lumped)
    assert model.joint_kind[hand] == "kinematic"
    contacts = default_contacts(model)
    assert hand not in contacts.joints.tolist()
    sk2, tr = motion(0.3)
    result = simulate(copied, tr)
    assert np.all(np.isfinite(result.trajectories.rotations))


def test_dynamic_control_lumps_a_made_up_tail_as_simulate_does():
    """Dynamic Control builds its body where Simulate does (closed_loop.simulated_skeleton): a
    leaf whose tail the file never gave is lumped into its parent there too, so controlling the
    skeleton as read gives the motion of controlling it lumped (same mass model, and the leaf
    follows the source instead of spinning on a lever the file never gave)."""
    from dataclasses import replace
    from humananim.solver.dynamics.closed_loop import lump_made_up_tails, simulated_skeleton
    from humananim.solver.motion_control import ControlSettings, control
    sk, tr = motion(0.3)
    hand, forearm = sk.index("hand.L"), sk.index("forearm.L")
    rest, lengths = sk.rest.copy(), np.asarray(sk.lengths, float).copy()
    rest[hand, :3, :3] = rest[forearm, :3, :3]  # Blender's guess for an End Site at zero offset
    lengths[hand] = lengths[forearm]
    read = replace(sk, rest=rest, lengths=lengths)
    lumped = lump_made_up_tails(read)
    built = simulated_skeleton(read, tr, ControlSettings())
    assert np.array_equal(built.mass, lumped.mass) and np.array_equal(built.inertia, lumped.inertia)
    assert built.lengths[hand] == 0.0
    as_read = control(read, tr)
    as_lumped = control(lumped, tr)
    assert np.allclose(as_read.trajectories.rotations, as_lumped.trajectories.rotations, atol=1e-9)
    assert np.allclose(as_read.trajectories.translations, as_lumped.trajectories.translations, atol=1e-9)
    # the lumped hand turns with the source relative to its forearm: no spin of its own
    spin = rotations.angle_between(as_read.trajectories.rotations[:, hand], tr.rotations[:, hand])
    assert spin.max() < 1e-6
    kept = control(read, tr, ControlSettings(lump_made_up_tails=False))
    assert np.allclose(as_read.zmp, as_lumped.zmp, atol=1e-9, equal_nan=True)
    assert np.allclose(as_read.stress, as_lumped.stress, atol=1e-9)
    assert np.array_equal(as_read.model.spatial_inertia, as_lumped.model.spatial_inertia)
    assert as_read.model.joint_kind[hand] == "kinematic"
    # and the setting is what does it: not lumped, the copied tail is a segment of its own, and
    # its made-up mass distribution moves the ZMP
    assert kept.model.joint_kind[hand] != "kinematic"
    assert np.nanmax(np.linalg.norm(kept.zmp - as_lumped.zmp, axis=1)) > 5e-4
    # a made-up tail that carries a load keeps its segment (the load needs the hand's reach), in
    # both: Simulate's loads are {bone: kg}, Dynamic Control's Load tuples
    from humananim.solver.motion_control import Load
    for settings in (Settings(loads={"hand.L": 3.0}), ControlSettings(loads=(Load("hand.L", 3.0),))):
        loaded = simulated_skeleton(read, tr, settings)
        assert loaded.mass[hand] == read.mass[hand] and loaded.lengths[hand] == read.lengths[hand]
