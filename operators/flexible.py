"""Flexible characters (issue 8): operators (being built)."""

CLASSES = ()
