"""Cloth on the character: the settings (properties.py), the job (job.py), the command `humananim cloth`
(cli.py)."""
