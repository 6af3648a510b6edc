"""Continuity of dynamic motion control's modes and strength limits (issue 27 item 1): a part's
mode (comfort or balance) switches with hysteresis, a mode change is blended over a settable time
(modes.ModeBlend), and the strength can saturate smoothly (comfort_control.saturated_stress)
instead of at eq. 2.9's hard clip."""

import numpy as np
import pytest

from humananim.solver.dynamics import build_model, default_strength, oshita_figure
from humananim.solver.motion_control.comfort_control import (ControlState, Settings, body_parts, joint_stress,
                                                             largest_with_kind, passive_control, required_torques,
                                                             saturated_stress, stress_of)
from humananim.solver.motion_control.modes import ModeBlend, ModeMemory
from test_motion_control_comfort import ARMS_FORWARD, HANDS, on_ground, posed, squat

BAND = 0.05


def knees_of(limits, band=BAND):
    return limits[0] * (1.0 - band), limits[1] * (1.0 - band)


def test_saturated_stress_is_the_documented_formula_and_smooth():
    high, low = 100.0, -60.0
    tau = np.linspace(-80.0, 120.0, 40001)
    limits = (np.full_like(tau, low), np.full_like(tau, high))
    s = saturated_stress(tau, limits, knees_of(limits))
    w = BAND * high
    e = tau - (high - w)
    expected = np.where(e <= 0.0, 0.0, np.where(e < 2 * w, e * e / (4 * w), tau - high))
    wl = BAND * -low
    el = (low + wl) - tau
    expected -= np.where(el <= 0.0, 0.0, np.where(el < 2 * wl, el * el / (4 * wl), low - tau))
    assert np.allclose(s, expected, rtol=0, atol=1e-12)
    # inside the knees nothing; beyond strength + w the hard eq. 2.9
    inside = (tau <= 0.95 * high) & (tau >= 0.95 * low)
    assert not s[inside].any()
    far = (tau >= high + w) | (tau <= low - wl)
    assert np.allclose(s[far], joint_stress(tau, limits)[far], atol=1e-12)
    # delivered torque never beyond the strength, and monotone in the demand
    delivered = tau - s
    assert delivered.max() <= high + 1e-12 and delivered.min() >= low - 1e-12
    assert np.all(np.diff(delivered) >= -1e-12)
    # C1: the slope changes by no more than one grid step's curvature (no kink)
    slope = np.diff(s) / np.diff(tau)
    assert np.abs(np.diff(slope)).max() < 2 * (tau[1] - tau[0]) / (2 * min(w, wl))
    # the hard clip's slope jumps by 1 at the limit
    hard = np.diff(joint_stress(tau, limits)) / np.diff(tau)
    assert np.abs(np.diff(hard)).max() > 0.99


def test_saturated_stress_band_zero_and_unbounded_base_are_eq_2_9():
    tau = np.array([-5.0, 3.0, 1e6, -1e6, 120.0])
    limits = (np.array([-np.inf, -np.inf, -np.inf, -10.0, -10.0]), np.array([np.inf, np.inf, np.inf, 10.0, 100.0]))
    assert np.array_equal(saturated_stress(tau, limits, limits), joint_stress(tau, limits))
    s = saturated_stress(tau, limits, knees_of(limits))
    assert not s[:3].any() and np.isfinite(s).all()


@pytest.fixture(scope="module")
def loaded_state():
    m = build_model(oshita_figure(), loads=HANDS)
    q = on_ground(m, posed(m, squat(arms=ARMS_FORWARD)))

    def make(band):
        return ControlState(m, m.create_data(), q, np.zeros(m.nv), (True, True), body_parts(m),
                            default_strength(m, 0.4), settings=Settings(saturation_band=band))
    return m, make


def test_passive_control_holds_joints_at_their_saturated_torque(loaded_state):
    """With the smooth saturation a joint that gives way is held at what it delivers, sat(tau):
    within its strength."""
    m, make = loaded_state
    st = make(BAND)
    a0 = np.zeros(m.nv)
    d = passive_control(st, a0)
    tau = required_torques(st, a0 + d)[0]
    upper = st.parts.upper
    assert np.abs(stress_of(st, required_torques(st, a0)[0])[upper]).max() > 1.0  # it did give way
    low, high = st.limits
    assert np.all(tau[upper] <= high[upper] + 1e-6) and np.all(tau[upper] >= low[upper] - 1e-6)


def test_passive_control_changes_continuously_with_the_strength(loaded_state):
    """The passive change as the strength scale moves through the point where a joint first
    gives way: smooth (no jump above 3x the median neighbour change) with the saturation. The
    hard clip's change is continuous too, but its slope jumps there."""
    m = loaded_state[0]
    q = on_ground(m, posed(m, squat(arms=ARMS_FORWARD)))

    def sizes(band):
        out = []
        for scale in np.linspace(0.8, 1.4, 61):
            st = ControlState(m, m.create_data(), q, np.zeros(m.nv), (True, True), body_parts(m),
                              default_strength(m, scale), settings=Settings(saturation_band=band))
            out.append(np.abs(passive_control(st, np.zeros(m.nv))).sum())
        return np.array(out)
    smooth = sizes(BAND)
    d = np.abs(np.diff(smooth))
    assert smooth[0] > 0 and smooth[-1] == 0.0  # gives way when weak, not when strong
    assert d.max() <= 3.0 * np.median(d[d > 0]) + 1e-9


def test_a_tie_between_comfort_and_balance_does_not_chatter():
    """A part's comfort and balance candidates whose sizes hover at a tie (a 5 % wobble each step):
    without memory the larger one acts and the kind flips almost every step; with the hysteresis
    (Settings.mode_margin = 10 %) the kind that acts stays."""
    rng = np.random.default_rng(0)
    wobble = 1.0 + rng.uniform(-0.08, 0.08, 400)  # within the 10 % margin

    class Parts:
        arms = np.arange(4)

    class State:
        settings = Settings()
        parts = Parts()

    def criteria(step):
        return {"comfort": lambda *a: [np.full(4, 1.0)],
                "balance": lambda *a: [np.full(4, wobble[step])]}

    def kinds(memory):
        out = []
        for step in range(len(wobble)):
            previous = memory.previous("arms") if memory else None
            kind, _ = largest_with_kind(State(), "arms", criteria(step), None, None, previous)
            if memory:
                memory.remember([("upper", "passive"), ("arms", kind)])
            out.append(kind)
        return out
    flips = lambda ks: sum(a != b for a, b in zip(ks, ks[1:]))
    assert flips(kinds(None)) > 100
    assert flips(kinds(ModeMemory())) <= 1
    # a clear winner still takes over
    memory = ModeMemory({"arms": "comfort"})
    st = State()
    kind, _ = largest_with_kind(st, "arms", {"comfort": lambda *a: [np.ones(4)],
                                             "balance": lambda *a: [1.2 * np.ones(4)]}, None, None,
                                memory.previous("arms"))
    assert kind == "balance"


def test_mode_changes_are_blended_over_the_blend_time():
    """Two modes whose outputs differ by 1, switched back and forth at random (a signal hovering
    at a switching point): the blended output moves by no more than its own change per step
    plus dt / blend_time of the jump, and reaches the new mode's output blend_time after the
    last switch."""
    dt, blend_time = 1.0 / 120.0, 0.1
    blend = ModeBlend(blend_time)
    rng = np.random.default_rng(1)
    modes = rng.integers(0, 2, 120)
    modes[80:] = 1
    outputs = []
    for k, mode in enumerate(modes):
        own = np.array([float(mode) + 0.001 * k])  # each mode's own output drifts slowly
        outputs.append(blend.blend(int(mode), own, dt)[0])
    steps = np.abs(np.diff(outputs))
    assert steps.max() <= 1.05 * dt / blend_time + 0.001
    last_switch = 80
    settle = last_switch + int(np.ceil(blend_time / dt)) + 1
    assert np.allclose(outputs[settle:], 1.0 + 0.001 * np.arange(settle, len(modes)))
    # without a blend, the output is the mode's own
    assert ModeBlend(0.0).blend(0, np.array([3.0]), dt)[0] == 3.0
