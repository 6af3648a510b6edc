"""Flexible bodies (lattice modes): the settings and the job (job.py), the command line (cli.py)."""
