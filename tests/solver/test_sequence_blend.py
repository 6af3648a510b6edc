import numpy as np
import pytest

import sequence_data as data
from humananim.solver import rotations
from humananim.solver.sequence import channels, multiresolution_blend as mb


def cmu(name, frames):
    bvh = data.load(name)
    euler, orders = data.euler(bvh)
    e = np.degrees(channels.unroll_euler(euler, orders))[frames]
    return np.concatenate((100 * data.root_position(bvh)[frames], e.reshape(len(e), -1)), axis=1)


def test_weights_for_overlap_and_inside_cases():
    w = mb.blend_weights(100, 60, 100)
    assert len(w) == 160 and np.all(w[:61] == 1.0) and np.all(w[99:] == 0.0)
    assert np.all(np.diff(w) <= 0.0)
    w = mb.blend_weights(200, 50, 61)  # B inside A: 1 at its ends, 0 at its middle
    assert len(w) == 200 and w[50] == 1.0 and w[80] == 0.0 and w[110] == 1.0
    assert np.all(w[:50] == 1.0) and np.all(w[110:] == 1.0)
    with pytest.raises(ValueError):
        mb.blend_weights(100, 120, 50)


def test_identical_sequences_blend_to_themselves():
    x = cmu("cmu_131_01.bvh", slice(0, 400))
    for fn in (mb.multiresolution_blend, mb.weighted_sum_blend):
        assert np.abs(fn(x, x, 0) - x).max() < 1e-9
        assert np.abs(fn(x, x, 0, transition=(100, 120)) - x).max() < 1e-9
    # B starting later: the plain sum is exact, the bands of B near its start see its extension
    assert np.abs(mb.weighted_sum_blend(x, x[150:], 150) - x).max() < 1e-9


def test_blend_keeps_each_sequence_away_from_the_transition():
    a = cmu("cmu_131_01.bvh", slice(0, 500))
    b = cmu("cmu_131_03.bvh", slice(300, 800))
    out = mb.multiresolution_blend(a, b, 400, levels=4)
    assert out.shape == (900, a.shape[1])
    reach = 2 ** 4 * 3  # an EXPAND cascade spreads a level-4 change over a few coarse samples
    assert np.abs(out[:400 - reach] - a[:400 - reach]).max() < 1e-9
    assert np.abs(out[499 + reach:] - b[99 + reach:]).max() < 1e-9


def packed(name, frames):
    """Rotation vectors (degrees) about a common reference and locations (cm) of a CMU clip."""
    _, traj = data.skeleton_and_motion(name, frames=frames)
    return traj


@pytest.mark.parametrize("mask", ["window", "gaussian"])
def test_blending_is_continuous_on_cmu(mask):
    ta = packed("cmu_131_01.bvh", slice(0, 500))
    tb = packed("cmu_131_03.bvh", slice(500, 1000))
    ref = channels.mean_quaternion(np.concatenate((ta.rotations, tb.rotations)))
    a = np.degrees(channels.to_tangent(ta.rotations, ref)).reshape(500, -1)
    b = np.degrees(channels.to_tangent(tb.rotations, ref)).reshape(500, -1)
    steady = (np.abs(np.diff(a, axis=0)).max(0) < 30) & (np.abs(np.diff(b, axis=0)).max(0) < 30)
    a, b = a[:, steady], b[:, steady]  # leave out the capture's glitches (a thumb flips 180 degrees)
    # a short transition (0.1 s) between two different motions
    multi = mb.multiresolution_blend(a, b, 450, transition=(450, 462), mask=mask)
    plain = mb.weighted_sum_blend(a, b, 450, transition=(450, 462))
    step = lambda x: np.abs(np.diff(x, axis=0))
    own = np.maximum(step(a).max(axis=0), step(b).max(axis=0))
    zone = slice(400, 520)
    jump = np.abs(a[450:463] - b[:13]).max(axis=0)  # what the blend must bridge
    # no jump: frame-to-frame steps stay within the inputs' own steps plus the gap spread over the window
    assert np.all(step(multi[zone]).max(axis=0) <= own + jump / 4 + 1e-9)
    # and the multiresolution blend is smoother there than the plain weighted sum
    accel = lambda x: np.abs(np.diff(x, 2, axis=0))[zone].max(axis=0)
    assert np.median(accel(multi) / np.maximum(accel(plain), 1e-12)) < 1.0


def test_quaternion_blend_stays_unit_and_on_one_hemisphere():
    _, ta = data.skeleton_and_motion("cmu_131_01.bvh", frames=slice(0, 300))
    _, tb = data.skeleton_and_motion("cmu_131_03.bvh", frames=slice(0, 300))
    qb = -tb.rotations  # the other hemisphere: the same rotations
    for method in ("multiresolution", "weighted_sum"):
        kw = {"levels": 4} if method == "multiresolution" else {}  # reach: 3 x 2^4 frames
        q = mb.blend_quaternions(ta.rotations, qb, 200, method=method, **kw)
        assert q.shape == (500,) + ta.rotations.shape[1:]
        assert np.allclose(np.linalg.norm(q, axis=-1), 1.0, atol=1e-12)
        steady = np.all((ta.rotations[1:] * ta.rotations[:-1]).sum(-1) > 0.7, axis=0)
        steady &= np.all((tb.rotations[1:] * tb.rotations[:-1]).sum(-1) > 0.7, axis=0)
        assert np.all((q[1:] * q[:-1]).sum(-1)[:, steady] > 0.0)  # a thumb flips 180 degrees in the capture
        assert np.all((q[0] * ta.rotations[0]).sum(-1) > 0.0)
        assert np.degrees(rotations.angle_between(q[:150], ta.rotations[:150])).max() < 1.0
        assert np.degrees(rotations.angle_between(q[350:], tb.rotations[150:])).max() < 1.0


def test_euler_blend_moves_b_onto_a_branch():
    a = np.zeros((100, 1, 3))
    b = np.zeros((100, 1, 3))
    b[..., 2] = 2 * np.pi + 0.1  # the same as 0.1 rad
    out = mb.blend_euler(a, b, 50, orders="XYZ")
    assert np.abs(out[..., 2]).max() <= 0.1 + 1e-12


def test_a_sequence_inside_another_blends_in_and_out_continuously():
    """B (a 1 s hop) played inside A (a walk): A until B starts, B in its middle, A again after.
    Measured with 4 levels: B's middle within a few degrees of B (A and B differ by 95 there),
    A untouched beyond the bands' reach, no jump in or out."""
    ta = packed("cmu_131_01.bvh", slice(0, 480))
    tb = packed("cmu_131_03.bvh", slice(600, 720))
    ref = channels.mean_quaternion(np.concatenate((ta.rotations, tb.rotations)))
    a = np.degrees(channels.to_tangent(ta.rotations, ref)).reshape(480, -1)
    b = np.degrees(channels.to_tangent(tb.rotations, ref)).reshape(120, -1)
    steady = (np.abs(np.diff(a, axis=0)).max(0) < 30) & (np.abs(np.diff(b, axis=0)).max(0) < 30)
    a, b = a[:, steady], b[:, steady]
    levels, reach = 4, 3 * 2 ** 4
    out = mb.multiresolution_blend(a, b, 200, levels=levels)
    assert out.shape == a.shape
    assert np.abs(a[260] - b[60]).max() > 50.0  # the two motions really differ there
    assert np.abs(out[260] - b[60]).max() < 10.0  # B's middle plays B
    assert np.abs(out[:200 - reach] - a[:200 - reach]).max() < 1e-9
    assert np.abs(out[320 + reach:] - a[320 + reach:]).max() < 1e-9
    step = lambda x: np.abs(np.diff(x, axis=0))
    own = np.maximum(step(a).max(axis=0), step(b).max(axis=0))
    jump = np.maximum(np.abs(a[200] - b[0]), np.abs(a[319] - b[-1]))
    assert np.all(step(out[150:370]).max(axis=0) <= own + jump / 4 + 1e-9)  # in and out without a jump
