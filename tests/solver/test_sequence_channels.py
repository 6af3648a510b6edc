import numpy as np
import pytest

import sequence_data as data
from humananim.solver import rotations
from humananim.solver.skeleton import Skeleton
from humananim.solver.trajectories import Trajectories
from humananim.solver.sequence import channels, equalizer, error_measures

RNG = np.random.default_rng(5)


def test_tangent_round_trip_and_unrolling_past_180_degrees():
    angle = np.linspace(0.0, 3 * np.pi, 400)  # a joint turning one and a half turns about z
    q = rotations.axis_rotation(2, angle)
    ref = np.array([1.0, 0.0, 0.0, 0.0])
    v = channels.to_tangent(rotations.make_continuous(q), ref)
    assert np.allclose(v[:, 2], angle)  # unrolled: continuous past pi
    back = channels.from_tangent(v, ref, like=q)
    assert np.abs(np.degrees(rotations.angle_between(back, q))).max() < 1e-9
    assert np.allclose(back, rotations.make_continuous(q))


def test_pack_unpack_trajectories_is_exact():
    _, traj = data.skeleton_and_motion(frames=slice(0, 300))
    x, layout = channels.pack(traj)
    assert x.shape == (300, 6 * len(layout.reference))
    back = channels.unpack(x, layout, traj)
    assert np.abs(back.rotations - traj.rotations).max() < 1e-12
    assert np.abs(back.translations - traj.translations).max() < 1e-12


def test_filtered_quaternions_stay_unit_and_on_their_hemisphere():
    _, traj = data.skeleton_and_motion(frames=slice(0, 500))
    q = traj.rotations
    levels = 6
    for gains in ([0.0, 0.0] + [1.0] * (levels - 1), [1.0, 1.0, 2.0, 2.0, 1.5, 1.0, 1.0]):
        out = equalizer.equalize_quaternions(q, gains, levels)
        assert np.allclose(np.linalg.norm(out, axis=-1), 1.0, atol=1e-12)
        assert np.all((out[0] * q[0]).sum(-1) > 0.0)
        steady = np.all((q[1:] * q[:-1]).sum(-1) > 0.7, axis=0)  # the capture's thumb flips
        assert np.all((out[1:] * out[:-1]).sum(-1)[:, steady] > 0.0)
    smooth = equalizer.equalize_quaternions(q, [0.0, 0.0] + [1.0] * (levels - 1), levels)
    assert np.median(error_measures.rotation_error_deg(smooth, q)) < 1.0  # jitter only


def test_euler_channels_are_unrolled_before_filtering():
    a = np.zeros((200, 1, 3))
    a[:, 0, 2] = np.linspace(0, 4 * np.pi, 200)
    wrapped = np.remainder(a + np.pi, 2 * np.pi) - np.pi
    out = equalizer.equalize_euler(wrapped, [0.0, 1.0, 1.0, 1.0, 1.0], "XYZ", levels=4)
    assert np.abs(out - a).max() < 1e-6


def chain():
    """Three bones of 0.5, 0.3 and 0.2 m stacked along world Y, rest frames along +Y."""
    rest = np.tile(np.eye(4), (3, 1, 1))
    rest[:, 1, 3] = [0.0, 0.5, 0.8]
    return Skeleton(names=("a", "b", "c"), parents=np.array([-1, 0, 1]), rest=rest,
                    lengths=np.array([0.5, 0.3, 0.2]), connected=np.ones(3, bool),
                    dof=np.ones((3, 3), bool), limits=np.tile([-np.inf, np.inf], (3, 3, 1)),
                    mass=np.ones(3), com=np.zeros((3, 3)), inertia=np.tile(np.eye(3), (3, 1, 1)))


def test_tail_error_of_a_hand_built_chain():
    sk = chain()
    F = 10
    q = np.tile([1.0, 0.0, 0.0, 0.0], (F, 3, 1))
    a = Trajectories(np.arange(F), 30.0, q, np.zeros((F, 3, 3)), np.eye(4))
    theta = np.radians(2.0)
    q2 = q.copy()
    q2[4, 0] = rotations.axis_rotation(2, theta)  # the root bends 2 degrees on frame 4
    b = Trajectories(np.arange(F), 30.0, q2, np.zeros((F, 3, 3)), np.eye(4))
    err = error_measures.tail_error(sk, a, b)
    assert err.tail == pytest.approx(2 * 1.0 * np.sin(theta / 2))  # the last tail, 1 m from the root
    assert err.point == pytest.approx(2 * 1.1 * np.sin(theta / 2))
    assert (err.tail_bone, err.tail_frame) == ("c", 4)
    assert err.point_cm == pytest.approx(100 * err.point)
    t2 = np.zeros((F, 3, 3))
    t2[7, 0] = [0.0, 0.0, 0.03]
    c = Trajectories(np.arange(F), 30.0, q, t2, np.eye(4))
    assert error_measures.tail_error(sk, a, c).tail_cm == pytest.approx(3.0)


def test_units_for_animators():
    assert error_measures.location_error_cm([0, 0, 0], [0.03, 0.04, 0]) == pytest.approx(5.0)
    assert error_measures.angle_error_deg(np.radians(359.0), 0.0) == pytest.approx(1.0)
    qa = rotations.axis_rotation(0, 0.0)
    qb = -rotations.axis_rotation(0, np.radians(3.0))
    assert error_measures.rotation_error_deg(qa, qb) == pytest.approx(3.0)
    tol = channels.channel_tolerances(np.array(["rotation", "location"]), degrees=2.0, centimetres=3.0)
    assert np.allclose(tol, [np.radians(2.0), 0.03])
