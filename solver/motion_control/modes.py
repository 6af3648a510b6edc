"""The control modes over time: hysteresis of each part's mode and a short blend when the mode
changes, so that a signal hovering at a switching point does not flip the output from one step to
the next.

A control step's mode is the kind (comfort or balance) acting on each part (arms, back, legs) and
how much of the tracking's return was kept (ControlLoop._slower_return); a control starting or
stopping to act is no mode change, its change starts from or ends at zero by itself. Two mechanisms keep it from chattering:

- **Hysteresis of a part's kind** (comfort or balance): the kind that acted on a part in the last
  step keeps acting until the other kind's candidate is larger by Settings.mode_margin (10 %)
  (comfort_control.largest_with_kind with `previous`); ModeMemory remembers the kinds.
- **A blend over `blend_time`** (ControlSettings.mode_blend_time; off, 0 s, by default: at 0.1 s
  the delayed feedback made the thesis's 15 kg box squat fall): when the mode changes, the
  change dynamic control makes to the tracking acceleration (c = a - a_tracking) continues from
  what it was and reaches the new mode's over blend_time, linearly:

      c_out(t) = c_new(t) + (c_out(t0-) - c_new(t0)) * max(0, 1 - (t - t0) / blend_time)

  t0 the step the mode changed at (a blend of offsets, "inertialisation": the new mode's output is
  followed as it moves, only the jump is spread). Within one mode the output is the mode's own.

The falling criterion keeps its own persistence (falling.FallCriterion: fall_time), and falling is
final: the fall is a declared threshold, where the change is the reaction itself.
"""

from dataclasses import dataclass, field

import numpy as np


@dataclass
class ModeMemory:
    """The kind (comfort or balance) that last acted on each part (arms, back, legs)."""

    kinds: dict = field(default_factory=dict)

    def previous(self, part):
        return self.kinds.get(part)

    def state(self):
        """The remembered kinds as a hashable value (part, kind) pairs."""
        return tuple(sorted(self.kinds.items()))

    def remember(self, actions):
        """Keep the kinds of a step's actions ((part, kind) pairs; the upper body's passive control
        is not a choice)."""
        for part, kind in actions:
            if part != "upper":
                self.kinds[part] = kind


@dataclass
class ModeBlend:
    """The blend of dynamic control's change across mode changes (module notes)."""

    blend_time: float = 0.1  # s; 0: switch at once
    mode: tuple = None  # the last step's mode
    last: np.ndarray = None  # (nv,) the last step's blended change
    offset: np.ndarray = None  # (nv,) what is left of the jump at the last mode change
    since: float = 0.0  # s since that change

    def blend(self, mode, change, dt):
        """The blended change (nv,) of a step of mode `mode` (hashable) whose own change is `change`;
        dt: the step's length (the blend advances by it after this step)."""
        if self.blend_time <= 0.0:
            return change
        if self.last is not None and mode != self.mode:
            self.offset, self.since = self.last - change, 0.0
        self.mode = mode
        out = change
        if self.offset is not None:
            share = 1.0 - self.since / self.blend_time
            if share > 0.0:
                out = change + share * self.offset
            else:
                self.offset = None
        self.last = out
        self.since += dt
        return out
