"""The fused kernel (Simulator.run) against the readable reference step (Simulator.reference_run)
on the benchmark's workloads, whole: the thesis workload (the table of 11 points and 4 modes under
pose control on the ground, 1,200 steps at dt 0.01) and the 200-point, 8-mode character dropped
on the ground (the many-points path: M from its polynomial in gamma, the ground's share of the
system matrix from the touching points alone). Same physics: the same trajectories to rounding,
which 12 s of hopping under pose control amplify to ~1e-7 m for the semi-implicit step (the fused
kernel before this one differed from the reference as much there), to 1e-11 for the others."""

import numpy as np
import pytest

from humananim.solver.flexible import Ground, ModeGains, Settings, Simulator
from humananim.solver.flexible.demo import blob_body, table_body
from humananim.solver.flexible.simulate import Controller, State


def table_controller(body):
    """benchmarks/flexible.py's pose graph: shear, bend and squash hop between two poses."""
    active = [0, 1, 2]
    m = body.modal_masses()[active]
    w = 2 * np.pi * 4.0
    return Controller(active, [[0.4, 0.4, 0.4], [-0.4, -0.4, -0.4]], [0.3, 0.3], m * w * w, 1.6 * w * m)


def assert_same_run(sim, start, duration, tol):
    fast = sim.run(start, duration, record_every=10)
    ref = sim.reference_run(start, duration, record_every=10)
    assert len(fast.times) == len(ref.times) == int(round(duration / sim.settings.dt)) // 10 + 1
    for a, b in ((fast.t, ref.t), (fast.quat, ref.quat), (fast.gamma, ref.gamma), (fast.com, ref.com)):
        assert np.abs(a - b).max() < tol
    assert fast.consumed_energy == pytest.approx(ref.consumed_energy, rel=tol)
    return fast


@pytest.mark.parametrize("integrator, tol", [("semi_implicit", 1e-6), ("implicit", 1e-9)])
def test_thesis_workload_fast_path_matches_the_reference(integrator, tol):
    body = table_body(count=11)
    gains = ModeGains.from_frequency(body, 3.0, 0.3)
    sim = Simulator(body, gains, Settings(dt=0.01, integrator=integrator, ground=Ground.flat(), cond_every=10),
                    table_controller(body))
    r = assert_same_run(sim, State.rest(4, t=(0, 0, 0.3)), 12.0, tol)
    assert not sim._kernel.big
    assert np.ptp(r.com[:, 2]) > 0.05 and r.consumed_energy > 1.0          # it hopped, the PD worked


def test_thesis_workload_thesis_scheme_matches_the_reference():
    body = table_body(count=11)
    sim = Simulator(body, ModeGains.from_frequency(body, 3.0, 0.3),
                    Settings(dt=0.01, integrator="thesis", ground=Ground.flat(), cond_every=10))
    r = assert_same_run(sim, State.rest(4, t=(0, 0, 0.5)), 12.0, 1e-12)
    assert r.com[:, 2].min() < 0.35                                          # it landed


@pytest.mark.parametrize("integrator", ["semi_implicit", "implicit"])
def test_many_points_fast_path_matches_the_reference(integrator):
    body = blob_body(points=200, modes=8)
    sim = Simulator(body, ModeGains.from_frequency(body, 3.0, 0.3),
                    Settings(dt=0.01, integrator=integrator, ground=Ground.flat(), cond_every=10))
    start = State.rest(8, t=(0, 0, 0.6))
    start.w[:] = [0.3, 0.5, 0.1]
    r = assert_same_run(sim, start, 3.0, 1e-12)
    assert sim._kernel.big
    assert r.com[:, 2].min() < 0.5 and np.abs(r.com[-1] - r.com[-2]).max() < 0.05   # fell, settled
