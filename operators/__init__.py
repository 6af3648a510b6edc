"""Blender operators, one module per capability; each gathers through the bridge and reports."""

import bpy

from . import capture, cloth, flexible, motion_control, rig, sequence, simulate, walking

CLASSES = (rig.CLASSES + simulate.CLASSES + motion_control.CLASSES + sequence.CLASSES
           + cloth.CLASSES + flexible.CLASSES + walking.CLASSES + capture.CLASSES)

register, unregister = bpy.utils.register_classes_factory(CLASSES)
