"""Motion Queue (synthesis): the queue's settings and the job (job.py), the command line (cli.py)."""
