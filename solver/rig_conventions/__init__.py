"""Bone-name tables of known rig conventions, one module per convention.

Each module holds TABLES: convention name -> {role: bone name or tuple of bone names}.
A chain role (spine, fingers) lists its bones proximal to distal; a single role may list
several alternatives (the first one present is taken). Names are matched exactly, then
with any namespace (`mixamorig:`, `mixamorig1:`) stripped, then case-insensitively.
Roles follow solver.body_roles; the rules for which bone carries a role are in
solver.role_detection.
"""

from . import bvh_cmu, bvh_common, mixamo, rigify_generated, rigify_metarig


# Order matters only on ties: the first table wins.
MODULES = (rigify_metarig, rigify_generated, mixamo, bvh_cmu, bvh_common)


def all_tables():
    tables = {}
    for module in MODULES:
        tables.update(module.TABLES)
    return tables
