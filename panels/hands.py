"""Hands: grasping, manipulation, self-collision (issue 9): sidebar panel (being built)."""

CLASSES = ()
