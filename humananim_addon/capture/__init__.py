"""Live capture: the device settings and the live session (job.py), its viewport drawing (drawing.py), the
command line (cli.py)."""
