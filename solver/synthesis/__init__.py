"""Motion synthesis after Oshita (2003, ch. 3): action data with per-limb constraints, transitions
(blending, connection, inertialization) with supporting feet kept in place, the synthesizer queue,
and dynamic reactions (protective step, fall, recovery) on top of the dynamic controller."""

from .action import ANGULAR, CONSTRAINT_NAMES, SPATIAL, SUPPORT, Action, from_trajectories
from .synthesizer import Request, Synthesizer
from .transitions import MODES, Transition, TransitionRejected, TransitionSettings, transition

__all__ = ["ANGULAR", "CONSTRAINT_NAMES", "MODES", "Request", "SPATIAL", "Synthesizer", "SUPPORT", "Action", "Transition",
           "TransitionRejected", "TransitionSettings", "from_trajectories", "transition"]
