"""Cloth on the character: the settings and the job (job.py), the command line (cli.py)."""
