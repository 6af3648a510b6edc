"""Blender operators, one module per capability; each gathers through the bridge and reports."""

import bpy

from . import motion_control, rig, sequence, simulate

CLASSES = rig.CLASSES + simulate.CLASSES + motion_control.CLASSES + sequence.CLASSES

register, unregister = bpy.utils.register_classes_factory(CLASSES)
