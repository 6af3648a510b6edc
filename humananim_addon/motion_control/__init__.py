"""Dynamic Control (Oshita 2003): its settings (properties.py), the job that reads the rig and the action,
runs the controller and writes the result with its stress curves (job.py), the command `humananim control`
(cli.py) and the viewport overlay and result pictures (overlay.py)."""
