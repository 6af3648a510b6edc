"""Blender operators, one module per capability; each gathers through the bridge and reports."""

import bpy

from . import rig, sequence, simulate

CLASSES = rig.CLASSES + simulate.CLASSES + sequence.CLASSES

register, unregister = bpy.utils.register_classes_factory(CLASSES)
