"""Rigs and paths shared by the walking tests: the Rigify metarig's skeleton (fixture) and a CMU
skeleton read from the bundled BVH by solver/bvh.py; a straight line, an S curve, a speed ramp
0.5 -> 2 m/s and a bumpy ground."""

from functools import lru_cache
from pathlib import Path as FilePath

import numpy as np

from humananim.solver.walking import Path, clip, walk

from test_dynamics_closed_loop_rigs import load

CMU_BVH = FilePath(__file__).parents[2] / "humananim_addon" / "data" / "mocap" / "cmu_131_01.bvh"
FPS = 24.0


@lru_cache(maxsize=None)
def rig(name):
    if name == "metarig":
        return load("metarig_legs")[0]
    return clip.load_bvh(str(CMU_BVH))[0]


def s_curve(length=8.0, amplitude=1.0, n=200):
    x = np.linspace(0.0, length, n)
    return np.column_stack((x, amplitude * np.sin(2 * np.pi * x / length), np.zeros(n)))


def bumps(x, y):
    return 0.06 * np.sin(1.3 * np.asarray(x)) * np.cos(0.9 * np.asarray(y)) + 0.03 * np.sin(3.1 * np.asarray(x) + 0.5)


CASES = {
    "straight": dict(path=[[0, 0, 0], [6, 0, 0]], speed=1.3),
    "s_curve": dict(path=s_curve(), speed=1.2),
    "ramp": dict(path=[[0, 0, 0], [14, 0, 0]], speed_keys=[(0, 0.5), (2, 0.5), (11, 2.0), (14, 2.0)]),
    "bumpy": dict(path=s_curve(), speed=1.2, ground=bumps),
}


@lru_cache(maxsize=None)
def walked(rig_name, case):
    kw = dict(CASES[case])
    path = Path.from_points(kw.pop("path"))
    return walk(rig(rig_name), path, fps=FPS, **kw)
