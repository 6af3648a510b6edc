"""`python -m humananim <command>`: the batch command line (needs the bpy module)."""

import os
import sys

from .humananim_addon.cli import main

status = main(sys.argv[1:])
bpy = sys.modules.get("bpy")
if bpy is not None and bpy.app.version < (4, 3, 0):
    # The bpy 4.2 module can segfault in its interpreter teardown once add-on classes have been
    # registered, even after they are unregistered (a Blender bug; tests/conftest.py does the
    # same): leave with the command's own status once everything is written.
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(status)
sys.exit(status)
