"""HumanAnim: physics-based human animation for Blender.

The tree is both the Blender extension and the development package `humananim`; importing
the solver must not import bpy, so registration is imported only when Blender asks for it.
"""


def register():
    from .humananim_addon import register as _register
    _register()


def unregister():
    from .humananim_addon import unregister as _unregister
    _unregister()
