"""`python -m humananim <command>`: the batch command line (needs the bpy module)."""

import sys

from .humananim_addon.cli import main

sys.exit(main(sys.argv[1:]))
