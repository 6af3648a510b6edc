"""The bridge between Blender and the solver: registration, settings, conversions, batch jobs.

Blender's modules are imported when Blender registers the add-on, not on import, so the bridge's
bpy-free parts (the device protocols in `devices`) import without Blender."""

_cli_handle = None


def register():
    global _cli_handle
    import bpy
    from . import cli, preferences, properties, sequence
    from .capture import job as capture
    from .cloth import job as cloth
    from .flexible import job as flexible
    from .hands import job as hands
    from .motion_control import job as motion_control
    from .motion_control import overlay
    from .simulation import job as simulation
    from .synthesis import job as synthesis
    from .walking import job as walking
    from .. import operators, panels  # they import the bridge: import them after it
    bpy.utils.register_class(preferences.HumanAnimPreferences)
    properties.register()
    simulation.register()
    motion_control.register()
    sequence.register()
    cloth.register()
    flexible.register()
    walking.register()
    capture.register()
    hands.register()
    synthesis.register()
    operators.register()
    panels.register()
    overlay.register()
    if hasattr(bpy.utils, "register_cli_command"):
        _cli_handle = bpy.utils.register_cli_command("humananim", cli.blender_command)
    prefs = preferences.get()
    if prefs:
        preferences.apply_log_level(prefs.log_level)


def unregister():
    global _cli_handle
    import bpy
    from . import preferences, properties, sequence
    from .capture import job as capture
    from .cloth import job as cloth
    from .flexible import job as flexible
    from .hands import job as hands
    from .motion_control import job as motion_control
    from .motion_control import overlay
    from .simulation import job as simulation
    from .synthesis import job as synthesis
    from .walking import job as walking
    from .. import operators, panels
    if _cli_handle is not None:
        bpy.utils.unregister_cli_command(_cli_handle)
        _cli_handle = None
    overlay.unregister()
    panels.unregister()
    operators.unregister()
    synthesis.unregister()
    hands.unregister()
    capture.unregister()
    walking.unregister()
    flexible.unregister()
    cloth.unregister()
    sequence.unregister()
    motion_control.unregister()
    simulation.unregister()
    properties.unregister()
    bpy.utils.unregister_class(preferences.HumanAnimPreferences)
