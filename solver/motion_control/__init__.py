"""Dynamic motion control after Oshita (2003): tracking control with Ferguson curves, foot support
intervals from the motion and analytic 7-DOF limb inverse kinematics. numpy and scipy only."""

from .contacts import Contact, remove_short_runs, runs, support_intervals, support_phases
from .limb_ik import LimbIK
from .tracking import TrackingController, next_extremum_times

__all__ = ["Contact", "LimbIK", "TrackingController", "next_extremum_times", "remove_short_runs", "runs",
           "support_intervals", "support_phases"]
