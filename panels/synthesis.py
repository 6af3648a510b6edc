"""Motion synthesis: transitions and dynamic reactions (issue 5): sidebar panel (being built)."""

CLASSES = ()
