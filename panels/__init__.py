"""Sidebar panels: View3D > Sidebar > HumanAnim, one panel per capability."""

import bpy

from . import capture, cloth, common, flexible, hands, motion_control, rig, sequence, simulate, synthesis, qa, walking, cleanup

CLASSES = (common.CLASSES + rig.CLASSES + simulate.CLASSES + motion_control.CLASSES + sequence.CLASSES
           + cloth.CLASSES + flexible.CLASSES + walking.CLASSES + capture.CLASSES
           + hands.CLASSES + synthesis.CLASSES + qa.CLASSES + cleanup.CLASSES)

register, unregister = bpy.utils.register_classes_factory(CLASSES)
