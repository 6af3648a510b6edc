"""Simulate (inverse dynamics): the settings and the job (job.py); its command line is in cli.py."""
