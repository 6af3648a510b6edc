"""Flexible characters (issue 8): the bridge between Blender data and the solver (being built)."""


def register():
    pass


def unregister():
    pass
