"""Blender operators, one module per capability; each gathers through the bridge and reports."""

import bpy

from . import capture, cloth, flexible, hands, motion_control, rig, sequence, simulate, synthesis, qa, walking, cleanup

CLASSES = (rig.CLASSES + simulate.CLASSES + motion_control.CLASSES + sequence.CLASSES
           + cloth.CLASSES + flexible.CLASSES + walking.CLASSES + capture.CLASSES
           + hands.CLASSES + synthesis.CLASSES + qa.CLASSES + cleanup.CLASSES)

register, unregister = bpy.utils.register_classes_factory(CLASSES)
