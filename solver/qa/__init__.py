"""Motion QA: measures of every result against its input (slide of planted feet, points below
the ground, pops, bone lengths, figure height, NaN, the source untouched), with the thresholds
in `thresholds` and warnings naming frames and bones. numpy only; see docs/qa.md."""

from . import thresholds
from .measures import Motion, angular_rates, checksum, contact_slides, estimate_floor, feet_from_roles, measure
from .report import describe, rows, summary_line, text, warnings

__all__ = ["Motion", "measure", "feet_from_roles", "checksum", "warnings", "summary_line", "text", "describe",
           "thresholds", "rows", "angular_rates", "contact_slides", "estimate_floor"]
