"""Dynamic motion control (Oshita 2003, sec. 2.5, eq. 2.7): theta''_output = theta''_tracking +
delta theta''_dynamic, from comfort control (joint stress against strength) and balance control
(ZMP against the support polygon) in the thesis's order (sec. 2.5.3):

  1-2. stress and balance of the tracking acceleration; nothing to do -> exactly zero change;
  3.   passive control of the upper body;
  4.   active control of the arms, then the back: for each, the comfort candidate (stressed joints)
       and the balance candidate (ZMP to MMP), the larger one acts; passive change recomputed;
  5.   the legs through the pelvis, comfort and balance candidates, the larger one acts;
  then the falling criterion: a ZMP still outside makes the figure turn about the MMP.

Diagnostics per step (stress per DOF, which controls acted, ZMP, MMP, support polygon) feed the
viewport overlay and the custom-property curves on the Blender side.
"""

from dataclasses import dataclass

import numpy as np

from .balance_control import (Falling, balance_criterion, balance_error, falling, support_polygon)
from .comfort_control import (ControlLog, ControlState, body_parts, comfort_criterion, control_sequence,
                              required_torques, stress_of)


@dataclass
class DynamicResult:
    acceleration: np.ndarray  # (nv,) theta''_output
    delta: np.ndarray  # (nv,) delta theta''_dynamic
    stress: np.ndarray  # (nv,) eq. 2.9 at the tracking acceleration
    stress_after: np.ndarray  # (nv,) at the output
    zmp_before: np.ndarray  # (2,) or None (nothing on the ground)
    zmp: np.ndarray  # (2,) of the output, or None
    mmp: np.ndarray  # (2,) of the output, or None
    polygon: np.ndarray  # (m, 2) support polygon
    falling: Falling  # None while balanced
    log: ControlLog  # per-DOF masks passive / comfort / balance, and the actions in order

    @property
    def acted(self):
        return bool(self.log.actions)


def dynamic_control(state, a_tracking, memory=None):
    """One control step on a ControlState (see comfort_control.ControlState); `memory`
    (modes.ModeMemory): the kinds that acted on each part in the last step (hysteresis)."""
    a0 = np.asarray(a_tracking, float)
    tol = state.settings
    tau, wrench = required_torques(state, a0)
    stress = stress_of(state, tau)
    polygon = support_polygon(state)
    p0, mmp, dist = balance_error(state, wrench, polygon)
    log = ControlLog(state.model.nv)
    if not np.count_nonzero(stress) and dist <= tol.zmp_tolerance:  # step 2: nothing to do
        return DynamicResult(a0, np.zeros(len(a0)), stress, stress, p0, p0, mmp, polygon, None, log)
    criteria = {"comfort": comfort_criterion, "balance": balance_criterion}
    out, log = control_sequence(state, a0, criteria, log=log, memory=memory)
    tau, wrench = required_torques(state, out)
    p, mmp, dist = balance_error(state, wrench, polygon)
    fall = falling(state, wrench, mmp) if mmp is not None and dist > tol.zmp_tolerance else None
    return DynamicResult(out, out - a0, stress, stress_of(state, tau),
                         p0, p, mmp, polygon, fall, log)


def control_state(model, data, q, v, feet, strength, f_ext=None, ground_height=0.0, parts=None,
                  settings=None, allowance=None, **known):
    """A ControlState for one step; pass `parts` (body_parts(model)) and `constants`
    (state_constants) to reuse them across steps, and any derived field the caller knows (soles,
    contact_sides, foot_bodies). `allowance`: (nv,) torque each DOF may exceed its strength by
    (see controller's input allowance)."""
    kw = {} if settings is None else {"settings": settings}
    return ControlState(model, data, q, v, feet, parts or body_parts(model), strength, f_ext=f_ext,
                        ground_height=ground_height, allowance=allowance, **kw, **known)


def stress_by_bone(model, stress):
    """(J, 3) stress per bone and local axis from a (nv,) vector: the custom-property curves."""
    out = np.zeros((model.skeleton.joint_count, 3))
    out[model.dof_joint[6:], model.dof_slot[6:]] = stress[6:]
    return out
