"""Walk along a path and the generator stack: the settings and the job (job.py), the command line (cli.py)."""
