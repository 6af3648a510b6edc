"""Add-on preferences, keyed by the extension's package."""

import bpy
from bpy.props import EnumProperty

PACKAGE = __package__.rpartition(".")[0]


class HumanAnimPreferences(bpy.types.AddonPreferences):
    bl_idname = PACKAGE

    log_level: EnumProperty(name="Log Level", items=(
        ("WARNING", "Warnings", ""), ("INFO", "Info", ""), ("DEBUG", "Debug", "")), default="INFO",
        update=lambda self, _ctx: apply_log_level(self.log_level))

    def draw(self, _context):
        self.layout.prop(self, "log_level")


def apply_log_level(level):
    import logging
    logging.getLogger(PACKAGE).setLevel(level)


def get(context=None):
    context = context or bpy.context
    addon = context.preferences.addons.get(PACKAGE)
    return addon.preferences if addon else None
