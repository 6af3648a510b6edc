"""Flexible characters (lattice modes): the settings (properties.py), the job (job.py), the command
`humananim flexible` (cli.py)."""
