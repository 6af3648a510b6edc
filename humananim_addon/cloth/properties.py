"""The Cloth panel's settings on the scene (scene.humananim_cloth)."""

import bpy
from bpy.props import (BoolProperty, EnumProperty, FloatProperty, FloatVectorProperty, IntProperty, PointerProperty,
                       StringProperty)

from ...solver.cloth import ClothParams, PRESETS
from ..properties import settings_registration

_RELATIVE = {"PATH_SUPPORTS_BLEND_RELATIVE"} if bpy.app.version >= (4, 5, 0) else set()


class HumanAnimCloth(bpy.types.PropertyGroup):
    garment: PointerProperty(name="Garment", type=bpy.types.Object,
                             description="The coarse garment mesh (tens to a few hundred vertices)")
    pin_group: StringProperty(name="Pinned Group", default="waist",
                              description="Vertex group of the garment that follows the body (e.g. a waistband)")
    armature: PointerProperty(name="Armature", type=bpy.types.Object,
                              description="The character's armature: pinned vertices follow its bones")
    body: PointerProperty(name="Body Mesh", type=bpy.types.Object,
                          description="The character's skinned mesh to collide with (empty: capsules on the bones)")
    collider: EnumProperty(name="Collide With", items=(
        ("AUTO", "Auto", "The body mesh when one is set, else capsules fitted to the bones"),
        ("MESH", "Body Mesh", "The evaluated (skinned) body mesh, every frame"),
        ("CAPSULES", "Capsules", "Capsules on the bones by body role (radii fitted to the body mesh if set)"),
        ("BOTH", "Both", "The body mesh and the capsules"),
        ("NONE", "None", "No collisions"),
    ), default="AUTO")
    level: IntProperty(name="Smoothing Level", default=2, min=1, max=8,
                       description="Segments per side of each of the four sub-patches: every coarse face "
                                   "becomes 4 x level^2 triangles")
    normal_control: BoolProperty(name="Normal Control", default=True,
                                 description="Particle normals weighted by the elastic forces (eq. 4.3)")
    edge_control: BoolProperty(name="Edge Length Control", default=True,
                               description="Shortened edges fold so their curves keep the rest length")
    preset: EnumProperty(name="Material", items=(
        ("COTTON", "Light Cotton", "Light and soft, waves freely"),
        ("DENIM", "Denim", "Heavier, stiffer in bending"),
        ("LEATHER", "Leather", "Heavy and stiff"),
        ("CUSTOM", "Custom", "The values below"),
    ), default="COTTON")  # no update callback: one on an EnumProperty crashes the bpy 4.2 module at exit
    density: FloatProperty(name="Density", default=PRESETS["COTTON"].density, min=0.01, soft_max=2.0,
                           description="kg per square metre")
    stretch: FloatProperty(name="Stretch Stiffness", default=PRESETS["COTTON"].stretch, min=0.0, soft_max=1000.0,
                           description="k_elastic of eq. 4.1, N/m (capped to what the time step keeps stable)")
    bend: FloatProperty(name="Bending", default=PRESETS["COTTON"].bend, min=0.0, soft_max=50.0, description="N/m")
    damping: FloatProperty(name="Damping", default=PRESETS["COTTON"].damping, min=0.0, soft_max=1.0,
                           description="Along the edges, N s/m")
    drag: FloatProperty(name="Air Drag", default=PRESETS["COTTON"].drag, min=0.0, soft_max=3.0,
                        description="Drag coefficient of the cloth moving across the air")
    air_damping: FloatProperty(name="Air Damping", default=PRESETS["COTTON"].air_damping, min=0.0, soft_max=5.0,
                               description="Damping of the absolute velocity, 1/s")
    wind: FloatVectorProperty(name="Wind", size=3, subtype="VELOCITY", unit="VELOCITY", default=(0.0, 0.0, 0.0))
    thickness: FloatProperty(name="Thickness", default=ClothParams.thickness, min=0.0, soft_max=0.05, unit="LENGTH",
                             description="Distance kept between the cloth and the body")
    compress_limit: FloatProperty(name="Compression Limit", default=ClothParams.compress_limit, min=0.0, max=0.5,
                                  subtype="FACTOR",
                                  description="Shortening of an edge beyond this share is undone in the simulation; "
                                              "up to it the smoothing folds the edge (0: all left to the smoothing, "
                                              "as in the thesis)")
    friction: FloatProperty(name="Friction", default=ClothParams.friction, min=0.0, max=1.0,
                            description="Share of the sliding speed lost in a contact")
    substeps: IntProperty(name="Substeps", default=ClothParams.substeps, min=1, max=64, description="RK4 steps per simulated frame")
    frame_start: IntProperty(name="Start", default=0, description="0: the scene's start")
    frame_end: IntProperty(name="End", default=0, description="0: the scene's end")
    frame_step: IntProperty(name="Step", default=0, min=0, max=16,
                            description="Simulate every Nth frame and interpolate between (0: about 30 per second)")
    keep_coarse: BoolProperty(name="Keep Coarse", default=False,
                              description="Also write the coarse simulated mesh (with its own point cache)")
    cache_dir: StringProperty(name="Cache Folder", default="//cloth_cache", subtype="DIR_PATH", options=_RELATIVE,
                              description="Where the PC2 files go ('//' is the .blend's folder; a temporary "
                                          "folder while the file is unsaved)")


CLASSES = (HumanAnimCloth,)

register, unregister = settings_registration(CLASSES, bpy.types.Scene, "humananim_cloth", HumanAnimCloth)
