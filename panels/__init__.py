"""Sidebar panels: View3D > Sidebar > HumanAnim, one panel per capability."""

import bpy

from . import motion_control, rig, sequence, simulate

CLASSES = rig.CLASSES + simulate.CLASSES + motion_control.CLASSES + sequence.CLASSES

register, unregister = bpy.utils.register_classes_factory(CLASSES)
