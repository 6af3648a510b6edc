"""The sequence tools' scene settings and the band analysis the panel shows."""

import bpy
from bpy.props import CollectionProperty, FloatProperty, IntProperty, StringProperty

from ..properties import settings_registration
from .equalize import MAX_LEVELS


class HumanAnimBand(bpy.types.PropertyGroup):
    label: StringProperty(name="Band")
    energy: FloatProperty(name="RMS")


class HumanAnimSequence(bpy.types.PropertyGroup):
    bands: CollectionProperty(type=HumanAnimBand)
    band_index: IntProperty()
    analysed: StringProperty(name="Analysed", description="The curve whose bands are listed")
    units: StringProperty()
    levels: IntProperty(name="Bands", default=0, min=0, max=MAX_LEVELS,
                        description="Pyramid levels to analyse (0: as many as the clip allows, up to 8)")


CLASSES = (HumanAnimBand, HumanAnimSequence)


def store_bands(props, label, labels, energies, units):
    props.bands.clear()
    for text, energy in zip(labels, energies):
        item = props.bands.add()
        item.label, item.energy = text, energy
    props.analysed, props.units = label, units


register, unregister = settings_registration(CLASSES, bpy.types.Scene, "humananim_sequence", HumanAnimSequence)
