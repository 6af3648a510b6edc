"""Live capture: the device and session settings (properties.py), the live session and its devices
(job.py), its viewport drawing (drawing.py), the command `humananim capture` (cli.py)."""
