"""Pose control and motion synthesis of flexible characters (Faloutsos 1995, ch. 5)."""

import numpy as np
import pytest

from humananim.solver.flexible import FlexibleError, Ground, ModeGains, Settings, Simulator
from humananim.solver.flexible.control import (HIGH_COST, AnnealSettings, CostSpec, anneal, cost_of,
                                               motion_measures, neighbour)
from humananim.solver.flexible.demo import table_body
from humananim.solver.flexible.simulate import Controller, Result, State
from humananim.solver.progress import run_to_end


def pd_gains(body, active, hertz=4.0, ratio=0.8):
    m = body.modal_masses()[active]
    w = 2 * np.pi * hertz
    return m * w * w, 2 * ratio * w * m


def test_pose_graph_cycles_through_its_poses():
    ctl = Controller([0, 2], [[0.1, 0.2], [0.3, 0.4], [0.5, 0.6]], [0.2, 0.3, 0.5], 1.0, 0.1)
    assert [ctl.pose_index(t) for t in (0.0, 0.19, 0.2, 0.49, 0.5, 0.99, 1.0, 1.25)] == [0, 0, 1, 1, 2, 2, 0, 1]
    assert np.allclose(ctl.target(1.3), [0.3, 0.4])
    with pytest.raises(FlexibleError):
        Controller([0], [[0.1, 0.2]], [0.2], 1, 1)
    with pytest.raises(FlexibleError):
        Controller([0], [[0.1]], [0.0], 1, 1)


def test_pd_controller_drives_active_modes_and_leaves_passive_ones():
    """Qr = -(C (q - q0) + D q_dot) on the active modes only; in free fall (no ground) the
    active mode settles on the pose, the passive one stays where its own spring holds it."""
    body = table_body()
    kp, kd = pd_gains(body, [1])
    ctl = Controller([1], [[0.6]], [1.0], kp, kd)
    sim = Simulator(body, ModeGains.from_frequency(body, 1.0, 0.5), Settings(gravity=(0, 0, 0)), ctl)
    result = sim.run(State.rest(4), 3.0)
    g = result.final.gamma
    k_passive = ModeGains.from_frequency(body, 1.0, 0.5).stiffness[1]
    assert abs(g[1] - kp[0] * 0.6 / (kp[0] + k_passive)) < 1e-3   # the PD and mode springs balance
    assert np.abs(g[[0, 2, 3]]).max() < 1e-3
    assert result.consumed_energy > 0


def fake_result(distance, speed, energy):
    st = State.rest(1)
    com = np.array([[0.0, 0, 0], [distance, 0, 0]])
    return Result(np.array([0.0, 12.0]), np.zeros((2, 3)), np.tile([1.0, 0, 0, 0], (2, 1)), np.zeros((2, 1)),
                  com, np.full(2, np.nan), energy, 1.0, np.ones(1), st, np.array([speed, 0, 0]), [])


def test_cost_functions_of_table_5_1():
    r = fake_result(2.0, 0.5, 400.0)
    assert cost_of(CostSpec("distance"), r)[0] == pytest.approx(0.5)
    assert cost_of(CostSpec("energy_distance"), r)[0] == pytest.approx(200.0)
    assert cost_of(CostSpec("energy_speed", scale=10.0), r)[0] == pytest.approx(400 / (10 * np.sqrt(1.0)))
    assert cost_of(CostSpec("energy_sqrt_distance", scale=10.0), r)[0] == pytest.approx(400 / (10 * np.sqrt(2.0)))
    custom = CostSpec("custom", w_energy=0.01, w_distance=2.0, w_speed=1.0)
    assert cost_of(custom, r)[0] == pytest.approx(4.0 - 4.0 - 0.5)
    # q_x qdot_x < 0 or no progress: the high value, worse the further back
    assert cost_of(CostSpec("energy_speed"), fake_result(2.0, -0.5, 400.0))[0] == HIGH_COST
    assert cost_of(CostSpec("energy_distance"), fake_result(-1.0, 0.5, 400.0))[0] == 2 * HIGH_COST
    # along any direction
    m = motion_measures(fake_result(2.0, 0.5, 1.0), np.array([0.0, 1.0, 0.0]))
    assert m["distance_m"] == 0.0
    with pytest.raises(FlexibleError):
        CostSpec("fastest")


def test_neighbours_change_only_what_is_optimised_within_bounds():
    rng = np.random.default_rng(0)
    poses, durations = np.full((3, 2), 0.9), np.full(3, 0.3)
    for _ in range(50):
        p, d = neighbour(rng, poses, durations, AnnealSettings(optimize="poses", pose_step=1.0))
        assert np.array_equal(d, durations) and (np.abs(p) <= 1).all() and not np.array_equal(p, poses)
        p, d = neighbour(rng, poses, durations, AnnealSettings(optimize="durations", duration_step=2.0))
        assert np.array_equal(p, poses) and ((d >= 0.05) & (d <= 2.0)).all() and not np.array_equal(d, durations)


def table_problem():
    body = table_body()
    active = [0, 1, 2]                              # shear, bend and squash active, hsquash passive
    kp, kd = pd_gains(body, active)
    ctl = Controller(active, [[0.2, 0.0, 0.2], [-0.2, 0.0, -0.2]], [0.3, 0.3], kp, kd)
    gains = ModeGains.from_frequency(body, 3.0, 0.3)
    settings = Settings(dt=0.02, integrator="semi_implicit", ground=Ground.flat(), cond_every=0)
    return body, ctl, (lambda c: Simulator(body, gains, settings, c)), State.rest(4, t=(0, 0, 0.3))


def test_annealing_finds_a_table_gait_repeatably():
    """From an animator's first guess that shuffles backwards, simulated annealing over poses
    and durations finds a controller that carries the table forward more than its own length
    in 12 s; the same seed finds the same controller."""
    body, ctl, make, start = table_problem()
    cost = CostSpec("energy_distance")
    settings = AnnealSettings(optimize="both", trials=6, duration=12.0, seed=1)
    first = run_to_end(anneal(make, ctl, start, cost, settings))
    length = body.extent()[0]
    assert first.initial_cost >= HIGH_COST                        # the guess goes backwards
    assert first.measures["distance_m"] >= length
    assert first.cost < first.initial_cost and first.trials == 6 and len(first.costs) == 6
    assert np.all(np.diff(first.best_costs) <= 0)
    # the controller found, simulated again, does what the annealing measured
    again = make(ctl.with_parameters(first.poses, first.durations)).run(start, 12.0)
    assert cost_of(cost, again)[0] == pytest.approx(first.cost)
    second = run_to_end(anneal(make, ctl, start, cost, settings))
    assert second.costs == first.costs
    assert np.array_equal(second.poses, first.poses) and np.array_equal(second.durations, first.durations)
