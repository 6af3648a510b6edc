"""Simulate (closed-loop inverse dynamics): its settings (properties.py), the job (job.py), the command
`humananim simulate` (cli.py)."""
