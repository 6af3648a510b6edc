"""Add-on preferences, keyed by the extension's package."""

import bpy
from bpy.props import EnumProperty, FloatProperty

PACKAGE = __package__.rpartition(".")[0]


class HumanAnimPreferences(bpy.types.AddonPreferences):
    bl_idname = PACKAGE

    default_total_mass: FloatProperty(name="Default Body Mass", unit="MASS", default=70.0, min=1.0,
                                      description="Total mass given to a rig the first time it is used")
    log_level: EnumProperty(name="Log Level", items=(
        ("WARNING", "Warnings", ""), ("INFO", "Info", ""), ("DEBUG", "Debug", "")), default="INFO",
        update=lambda self, _ctx: apply_log_level(self.log_level))

    def draw(self, _context):
        col = self.layout.column()
        col.prop(self, "default_total_mass")
        col.prop(self, "log_level")


def apply_log_level(level):
    import logging
    logging.getLogger(PACKAGE).setLevel(level)


def get(context=None):
    context = context or bpy.context
    addon = context.preferences.addons.get(PACKAGE)
    return addon.preferences if addon else None
