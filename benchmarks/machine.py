"""The machine's speed, printed beside the figures it scales, and the benchmarks' common JSON
output.

A shared or throttled host (other guests, CPU taken by the hypervisor) can make every figure of
one run twice another's, so every result carries `machine_speed`: the CPU time of one small
numpy operation, measured in the same run. Every benchmark's `--json` prints one object

    {"benchmark": NAME, "date": ISO date, "machine_speed": {"numpy_add_us": ...},
     "claims": [{"claim", "value", "unit", "aim", "met"}, ...], ...other fields}

and writes it to benchmarks/results/NAME.json, where `python benchmarks/results.py` renders
benchmarks/RESULTS.md from it."""

import datetime
import json
import os
import time

import numpy as np

RESULTS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "results")


def numpy_op_us(count=20000):
    """CPU microseconds of one small numpy operation, a + b on (66, 3): the price of each of the
    many small calls the solvers make, so the indicator of how fast this host is right now."""
    a, b = np.random.rand(66, 3), np.random.rand(66, 3)
    t = time.process_time()
    for _ in range(count):
        a + b
    return (time.process_time() - t) / count * 1e6


def numpy_add_us(count=20000):
    """The results' machine-speed indicator: CPU microseconds of a + b on two 1000-float arrays,
    the fastest of three batches (a moment's load from another process counts as little as
    possible)."""
    a, b = np.random.rand(1000), np.random.rand(1000)
    best = np.inf
    for _ in range(3):
        t = time.process_time()
        for _ in range(count):
            a + b
        best = min(best, time.process_time() - t)
    return best / count * 1e6


def claim(text, value, unit, aim=None, met=None):
    """One line of RESULTS.md: what is claimed, the figure measured, and the aim it is held to
    (`met` None when there is no aim)."""
    value = None if value is None else float(value)
    return {"claim": text, "value": value, "unit": unit, "aim": aim, "met": None if met is None else bool(met)}


def result(name, claims, **fields):
    """The benchmark's JSON object: its name, today's date, the machine speed, the claims and
    any other fields."""
    return {"benchmark": name, "date": datetime.date.today().isoformat(),
            "machine_speed": {"numpy_add_us": round(numpy_add_us(), 4)}, "claims": list(claims), **fields}


def emit(obj, directory=RESULTS):
    """Print the object as one JSON line and write it to `directory`/<benchmark>.json (written
    to a temporary file first, so an interrupted run leaves the previous result)."""
    text = json.dumps(obj, default=_plain)
    print(text)
    os.makedirs(directory, exist_ok=True)
    path = os.path.join(directory, f"{obj['benchmark']}.json")
    with open(path + ".tmp", "w") as f:
        f.write(json.dumps(obj, indent=1, default=_plain) + "\n")
    os.replace(path + ".tmp", path)
    return path


def _plain(value):  # numpy scalars and arrays in a benchmark's extra fields
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")
