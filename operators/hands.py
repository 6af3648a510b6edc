"""Hands: grasping, manipulation, self-collision (issue 9): operators (being built)."""

CLASSES = ()
