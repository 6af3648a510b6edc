"""Procedural walking (issue 11): operators (being built)."""

CLASSES = ()
