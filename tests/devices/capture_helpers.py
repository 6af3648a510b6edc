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


def drained(devices, quiet=0.2, timeout=30.0):
    """Wait until the devices' readers have taken every record on the line (no new sample for
    `quiet` seconds, the senders being stopped): a loaded machine reads late, not less."""
    last, since = None, time.perf_counter()
    end = since + timeout
    while time.perf_counter() < end:
        now = tuple(d.seq for d in devices)
        if now != last:
            last, since = now, time.perf_counter()
        elif time.perf_counter() - since >= quiet:
            return True
        time.sleep(0.01)
    return False
