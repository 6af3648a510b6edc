"""Live capture (issue 10): operators (being built)."""

CLASSES = ()
