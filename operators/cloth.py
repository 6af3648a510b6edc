"""Fast plausible cloth (issue 7): operators (being built)."""

CLASSES = ()
