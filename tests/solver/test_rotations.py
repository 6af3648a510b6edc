import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from humananim.solver import rotations

RNG = np.random.default_rng(7)


def scipy_quat(q_wxyz):
    return Rotation.from_quat(np.roll(q_wxyz, -1, axis=-1))


@pytest.mark.parametrize("order", rotations.EULER_ORDERS)
def test_euler_matches_blender_convention(order):
    # Blender's order names the first axis applied first: extrinsic rotations in that order
    angles = RNG.uniform(-np.pi, np.pi, (200, 3))
    q = rotations.from_euler(angles, order)
    seq = order.lower()
    ref = Rotation.from_euler(seq, angles[:, ["XYZ".index(a) for a in order]])
    assert np.allclose(rotations.to_matrix(q), ref.as_matrix(), atol=1e-12)


@pytest.mark.parametrize("order", rotations.EULER_ORDERS)
def test_euler_round_trip_including_gimbal_lock(order):
    angles = RNG.uniform(-np.pi, np.pi, (300, 3))
    angles[:20, "XYZ".index(order[1])] = np.pi / 2  # the middle axis at +-90 degrees
    angles[20:40, "XYZ".index(order[1])] = -np.pi / 2
    q = rotations.from_euler(angles, order)
    back = rotations.from_euler(rotations.to_euler(q, order), order)
    assert np.allclose(rotations.angle_between(q, back), 0.0, atol=1e-6)


def test_matrix_quaternion_round_trip_and_hemisphere():
    q = rotations.normalize(RNG.normal(size=(500, 4)))
    back = rotations.from_matrix(rotations.to_matrix(q))
    assert np.all(back[:, 0] >= 0)
    assert np.allclose(np.abs((q * back).sum(-1)), 1.0, atol=1e-12)


def test_multiply_composes_like_matrices():
    a, b = rotations.normalize(RNG.normal(size=(2, 50, 4)))
    assert np.allclose(rotations.to_matrix(rotations.multiply(a, b)),
                       rotations.to_matrix(a) @ rotations.to_matrix(b), atol=1e-12)


def test_axis_angle_round_trip_and_zero_axis():
    q = rotations.normalize(RNG.normal(size=(100, 4)))
    aa = rotations.to_axis_angle(q)
    assert np.allclose(rotations.angle_between(rotations.from_axis_angle(aa), q), 0, atol=1e-9)
    assert np.allclose(rotations.from_axis_angle([0.3, 0, 0, 0]), [1, 0, 0, 0])


def test_unrolled_euler_is_continuous():
    t = np.linspace(0, 4 * np.pi, 400)
    angles = np.column_stack((t, 0.3 * np.sin(t), np.zeros_like(t)))
    wrapped = rotations.to_euler(rotations.from_euler(angles, "ZYX"), "ZYX")
    unrolled = rotations.unroll_euler(wrapped, "ZYX")
    assert np.abs(np.diff(unrolled, axis=0)).max() < 0.1
    assert np.allclose(unrolled, angles, atol=1e-9)


def test_make_continuous_flips_to_previous_hemisphere():
    t = np.linspace(0, 3, 50)[:, None]
    q = rotations.normalize(np.column_stack((np.cos(t), np.sin(t), 0.2 * t, 0 * t)))
    q[1::2] *= -1
    smooth = rotations.make_continuous(q)
    assert np.all((smooth[1:] * smooth[:-1]).sum(-1) > 0)
    assert np.allclose(rotations.angle_between(smooth, q), 0, atol=1e-7)
