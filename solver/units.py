"""Guessing the length unit of motion files, so rigs in cm, mm or inches come out in metres; a
figure no common unit makes human-sized is refused with its measured height and the --scale
that would make it 1.7 m tall."""

import numpy as np

from .errors import MotionError

# (metres per file unit, name), most likely first
LENGTH_UNITS = ((1.0, "m"), (0.01, "cm"), (0.0254, "in"), (0.001, "mm"), (0.1, "dm"))
# metres: the joint-centre height (ankle to the top of the head joint) of a child to a very tall adult
HUMAN_HEIGHT = (1.0, 2.3)
TYPICAL_HEIGHT = 1.7


def guess_length_scale(extent):
    """(metres per unit, unit name) for a figure `extent` file units tall. Raises MotionError
    when no common unit makes it 1.0-2.3 m tall."""
    if not np.isfinite(extent) or extent <= 0.0:
        raise MotionError(f"the figure has no height ({extent:g} file units): the file's skeleton is "
                          "flat or empty; pass --scale (metres per file unit)")
    for scale, name in LENGTH_UNITS:
        if HUMAN_HEIGHT[0] <= extent * scale <= HUMAN_HEIGHT[1]:
            return scale, name
    raise MotionError(refusal(extent))


def refusal(extent):
    """The message for a figure of `extent` file units that no common unit makes human-sized."""
    return (f"the figure is {extent:.4g} file units tall: in m, cm, in, mm or dm that is not "
            f"{HUMAN_HEIGHT[0]:g}-{HUMAN_HEIGHT[1]:g} m; pass --scale {TYPICAL_HEIGHT / extent:.4g} "
            f"(metres per file unit, for a {TYPICAL_HEIGHT:g} m figure)")


def bvh_rest_extent(text):
    """The figure's height in a BVH's file units (whatever its whitespace or line endings): the
    posed figure's vertical extent when the file has motion (a rest pose may lie on its side),
    else the rest skeleton's. Raises MotionError for a broken file."""
    from . import bvh
    lines, motion, _ = bvh.split_motion(text)
    if not motion.split():
        names, parents, offsets, ends, _ = bvh.parse_hierarchy(lines)
        heads = np.zeros((len(names), 3))
        for j, p in enumerate(parents):
            heads[j] = offsets[j] + (heads[p] if p >= 0 else 0.0)
        tips = [heads[j] + e for j, e in enumerate(ends) if np.all(np.isfinite(e))]
        return float(np.ptp(np.concatenate((heads, tips))[:, 1])) if tips else float(np.ptp(heads[:, 1]))
    return bvh.figure_height(bvh.parse(text))
