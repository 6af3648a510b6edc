"""Motion QA: measuring a result, storing and reading the report (job.py), the command line (cli.py)."""
