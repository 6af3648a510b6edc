"""Retarget Motion (issue 25 item 3): a source armature's motion put on another rig's controls."""
