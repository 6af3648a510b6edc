"""Procedural walking along a path (Boulic's walking motor in Huang 1996, sec. 2.6 and 6.4.2) and
motion generators sharing a body (sec. 6.4.3-6.4.4)."""

from .model import PRESETS, Style, preset
from .path import Path, Progress, from_keys, progress_from_speed, speed_profile
from .generators import PRIORITIES, SCOPES, Actor, Generator, Stage, schedule, scope_bones, walk_generator
from .walk import WalkResult, flat_ground, iter_walk, walk

__all__ = ["PRESETS", "Style", "preset", "Path", "Progress", "from_keys", "progress_from_speed",
           "speed_profile", "WalkResult", "flat_ground", "iter_walk", "walk", "PRIORITIES", "SCOPES", "Actor",
           "Generator", "Stage", "schedule", "scope_bones", "walk_generator"]
