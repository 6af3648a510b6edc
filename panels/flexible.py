"""Flexible characters (issue 8): sidebar panel (being built)."""

CLASSES = ()
