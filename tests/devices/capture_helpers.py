"""Shared helpers for the capture tests: waiting on threads without asserting wall times."""

import time


def wait_for(predicate, timeout=10.0, step=0.01):
    end = time.perf_counter() + timeout
    while time.perf_counter() < end:
        if predicate():
            return True
        time.sleep(step)
    return predicate()


def collect(device, n, timeout=10.0):
    """Drain the device's buffer until n samples have arrived."""
    out = []
    wait_for(lambda: out.extend(device.buffer.drain()) or len(out) >= n, timeout)
    return out
