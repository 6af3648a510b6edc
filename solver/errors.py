"""Errors a user can fix: shown as one clear message, never as a traceback."""


class HumanAnimError(Exception):
    """Base class for problems with the user's input (rig, action, file, device)."""


class RigError(HumanAnimError):
    """The armature cannot be used: missing roles, bad scale, no bones."""


class MotionError(HumanAnimError):
    """The motion cannot be used: no action, NaN keys, empty frame range."""
