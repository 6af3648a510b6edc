import numpy as np
import pytest

import sequence_data as data
from humananim.solver.sequence import channels, error_measures, key_reduction as kr

RNG = np.random.default_rng(11)


def cmu_blender_like(name="cmu_131_01.bvh", frames=slice(None)):
    """Unrolled Euler channels in radians and the root location in metres, with their kinds."""
    bvh = data.load(name)
    euler, orders = data.euler(bvh)
    euler = channels.unroll_euler(euler[frames], orders)
    x = np.concatenate((data.root_position(bvh)[frames], euler.reshape(len(euler), -1)), axis=1)
    kinds = np.array(["location"] * 3 + ["rotation"] * (x.shape[1] - 3))
    return x, kinds


def test_bezier_with_third_handles_is_the_hermite_cubic():
    for _ in range(50):
        t0, t1 = np.sort(RNG.uniform(-5, 5, 2))
        p0, p1, m0, m1 = RNG.normal(size=4) * [1, 1, 5, 5]
        d = t1 - t0
        keys = kr.Keys(np.array([t0, t1]), np.array([p0, p1]),
                       np.array([[t0 - d / 3, p0 - m0 * d / 3], [t1 - d / 3, p1 - m1 * d / 3]]),
                       np.array([[t0 + d / 3, p0 + m0 * d / 3], [t1 + d / 3, p1 + m1 * d / 3]]),
                       np.array(["BEZIER", "BEZIER"], dtype=object))
        t = np.linspace(t0, t1, 41)
        # the general 2-D Bezier evaluator (solves x(s) = t numerically) against the cubic
        assert np.abs(kr.evaluate(keys, t) - kr.hermite(t, t0, t1, p0, p1, m0, m1)).max() < 1e-9


def test_bezier_evaluator_is_a_true_2d_bezier():
    # handles not at one third: the curve is not a cubic in time, check a point by its parameter
    keys = kr.Keys(np.array([0.0, 3.0]), np.array([0.0, 1.0]), np.array([[-1, 0], [2.5, 1.0]]),
                   np.array([[0.2, 0.9], [4, 1]]), np.array(["BEZIER", "BEZIER"], dtype=object))
    s = 0.3
    u = 1 - s
    x = 3 * u * u * s * 0.2 + 3 * u * s * s * 2.5 + s ** 3 * 3.0
    y = 3 * u * u * s * 0.9 + 3 * u * s * s * 1.0 + s ** 3 * 1.0
    assert kr.evaluate(keys, np.array([x]))[0] == pytest.approx(y, abs=1e-10)


def test_straight_and_constant_curves_become_two_linear_keys():
    t = np.arange(200, dtype=float)
    for y in (0.3 * t - 2.0, np.full_like(t, 4.0)):
        keys = kr.reduce_keys(t, y, 1e-6)
        assert len(keys) == 2 and keys.interpolation[0] == "LINEAR"
        assert np.abs(kr.evaluate(keys, t) - y).max() < 1e-9


def test_linear_runs_are_kept_as_linear_segments():
    t = np.arange(300, dtype=float)
    y = np.where(t < 150, 0.01 * t, 1.5 + np.sin((t - 150) / 20.0))
    keys = kr.reduce_keys(t, y, 1e-3)
    assert keys.interpolation[0] == "LINEAR" and keys.times[1] >= 140
    assert np.abs(kr.evaluate(keys, t) - y).max() <= 1e-3


@pytest.mark.parametrize("tangents", ["fitted", "samples"])
@pytest.mark.parametrize("search", ["greedy", "recursive"])
def test_every_method_meets_the_tolerance_on_every_frame(tangents, search):
    x, kinds = cmu_blender_like(frames=slice(200, 500))
    t = np.arange(len(x), dtype=float)
    tol = channels.channel_tolerances(kinds, degrees=0.5, centimetres=0.5)
    keys = kr.reduce_channels(t, x, tol, tangents=tangents, search=search)
    got = kr.evaluate_channels(keys, t)
    assert np.all(np.abs(got - x).max(axis=0) <= tol * (1 + 1e-9))
    # the emitted Bezier keys are the Hermite segments exactly, also between frames
    tt = np.linspace(0, len(x) - 1, 1777)
    for k in keys[::7]:
        assert np.abs(kr.evaluate(k, tt) - kr.evaluate_hermite(k, tt)).max() < 1e-9
    assert sum(len(k) for k in keys) < 0.5 * x.size


@pytest.mark.parametrize("clip", data.CLIPS)
def test_cmu_compression_meets_degrees_and_centimetres(clip):
    x, kinds = cmu_blender_like(clip)
    t = np.arange(len(x), dtype=float)
    tol = channels.channel_tolerances(kinds, degrees=1.0, centimetres=1.0)
    keys = kr.reduce_channels(t, x, tol)
    err = error_measures.channel_errors(kr.evaluate_channels(keys, t), x, kinds)
    assert err[kinds == "rotation"].max() <= 1.0 + 1e-9
    assert err[kinds == "location"].max() <= 1.0 + 1e-9
    n = sum(len(k) for k in keys)
    assert n < 0.1 * x.size  # real noise, yet fewer than one key in ten


def test_simpson_criterion_alone_bounds_the_mean_error():
    t = np.arange(400, dtype=float)
    y = np.sin(t / 15.0) + RNG.normal(scale=0.01, size=t.shape)
    keys = kr.reduce_keys(t, y, 0.02, max_error=None)
    e = np.abs(kr.evaluate(keys, t) - y)
    assert e.mean() <= 0.02 * 1.05
    assert len(keys) < len(kr.reduce_keys(t, y, 0.02))  # weaker than the per-frame bound


def test_compressed_skeleton_motion_meets_its_tolerance_on_every_bone():
    skeleton, traj = data.skeleton_and_motion(frames=slice(0, 600))
    x, layout = channels.pack(traj)
    degrees, centimetres = 0.5, 0.5
    tol = channels.channel_tolerances(layout.kinds, degrees, centimetres, per_joint=True)
    t = traj.frames
    keys = kr.reduce_channels(t, x, tol)
    back = channels.unpack(kr.evaluate_channels(keys, t), layout, traj)
    assert np.allclose(np.linalg.norm(back.rotations, axis=-1), 1.0, atol=1e-12)
    assert error_measures.rotation_error_deg(back.rotations, traj.rotations).max() <= degrees * (1 + 1e-9)
    assert error_measures.location_error_cm(back.translations, traj.translations).max() <= centimetres * (1 + 1e-9)
    err = error_measures.tail_error(skeleton, traj, back)
    # each joint's error moves a point by at most angle x distance: bound along the longest chain
    world = traj.world_frames(skeleton)
    reach = np.linalg.norm(world[:, :, None, :3, 3] - world[:, None, :, :3, 3], axis=-1).max()
    bound = centimetres / 100 + len(skeleton.names) * np.radians(degrees) * (reach + 0.1)
    assert 0.0 < err.tail <= err.point <= bound
    assert err.tail_cm < 5.0


def test_fit_to_error_scales_the_tolerance_until_the_target_holds():
    from humananim.solver.sequence.key_reduction import fit_to_error
    t = np.linspace(0.0, 4.0, 401)
    x = np.column_stack((np.sin(3 * t), np.cos(5 * t)))
    reduce = lambda scale: kr.reduce_channels(t, x, np.array([0.05, 0.05]) * scale)
    measure = lambda keys: float(np.abs(kr.evaluate_channels(keys, t) - x).max())
    keys, scale, error = fit_to_error(reduce, measure, 0.01)
    assert error <= 0.01 and 0.0 < scale < 1.0 and error == measure(keys)
    assert fit_to_error(reduce, measure, 1.0)[1] == 1.0  # met at once: no bisection


def test_scale_to_error_finds_the_scale_on_the_errors_in_fewer_reductions():
    """The scale searched on the measured errors (secant through the origin) meets the target as
    the halving does, as close to it (within its window or the halving's 1/32), in fewer
    reductions: a combination of channel errors, as a planted foot's or a tail's is."""
    from humananim.solver.sequence.key_reduction import fit_to_error, scale_to_error
    t = np.linspace(0.0, 4.0, 401)
    x = np.column_stack((np.sin(3 * t), np.cos(5 * t), 0.3 * np.sin(11 * t + 1.0)))
    calls = {"halving": [], "errors": []}

    def reduce_for(name):
        def reduce(scale):
            calls[name].append(scale)
            return kr.reduce_channels(t, x, np.array([0.05, 0.05, 0.02]) * scale)
        return reduce

    def measure(keys):  # a weighted sum of the channels' errors, its largest over the frames
        return float(np.abs((kr.evaluate_channels(keys, t) - x) @ np.array([1.0, 0.7, 2.0])).max())
    for target in (0.01, 0.03, 0.06):
        calls["halving"].clear(), calls["errors"].clear()
        _, s_half, e_half = fit_to_error(reduce_for("halving"), measure, target, steps=5)
        keys, scale, error = scale_to_error(reduce_for("errors"), measure, target, tries=5)
        assert error <= target and error == measure(keys) and 0.0 < scale < 1.0
        assert error >= 0.85 * target or scale >= s_half - 1.0 / 32.0, (target, scale, s_half, error, e_half)
        assert len(calls["errors"]) < len(calls["halving"]), calls
    keys, scale, error = scale_to_error(reduce_for("errors"), measure, 10.0)
    assert scale == 1.0 and error <= 10.0  # met at once: one reduction
