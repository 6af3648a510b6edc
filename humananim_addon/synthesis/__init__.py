"""The Motion Queue (synthesis): the queue's settings (properties.py), the job (job.py), the command
`humananim synthesize` (cli.py)."""
