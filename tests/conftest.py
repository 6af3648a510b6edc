"""Test-wide hooks."""

import os
import sys

_exit_status = {}


def pytest_sessionfinish(session, exitstatus):
    _exit_status["code"] = int(exitstatus)


def pytest_unconfigure(config):
    # The bpy 4.2 module segfaults at interpreter exit once an add-on such as Rigify has been
    # enabled (even after disabling it): a Blender bug, not ours. Leave with pytest's own status
    # after all reporting is done, skipping the interpreter's teardown.
    bpy = sys.modules.get("bpy")
    if bpy is not None and bpy.app.version < (4, 3, 0) and "code" in _exit_status:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(_exit_status["code"])
