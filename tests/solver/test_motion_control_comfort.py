"""Comfort control (Oshita 2003, eq. 2.8-2.10, 2.17-2.22) on Oshita's 18-segment figure and the
real-rig fixtures, from held poses built by hand (zero velocity)."""

import importlib

import numpy as np
import pytest

from humananim.solver import rotations
from humananim.solver.dynamics import build_model, default_strength, oshita_figure, rnea
from humananim.solver.dynamics.kinematics import point_positions
from humananim.solver.motion_control.comfort_control import (ControlState, body_parts, comfort_control,
                                                             joint_stress, passive_control,
                                                             required_torques)
from humananim.solver.motion_control.dynamic_control import dynamic_control, stress_by_bone

from test_dynamics_closed_loop_rigs import load

HANDS = {"hand.L": 8.0, "hand.R": 8.0}
ARMS_FORWARD = {"upper_arm.L": (0, -90.0), "upper_arm.R": (0, -90.0)}


def posed(model, angles):
    """Neutral pose with bones turned about one local axis: {bone: (axis, degrees)}."""
    q = model.neutral()
    for name, (axis, deg) in angles.items():
        b = model.joint_body[model.skeleton.index(name)]
        q[3 + 4 * b:7 + 4 * b] = rotations.axis_rotation(axis, np.radians(deg))
    return q


def squat(knee=40.0, lean=10.0, arms=None):
    """Oshita pose: knees bent (feet flat), trunk leaning forward, optionally arms forward."""
    a = {"thigh.L": (0, -knee / 2), "thigh.R": (0, -knee / 2), "shin.L": (0, knee), "shin.R": (0, knee),
         "foot.L": (0, -knee / 2), "foot.R": (0, -knee / 2), "spine": (0, lean)}
    a.update(arms or {})
    return a


def on_ground(model, q, ground=0.0):
    """q shifted so that the feet stand where the rest pose's do, soles on the ground."""
    sk, data = model.skeleton, model.create_data()
    feet = [sk.role_index("foot.L"), sk.role_index("foot.R")]
    zero = np.zeros((2, 3))
    ref = point_positions(model, data, model.neutral(), feet, zero).mean(axis=0)
    now = point_positions(model, data, q, feet, zero).mean(axis=0)
    q = q.copy()
    q[:3] += ref - now
    q[2] += ground
    return q


def state(model, q, strength=None, feet=(True, True), ground=0.0, f_ext=None):
    return ControlState(model, model.create_data(), q, np.zeros(model.nv), feet, body_parts(model),
                        strength or default_strength(model), f_ext=f_ext, ground_height=ground)


@pytest.fixture(scope="module")
def figure():
    return oshita_figure()


def test_required_torques_carry_the_ground_reaction_on_the_feet(figure):
    m = build_model(figure)
    st = state(m, on_ground(m, posed(m, squat())))
    tau, wrench = required_torques(st, np.zeros(m.nv))
    assert np.abs(tau[:6]).max() < 1e-8  # the feet take the whole ground wrench
    assert wrench[5] == pytest.approx(m.mass.sum() * 9.81)
    plain = rnea(m, st.data, st.q, st.v, np.zeros(m.nv))
    upper = st.parts.upper
    np.testing.assert_allclose(tau[upper], plain[upper], atol=1e-9)  # the upper body does not feel it


def test_limits_are_the_strength_models_at_each_dofs_rotation(figure):
    """ControlState.limits' fused arithmetic (fewer numpy calls) against its definition: the
    strength model's limits at the rotation-vector component of each DOF's body (quat_log, the
    short way round: quaternions with w < 0, tiny and half-turn rotations) and its velocity."""
    from humananim.solver.dynamics import spatial
    m = build_model(figure)
    rng = np.random.default_rng(3)
    for scale in (1e-12, 1e-5, 0.5, 3.1):
        q = m.neutral()
        quats = rng.normal(size=(m.nb, 4))
        quats[:, 1:] *= scale
        q[3:] = (quats / np.linalg.norm(quats, axis=1)[:, None]).ravel()  # w of either sign
        v = rng.normal(scale=30.0, size=m.nv)
        strength = default_strength(m)
        st = ControlState(m, m.create_data(), q, v, (True, True), body_parts(m), strength)
        angles = spatial.quat_log(q[7:].reshape(-1, 4))[m.dof_body[6:] - 1, m.dof_slot[6:]]
        low, high = strength.select(m.dof_joint[6:], m.dof_slot[6:]).limits(angles, v[6:])
        got_low, got_high = st.limits
        assert np.all(np.isinf(got_low[:6])) and np.all(np.isinf(got_high[:6]))
        np.testing.assert_allclose(got_low[6:], low, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(got_high[6:], high, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("pose", [{}, squat(), squat(arms=ARMS_FORWARD)])
def test_no_load_comfortable_motion_changes_nothing(figure, pose):
    m = build_model(figure)
    st = state(m, on_ground(m, posed(m, pose)))
    a0 = np.zeros(m.nv)
    res = comfort_control(st, a0)
    assert not res.stress.any()
    assert np.array_equal(res.delta, np.zeros(m.nv)) and not res.log.actions
    dyn = dynamic_control(st, a0)
    assert np.array_equal(dyn.delta, np.zeros(m.nv)) and dyn.acceleration is not None


def test_early_exit_does_no_control_work(figure, monkeypatch):
    """Nothing stressed and balance holding: one inverse dynamics pass, no control sequence (the
    thesis's 'no work'; the time it takes is in benchmarks/control.py, not asserted here)."""
    dc = importlib.import_module("humananim.solver.motion_control.dynamic_control")
    m = build_model(figure)
    q = on_ground(m, posed(m, squat()))
    calls = {"torques": 0}
    required = dc.required_torques

    def counted(*a, **kw):
        calls["torques"] += 1
        return required(*a, **kw)

    def forbidden(*a, **kw):
        raise AssertionError("the control sequence ran although nothing needed control")

    monkeypatch.setattr(dc, "required_torques", counted)
    monkeypatch.setattr(dc, "control_sequence", forbidden)
    state = ControlState(m, m.create_data(), q, np.zeros(m.nv), (True, True), body_parts(m), default_strength(m))
    res = dc.dynamic_control(state, np.zeros(m.nv))
    assert calls["torques"] == 1 and not res.log.actions and not res.delta.any()


def acted_within_strength(res, st, tol=1e-6):
    """Stress after control on the upper-body DOFs the control acted on."""
    acted = (res.log.passive | res.log.comfort)
    acted[st.parts.lower] = False
    acted[:6] = False
    low, high = st.limits
    tau = required_torques(st, np.zeros(st.model.nv) + res.delta)[0]  # from a0 = 0
    over = joint_stress(tau, (low - tol * np.abs(low), high + tol * np.abs(high)))
    return acted, over[acted]


def test_loads_in_the_hands_at_arms_forward_relieve_the_shoulders(figure):
    m = build_model(figure, loads=HANDS)
    st = state(m, on_ground(m, posed(m, squat(arms=ARMS_FORWARD))))
    a0 = np.zeros(m.nv)
    res = comfort_control(st, a0)
    stressed = np.flatnonzero(res.stress)
    names = {m.dof_names[i] for i in stressed}
    assert {"upper_arm.L.x", "upper_arm.R.x"} <= names
    acted, over = acted_within_strength(res, st)
    assert acted[stressed].all() and not over.any()
    # arms (two swing axes each) act before the back, which is not needed
    assert res.log.actions[0] == ("upper", "passive") and ("arms", "comfort") in res.log.actions
    assert not res.delta[st.parts.back].any() and not res.delta[st.parts.lower].any()
    # the arms give way downwards: +X swings a limb backwards
    assert res.delta[stressed].min() > 0.0
    print("stress before", res.stress[stressed], "after", res.stress_after[stressed])


def test_weak_back_is_relieved_by_the_arms_then_the_back(figure):
    """A weak figure (half strength) squatting with 8 kg in each hand: back and shoulders stressed;
    every upper-body joint the control touched ends within strength."""
    m = build_model(figure, loads=HANDS)
    st = state(m, on_ground(m, posed(m, squat(lean=35.0, arms=ARMS_FORWARD))),
               strength=default_strength(m, scale=0.5))
    res = dynamic_control(st, np.zeros(m.nv))
    names = {m.dof_names[i] for i in np.flatnonzero(res.stress)}
    assert "spine.x" in names and "upper_arm.L.x" in names
    acted, over = acted_within_strength(res, st)
    before = np.abs(res.stress[st.parts.upper]).sum()
    after = np.abs(res.stress_after[st.parts.upper]).sum()
    # the legs act last (balance here) and their pelvis acceleration loads the upper body again a
    # little: the thesis accepts it ("the joint torque ... may exceed the available torque range")
    assert np.abs(over).sum() < 0.02 * before and after < 0.02 * before
    kinds = [p for p, _ in res.log.actions]
    assert kinds.index("arms") < (kinds.index("back") if "back" in kinds else len(kinds))
    print("upper stress |sum| before", before, "after", after, res.log.actions)
    assert stress_by_bone(m, res.stress).shape == (figure.joint_count, 3)


def test_passive_control_is_exact_on_the_upper_body(figure):
    m = build_model(figure, loads=HANDS)
    st = state(m, on_ground(m, posed(m, squat(arms=ARMS_FORWARD))), strength=default_strength(m, 0.4))
    a0 = np.zeros(m.nv)
    d = passive_control(st, a0)
    s = joint_stress(required_torques(st, a0 + d)[0], st.limits, 1e-6)
    assert not s[st.parts.upper].any()
    assert not d[st.parts.lower].any() and not d[:6].any()


@pytest.mark.parametrize("name", ["cmu_131_01", "metarig_legs"])
def test_real_rigs(name):
    sk, tr = load(name, frames=1)
    basis = tr.basis()[0]
    for loads in ({}, {sk.roles.bone("hand.L"): 8.0, sk.roles.bone("hand.R"): 8.0}):
        m = build_model(sk, reference_basis=basis, loads=loads)
        parts = body_parts(m)
        assert len(parts.arms) == 4 and len(parts.back) == 3
        q = m.neutral()
        data = m.create_data()
        soles = [point_positions(m, data, q, j, p) for j, p in zip(parts.sole_joints, parts.sole_points)]
        ground = min(s[:, 2].min() for s in soles)
        weak = default_strength(m, scale=0.25 if loads else 1.0)  # stresses the loaded rest pose
        st = ControlState(m, data, q, np.zeros(m.nv), (True, True), parts, weak, ground_height=ground)
        res = comfort_control(st, np.zeros(m.nv))
        if not loads:
            assert np.array_equal(res.delta, np.zeros(m.nv)) == (not res.stress.any())
            continue
        acted, over = acted_within_strength(res, st)
        assert res.stress.any() and res.log.actions
        assert np.abs(over).sum() < 0.02 * np.abs(res.stress[parts.upper]).sum()
        print(name, "stressed", [m.dof_names[i] for i in np.flatnonzero(res.stress)],
              "actions", res.log.actions)
