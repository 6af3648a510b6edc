"""Hands: grasp, follow, hold and self-collision: the settings (properties.py), the job (job.py), the
command `humananim grasp` (cli.py)."""
