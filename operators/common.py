"""What every HumanAnim operator shares: the armature poll and user-error reporting."""

import logging

from ..solver.errors import HumanAnimError

log = logging.getLogger(__name__)


def active_armature(context):
    obj = context.active_object
    return obj if obj is not None and obj.type == "ARMATURE" else None


def run_reporting(operator, work):
    """Run `work()`; a user error becomes one message in the UI and the log, no traceback."""
    try:
        message = work()
    except HumanAnimError as error:
        log.error("%s: %s", operator.bl_idname, error)
        operator.report({"ERROR"}, str(error))
        return {"CANCELLED"}
    if message:
        log.info("%s: %s", operator.bl_idname, message)
        operator.report({"INFO"}, message)
    return {"FINISHED"}
