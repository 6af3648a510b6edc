"""Fast plausible cloth (Oshita 2003, chapter 4): a coarse particle simulation (RK4, springs,
bending, drag, Provot elongation limits, body collisions) and a geometric smoothing (PN
triangles, particle normal control, edge length control) that turns a few dozen particles into
a detailed surface. numpy and scipy only."""

from .body import CapsuleSpec, capsule_ends, capsule_mesh, capsules_from_roles, fit_radii
from .collision import CapsuleBody, MeshBody, penetration, resolve_contacts
from .dynamics import ClothDynamics
from .materials import PRESETS, ClothParams, preset
from .mesh import ClothError, ClothMesh, build_mesh, edge_lengths
from .pc2 import read_pc2, write_pc2
from .simulation import ClothSimulation
from .skirt import fit_skirt, skirt_mesh
from .smoothing import Smoother, controlled_normals, edge_midpoints, tessellation
