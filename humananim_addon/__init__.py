"""The bridge between Blender and the solver: registration, settings, conversions, batch jobs.

Blender's modules are imported when Blender registers the add-on, not on import, so the bridge's
bpy-free parts (the device protocols in `devices`) import without Blender."""

_cli_handle = None


# The capabilities whose settings (property groups) register with the add-on, in order; capture's
# job wraps its settings' registration (it closes a running session on unregister).
SETTINGS = ("simulation.properties", "motion_control.properties", "sequence", "cloth.properties",
            "flexible.properties", "walking.properties", "capture.job", "hands.properties", "synthesis.properties")


def _settings_modules():
    import importlib
    return [importlib.import_module(f".{name}", __package__) for name in SETTINGS]


def register():
    global _cli_handle
    import bpy
    from . import cli, preferences, properties
    from .motion_control import overlay
    from .. import operators, panels  # they import the bridge: import them after it
    bpy.utils.register_class(preferences.HumanAnimPreferences)
    properties.register()
    for module in _settings_modules():
        module.register()
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
    from . import preferences, properties
    from .motion_control import overlay
    from .. import operators, panels
    if _cli_handle is not None:
        bpy.utils.unregister_cli_command(_cli_handle)
        _cli_handle = None
    overlay.unregister()
    panels.unregister()
    operators.unregister()
    for module in reversed(_settings_modules()):
        module.unregister()
    properties.unregister()
    bpy.utils.unregister_class(preferences.HumanAnimPreferences)
