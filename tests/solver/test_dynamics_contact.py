"""Ground contact: the penalty force field, its split for implicit damping, explicit stepping."""

import numpy as np
import pytest

from humananim.solver.dynamics import (GroundModel, Settings, build_model, default_contacts,
                                       oshita_figure, simulate)
from humananim.solver.trajectories import Trajectories


@pytest.fixture(scope="module")
def fig():
    m = build_model(oshita_figure())
    return m, m.create_data(), default_contacts(m)


def test_standing_figure_contacts(fig):
    m, d, c = fig
    ground = GroundModel()
    q = m.neutral()
    q[2] -= 0.003  # 3 mm into the ground: the eight sole spheres push back, nothing else touches
    w, x, f = ground.forces(m, d, q, np.zeros(m.nv), c)
    touching = f[:, 2] > 0
    assert touching.sum() == 8
    np.testing.assert_allclose(f[touching, 2], ground.stiffness * 0.003)
    np.testing.assert_allclose(f[:, :2], 0.0)
    # the body wrench is the sum of the point forces about the origin
    np.testing.assert_allclose(w.sum(axis=0)[3:], f.sum(axis=0))
    np.testing.assert_allclose(w.sum(axis=0)[:3], np.cross(x, f).sum(axis=0), atol=1e-9)


# slow slip sticks (viscous); 3 m/s is past the cap mu N / friction_damping (~0.8 m/s at this
# depth with the default ground) so it slides
@pytest.mark.parametrize("speed", [0.001, 3.0])
def test_split_forces_match_the_force_field(fig, speed):
    """Elastic + saturated friction + damped parts (-gain J v) add up to the full penalty forces,
    both when sticking (slow slip) and sliding (fast slip, Coulomb's cap mu N)."""
    m, d, c = fig
    ground = GroundModel()
    rng = np.random.default_rng(0)
    q = m.neutral()
    q[2] -= 0.004
    v = np.zeros(m.nv)
    v[3:6] = (speed, 0.0, -0.01)  # root axes: x is world x; sliding sideways, sinking slowly
    v[6:] = 0.01 * rng.normal(size=m.nv - 6)
    w_full, x, f = ground.forces(m, d, q, v, c)
    w, jac, gain = ground.split_forces(m, d, q, v, c)
    damped = -(gain * (jac @ v))
    active = int((gain == ground.damping).sum())  # rows: normals, then tangential x, then y
    stick = (len(gain) - active) // 2
    parts = (damped[:active].sum(), damped[active:active + stick].sum(), damped[active + stick:].sum())
    assert jac.shape[1] == m.nv and np.all(gain > 0)
    total = w.sum(axis=0)[3:] + np.array([parts[1], parts[2], parts[0]])
    np.testing.assert_allclose(total, w_full.sum(axis=0)[3:], rtol=1e-9, atol=1e-9)
    touching = f[:, 2] > 0
    slip = np.linalg.norm(f[touching, :2], axis=1)
    if speed > 0.1:
        np.testing.assert_allclose(slip, ground.friction * f[touching, 2])  # Coulomb's cap


def test_explicit_aba_simulation_agrees_with_implicit():
    """Standing still for 0.2 s: explicit ABA steps (small) and the implicit step give the same
    motion within a centimetre (measured 7 mm): implicit Euler at 1 ms damps the stiff contact
    mode (about 150 rad/s, omega dt = 0.15), the price of unconditional stability on light
    segments."""
    sk = oshita_figure()
    n = 13
    rot = np.zeros((n, sk.joint_count, 4))
    rot[..., 0] = 1.0
    tr = Trajectories(np.arange(n), 60.0, rot, np.zeros((n, sk.joint_count, 3)), np.eye(4))
    ground = GroundModel(height=0.004)
    a = simulate(sk, tr, Settings(tracking=0.0, ground=ground))
    b = simulate(sk, tr, Settings(tracking=0.0, ground=ground, forward="aba", max_step=1e-4))
    pa, pb = a.trajectories.root_pose(sk)[0], b.trajectories.root_pose(sk)[0]
    assert np.abs(pa - pa[0]).max() > 0.002  # it moved: pushed up, then sagging without tracking
    np.testing.assert_allclose(pa, pb, atol=1e-2)
