"""Procedural walking (issue 11): sidebar panel (being built)."""

CLASSES = ()
