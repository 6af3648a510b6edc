"""Motion synthesis: transitions and dynamic reactions (issue 5): operators (being built)."""

CLASSES = ()
