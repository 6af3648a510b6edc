"""Sidebar panels: View3D > Sidebar > HumanAnim, one panel per capability."""

import bpy

from . import rig, sequence, simulate

CLASSES = rig.CLASSES + simulate.CLASSES + sequence.CLASSES


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)


def unregister():
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
