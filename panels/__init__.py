"""Sidebar panels: View3D > Sidebar > HumanAnim, one panel per capability."""

import bpy

from . import batch, capture, cleanup, cloth, common, flexible, hands, motion_control, qa, retarget, rig, sequence, simulate, synthesis, walking

CLASSES = (common.CLASSES + rig.CLASSES + cleanup.CLASSES + simulate.CLASSES + motion_control.CLASSES
           + sequence.CLASSES + cloth.CLASSES + flexible.CLASSES + walking.CLASSES + capture.CLASSES
           + hands.CLASSES + synthesis.CLASSES + retarget.CLASSES + qa.CLASSES + batch.CLASSES)

register, unregister = bpy.utils.register_classes_factory(CLASSES)
