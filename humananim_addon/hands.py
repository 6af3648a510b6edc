"""Hands: grasping, manipulation, self-collision (issue 9): the bridge between Blender data and the solver (being built)."""


def register():
    pass


def unregister():
    pass
