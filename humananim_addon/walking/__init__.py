"""Walking along a path and the generator stack: the settings (properties.py), the job (job.py), the
command `humananim walk` (cli.py)."""
