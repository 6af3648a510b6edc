"""Motion synthesis: transitions and dynamic reactions (issue 5): the bridge between Blender data and the solver (being built)."""


def register():
    pass


def unregister():
    pass
