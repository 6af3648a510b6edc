"""Two-axis joints (clavicles, forearms, hands, feet) hold their restriction: the locked axis
never turns, whatever sequence of turns, torques or integration steps they go through, and the
dynamics with them stay exact (energy and power balance).

The locked-axis rotation is measured independently of the model's own parametrisation: scipy's
intrinsic Euler decomposition R = R_i(a) R_k(b) R_j(c) (free axes i, k, locked axis j) gives c.
"""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from humananim.solver.dynamics import aba, build_model, difference, integrate, oshita_figure, rk4_step
from humananim.solver.dynamics.inertia_matrix import crba
from humananim.solver.dynamics.kinematics import kinetic_energy, potential_energy


@pytest.fixture(scope="module")
def fig():
    m = build_model(oshita_figure())
    return m, m.create_data()


def two_axis_joints(m):
    """(body, free axis i, free axis k, locked axis j) of every two-axis joint."""
    out = []
    for b in range(1, m.nb):
        if m.free[b].sum() == 2:
            i, k = np.flatnonzero(m.free[b])
            out.append((b, i, k, int(np.flatnonzero(~m.free[b])[0])))
    return out


def locked_turn(quat, i, k, j):
    """The rotation c about the locked axis j in R = R_i(a) R_k(b) R_j(c) (scipy, intrinsic),
    taken to (-pi/2, pi/2]: scipy keeps |b| <= pi/2, so a joint turned past that about k reads
    c = pi (R_i(a + pi) R_k(pi - b) R_j(pi) is R_i(a) R_k(b))."""
    w, x, y, z = quat
    c = Rotation.from_quat([x, y, z, w]).as_euler("XYZ"[i] + "XYZ"[k] + "XYZ"[j])[2]
    return c - np.pi * np.round(c / np.pi)


def locked_turns(m, q):
    return np.array([locked_turn(q[3 + 4 * b:7 + 4 * b], i, k, j) for b, i, k, j in two_axis_joints(m)])


def dof(m, name, axis):
    return m.dof_names.index(f"{name}.{axis}")


def test_the_figure_has_two_axis_joints(fig):
    m, _ = fig
    names = {m.skeleton.names[m.body_joint[b]] for b, *_ in two_axis_joints(m)}
    assert names == {f"{n}.{s}" for n in ("clavicle", "forearm", "hand", "foot") for s in "LR"}


@pytest.mark.parametrize("substeps", [1, 100])
def test_a_sequence_of_turns_leaves_the_locked_axis_alone(fig, substeps):
    """0.3 rad about x, z, -x, -z turns a clavicle back to rest; restricting only the angular
    velocity (turning the bone by exp of its free-axis velocity) leaves it turned 0.089 rad
    about its locked y."""
    m, _ = fig
    b = m.joint_body[m.skeleton.index("clavicle.L")]
    q = m.neutral()
    naive = np.array([1.0, 0.0, 0.0, 0.0])
    for axis, angle in (("x", 0.3), ("z", 0.3), ("x", -0.3), ("z", -0.3)):
        v = np.zeros(m.nv)
        v[dof(m, "clavicle.L", axis)] = angle / substeps
        for _ in range(substeps):
            q = integrate(m, q, v)
            turn = Rotation.from_rotvec(angle / substeps * np.eye(3)["xyz".index(axis)])
            x, y, z, w = (Rotation.from_quat(np.r_[naive[1:], naive[0]]) * turn).as_quat()
            naive = np.array([w, x, y, z])
        assert abs(locked_turn(q[3 + 4 * b:7 + 4 * b], 0, 2, 1)) < 1e-9
    assert abs(locked_turn(naive, 0, 2, 1)) > 0.08  # the old behaviour (0.087 rad)
    np.testing.assert_allclose(np.abs(q[3 + 4 * b:7 + 4 * b]), [1.0, 0.0, 0.0, 0.0], atol=1e-12)


def test_retargeted_rotations_are_projected_onto_the_allowed_set(fig):
    """A source rotation with a twist about the locked axis loses exactly that twist."""
    m, _ = fig
    sk = m.skeleton
    local = np.tile([1.0, 0.0, 0.0, 0.0], (sk.joint_count, 1))
    rot = Rotation.from_euler("XZY", [0.4, -0.3, 0.25])  # clavicle: x, z free, y locked
    x, y, z, w = rot.as_quat()
    local[sk.index("clavicle.L")] = (w, x, y, z)
    q = m.configuration(np.zeros(3), [1.0, 0.0, 0.0, 0.0], local)
    b = m.joint_body[sk.index("clavicle.L")]
    expected = Rotation.from_euler("XZ", [0.4, -0.3]).as_quat()
    got = q[3 + 4 * b:7 + 4 * b]
    assert abs(abs(np.dot(np.r_[got[1:], got[0]], expected)) - 1.0) < 1e-12


@pytest.mark.parametrize("stepper", ["semi-implicit", "rk4"])
def test_random_torques_never_leave_the_allowed_set(fig, stepper):
    """3 s of random joint torques (changing every 50 ms, scaled by each DOF's inertia in the
    rest pose, on a soft spring to the rest pose that keeps the joints in a human range) in the
    closed loop's semi-implicit step and in RK4: every two-axis joint keeps a zero locked-axis
    rotation, and it really moved."""
    m, d = fig
    rng = np.random.default_rng(3)
    q, v = m.neutral(), np.zeros(m.nv)
    dt = 2.5e-3
    g0 = np.zeros(3)
    start = q.copy()
    worst = 0.0
    moved = np.zeros(len(two_axis_joints(m)))
    scale = np.diag(crba(m, d, q)).copy()
    scale[:6] = 0.0
    for step in range(1200):
        if step % 20 == 0:
            drive = rng.normal(scale=8.0, size=m.nv)  # about 8 rad/s^2 on each DOF
        tau = scale * (drive + 20.0 * difference(m, q, start) - 2.0 * v)
        if stepper == "rk4":
            q, v = rk4_step(m, d, q, v, tau, dt, gravity=g0)
        else:
            v = v + dt * aba(m, d, q, v, tau, gravity=g0)
            q = integrate(m, q, v * dt)
        if step % 10 == 0:
            worst = max(worst, np.abs(locked_turns(m, q)).max())
            turned = [2.0 * np.arccos(min(abs(q[3 + 4 * b]), 1.0)) for b, *_ in two_axis_joints(m)]
            moved = np.maximum(moved, turned)
    assert worst < 1e-9
    assert moved.min() > 0.1  # every two-axis joint turned by more than 0.1 rad at some time


def test_undamped_figure_under_gravity_conserves_energy(fig):
    """No torques, no damping, gravity on, tumbling freely for 2 s with every two-axis joint
    moving: kinetic plus potential energy stays constant (an inconsistent velocity product or
    subspace of the universal joints shows as a drift here)."""
    m, d = fig
    rng = np.random.default_rng(7)
    q = integrate(m, m.neutral(), 0.7 * rng.normal(size=m.nv))
    v = rng.normal(size=m.nv)
    zero = np.zeros(m.nv)

    def energy(q, v):
        return kinetic_energy(m, d, q, v) + potential_energy(m, d, q)

    e0 = energy(q, v)
    for _ in range(800):
        q, v = rk4_step(m, d, q, v, zero, 2.5e-3)
    assert energy(q, v) == pytest.approx(e0, abs=1e-6 * kinetic_energy(m, d, q, v))
    assert np.abs(locked_turns(m, q)).max() < 1e-9


@pytest.mark.parametrize("seed", range(3))
def test_power_balance_with_joint_torques(fig, seed):
    """d/dt (kinetic + potential energy) = v . tau along the forward dynamics of a free-floating
    figure (no base wrench), by central differences along q (+) v t, v + a t (second-order terms
    of the path cancel in the central difference)."""
    m, d = fig
    rng = np.random.default_rng(seed)
    q = integrate(m, m.neutral(), 0.7 * rng.normal(size=m.nv))
    v = rng.normal(size=m.nv)
    tau = np.zeros(m.nv)
    tau[6:] = 5.0 * rng.normal(size=m.nv - 6)
    a = aba(m, d, q, v, tau)
    h = 1e-5

    def energy(t):
        qt = integrate(m, q, v * t)
        return kinetic_energy(m, d, qt, v + a * t) + potential_energy(m, d, qt)

    rate = (energy(h) - energy(-h)) / (2 * h)
    assert rate == pytest.approx(v @ tau, abs=1e-5 * np.abs(v * tau).sum())
