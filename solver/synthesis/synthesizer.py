"""The motion synthesizer (Oshita 2003, sec. 3.4.1): actions are queued "after the current one" or
"now", interrupting it, with a transition mode; a request the constraints at the join do not allow
is rejected with the reason and changes nothing, so the caller can retry with another mode."""

from dataclasses import dataclass, field

import numpy as np

from ..errors import HumanAnimError
from .action import ANGULAR, SPATIAL, SUPPORT, Action
from .transitions import MODES, TransitionRejected, TransitionSettings, continuity_rejection, transition

WHEN = ("after", "now")


@dataclass
class Request:
    action: str
    mode: str
    when: str
    accepted: bool
    reason: str = ""
    start: int = None  # output frame index where the action's own frames begin
    window: tuple = None  # (first, last) output frame index of the transition
    held: dict = field(default_factory=dict)  # side -> (F,) bool, frames a foot was held in place
    info: dict = field(default_factory=dict)


class Synthesizer:
    """Continuous motion from queued actions; `motion` is the joined result so far (an Action
    whose leg constraints are the joined support)."""

    def __init__(self, first, settings=None):
        self.settings = settings or TransitionSettings()
        self.motion = first
        self.requests = [Request(first.name, "start", "after", True, start=0, window=(0, 0))]

    def queue(self, action, mode="blend", when="after", at=None):
        """Add `action` with `mode` ("blend", "connect", "inertialize"); when="now" interrupts the
        current motion at output frame index `at` (default: its last frame). Returns the Request
        (accepted or rejected with its reason)."""
        if mode not in MODES:
            raise HumanAnimError(f"unknown transition mode {mode!r} (one of {', '.join(MODES)})")
        if when not in WHEN:
            raise HumanAnimError(f"when must be 'after' or 'now', not {when!r}")
        cur = self.motion
        last = cur.frame_count - 1
        end1 = last
        if when == "now":
            at = last if at is None else int(np.clip(at, 1, last))
            end1 = at
            if mode == "blend":  # the current action keeps playing under the blend window
                s = self.settings
                blend = s.blend_duration if s.blend_duration is not None else \
                    min(cur.terminal_duration, action.initial_duration)
                end1 = min(at + int(round(blend * cur.fps)), last)
        try:
            tr = transition(cur, action, mode, self.settings, end1=end1)
            why = continuity_rejection(cur, end1, action, tr, mode)  # pops or slides: refused
            if why:
                raise TransitionRejected(why)
        except TransitionRejected as e:
            req = Request(action.name, mode, when, False, e.reason)
            self.requests.append(req)
            return req
        self.motion = _joined_action(cur, action, tr)
        # earlier requests' held masks grow with the motion
        for r in self.requests:
            r.held = {k: _fit(v, tr.trajectories.frame_count) for k, v in r.held.items()}
        req = Request(action.name, mode, when, True, start=tr.next_start, window=tr.window, held=tr.held,
                      info=tr.info)
        self.requests.append(req)
        return req

    @property
    def trajectories(self):
        return self.motion.trajectories

    def support(self):
        return {limb[-1]: self.motion.constraints[limb] == SUPPORT for limb in ("foot.L", "foot.R")
                if limb in self.motion.constraints}


def _fit(mask, n):
    out = np.zeros(n, bool)
    out[:min(n, len(mask))] = mask[:n]
    return out


def _joined_action(a1, a2, tr):
    n, start = tr.trajectories.frame_count, tr.next_start
    cons = {}
    for limb in a1.constraints:
        c = np.full(n, SPATIAL if limb == "root" else ANGULAR, np.int8)
        k1 = min(start, a1.frame_count)
        c[:k1] = a1.constraints[limb][:k1]
        if limb in a2.constraints:
            k2 = min(a2.frame_count, n - start)
            c[start:start + k2] = a2.constraints[limb][:k2]
        if limb.startswith("foot."):
            c = np.where(tr.support[limb[-1]], SUPPORT, np.where(c == SUPPORT, ANGULAR, c)).astype(np.int8)
        cons[limb] = c
    return Action(f"{a1.name}+{a2.name}", a1.skeleton, tr.trajectories, cons, a1.initial_duration,
                  a2.terminal_duration)
