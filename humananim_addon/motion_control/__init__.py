"""Dynamic Control: the animator's settings (job.py's property groups), the job that reads the rig and the
action, runs the controller and writes the result (job.py), the command line (cli.py) and the viewport overlay and
result pictures (overlay.py)."""
