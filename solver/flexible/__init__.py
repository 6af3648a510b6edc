"""Flexible characters (issue 8; Faloutsos 1995, ch. 4-5): dynamic free-form deformations of
lattice-deformed objects, key-framing, PD pose control and simulated annealing of pose graphs."""

from .body import FlexibleBody, FlexibleError, check_modes
from .forces import Ground, ModeGains, Plane, Spring
from .simulate import Controller, Settings, Simulator, State

__all__ = ["FlexibleBody", "FlexibleError", "check_modes", "Ground", "ModeGains", "Plane", "Spring", "Controller",
           "Settings", "Simulator", "State"]
