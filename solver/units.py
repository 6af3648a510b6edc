"""Guessing the length unit of motion files, so rigs in cm, mm or inches come out in metres."""

import re

import numpy as np

# (metres per file unit, name), most likely first
LENGTH_UNITS = ((1.0, "m"), (0.01, "cm"), (0.0254, "in"), (0.001, "mm"), (0.1, "dm"))
HUMAN_HEIGHT = (0.8, 2.4)  # metres, rest-pose extent of a child to a very tall adult


def guess_length_scale(extent):
    """Metres per unit for a figure whose rest-pose height is `extent` file units.

    Returns (scale, unit name); a figure that fits no common unit is scaled to 1.7 m."""
    if not np.isfinite(extent) or extent <= 0.0:
        return 1.0, "m"
    for scale, name in LENGTH_UNITS:
        if HUMAN_HEIGHT[0] <= extent * scale <= HUMAN_HEIGHT[1]:
            return scale, name
    return 1.7 / extent, "unknown (scaled to 1.7 m)"


_OFFSET = re.compile(r"^\s*OFFSET\s+(\S+)\s+(\S+)\s+(\S+)", re.M)


def bvh_rest_extent(text):
    """Vertical extent of a BVH rest skeleton (its Y axis, end sites included), in file units."""
    header = text.split("MOTION", 1)[0]
    heights, stack, y = [], [], 0.0
    for line in header.splitlines():
        word = line.strip().split(" ", 1)[0]
        if word == "{":
            stack.append(y)
        elif word == "}":
            y = stack.pop() if stack else 0.0
        elif word == "OFFSET":
            m = _OFFSET.match(line)
            if m is None:
                raise ValueError(f"bad OFFSET line: {line.strip()!r}")
            y = (stack[-1] if stack else 0.0) + float(m.group(2))
            heights.append(y)
    return (max(heights) - min(heights)) if heights else 0.0
