"""Fast plausible cloth (issue 7): sidebar panel (being built)."""

CLASSES = ()
