"""Hands: grasp, follow, hold and self-collision: the settings and the job (job.py), the command line (cli.py)."""
