"""Live capture (issue 10): sidebar panel (being built)."""

CLASSES = ()
