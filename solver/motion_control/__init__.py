"""Dynamic motion control after Oshita (2003): tracking control with Ferguson curves, foot support
intervals from the motion, analytic 7-DOF limb inverse kinematics, and comfort and balance control
on top of the tracking acceleration. numpy and scipy only."""

from .balance_control import balance_control
from .comfort_control import comfort_control
from .contacts import Contact, remove_short_runs, runs, support_intervals, support_phases
from .dynamic_control import control_state, dynamic_control, stress_by_bone
from .limb_ik import LimbIK
from .tracking import TrackingController, next_extremum_times

__all__ = ["Contact", "LimbIK", "TrackingController", "balance_control", "comfort_control", "control_state",
           "dynamic_control", "next_extremum_times", "remove_short_runs", "runs", "stress_by_bone",
           "support_intervals", "support_phases"]
from .controller import Collider, ControlResult, ControlSettings, Impulse, Load, control, iter_control

__all__ += ["Collider", "ControlResult", "ControlSettings", "Impulse", "Load", "control", "iter_control"]
