"""Procedural walking (issue 11): the bridge between Blender data and the solver (being built)."""


def register():
    pass


def unregister():
    pass
