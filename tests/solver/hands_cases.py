"""Shared rigs and objects for the hands tests: the Rigify human metarig skeleton (fingers
included) from tests/data/dynamics/metarig_legs.npz, standing in its first frame."""

import functools
import json
from pathlib import Path

import numpy as np

from humananim.solver.body_roles import RoleMap
from humananim.solver.hands.primitives import Box, Cylinder, Frustum, Sphere
from humananim.solver.skeleton import Skeleton

DATA = Path(__file__).parent.parent / "data" / "dynamics"


@functools.lru_cache(maxsize=None)
def metarig():
    z = np.load(DATA / "metarig_legs.npz")
    roles = RoleMap({k: tuple(v) for k, v in json.loads(str(z["roles"])).items()})
    sk = Skeleton(names=tuple(str(n) for n in z["names"]), parents=z["parents"], rest=z["rest"],
                  lengths=z["lengths"], connected=z["connected"], dof=z["dof"], limits=z["limits"],
                  mass=z["mass"], com=z["com"], inertia=z["inertia"], roles=roles,
                  unit_scale=float(z["unit_scale"]))
    from humananim.solver.skeleton import compose
    basis = compose(z["translations"][0], z["rotations"][0])
    return sk, basis, np.asarray(z["armature_to_world"], float)


def frame(p, rot=None):
    f = np.eye(4)
    f[:3, 3] = p
    if rot is not None:
        f[:3, :3] = rot
    return f


# within reach of the right hand, in front of the chest, of the left hand (the metarig faces -Y)
SPOTS = ((-0.25, -0.35, 1.15), (-0.12, -0.42, 1.3), (0.25, -0.35, 1.15))


def object_cases():
    """Spheres, boxes, cylinders and frusta from 1 cm to 60 cm (size = the smallest extent),
    within reach around the character; the large ones in front of the chest."""
    out = []
    for s in (0.01, 0.02, 0.04, 0.08, 0.2, 0.4, 0.6):
        spots = SPOTS if s < 0.03 else SPOTS[:2] if s < 0.12 else [(0.0, -0.3 - 0.5 * s, 1.3)]
        for p in spots:
            out += [("sphere", s, p, Sphere(np.array(p, float), s / 2)),
                    ("box", s, p, Box(frame(p), np.array([s / 2, 0.75 * s, s]))),
                    ("cylinder", s, p, Cylinder(frame(p), s / 2, s)),
                    ("frustum", s, p, Frustum(frame(p), s / 2, 0.35 * s, 0.75 * s))]
    # a card (thin box: lateral) and a jar lid (short wide cylinder: disk)
    out += [("card", 0.006, SPOTS[0], Box(frame(SPOTS[0]), np.array([0.003, 0.025, 0.04]))),
            ("lid", 0.02, SPOTS[0], Cylinder(frame(SPOTS[0]), 0.05, 0.01)),
            ("lid", 0.024, SPOTS[1], Cylinder(frame(SPOTS[1]), 0.045, 0.012))]
    return out


# the thesis's table (sec. 4.3.2) on these objects, for an adult hand of ~0.2 m: what a person
# would do, written out case by case (not computed by the code under test)
EXPECTED = {
    ("sphere", 0.01): ("PINCH", 1), ("sphere", 0.02): ("PINCH", 1), ("sphere", 0.04): ("TRIPOD", 1),
    ("sphere", 0.08): ("WRAP", 1),
    ("box", 0.01): ("PINCH", 1), ("box", 0.02): ("PINCH", 1), ("box", 0.04): ("PINCH", 1), ("box", 0.08): ("PINCH", 1),
    ("cylinder", 0.01): ("PINCH", 1), ("cylinder", 0.02): ("PINCH", 1), ("cylinder", 0.04): ("PINCH", 1),
    ("cylinder", 0.08): ("WRAP", 1),
    ("frustum", 0.01): ("PINCH", 1), ("frustum", 0.02): ("PINCH", 1), ("frustum", 0.04): ("PINCH", 1),
    ("frustum", 0.08): ("WRAP", 1),
    ("card", 0.006): ("LATERAL", 1), ("lid", 0.02): ("DISK", 1), ("lid", 0.024): ("DISK", 1),
}


def expected(name, size):
    """Large objects (20 cm and more across their smallest side) take two hands."""
    return EXPECTED.get((name, size), ("WRAP", 2))


def crossed_legs(sk, basis, frames=30, cross=0.45, lift=0.1, extend=0.7):
    """Keyframed legs on the metarig: both legs go from standing to a seated pose (hips and knees
    flexed 1.5 rad, the pelvis left where it is) over the first half, then the left leg crosses
    over the right (its hip turns `cross` rad, its knee opens `extend` rad) and its knee and shin
    go through the right thigh and knee. With `extend` 0 the left ankle ends inside the right
    shin too (its goal is inside the body)."""
    from humananim.solver.hands.ik import matrix_xyz

    idx = {r: sk.role_index(r) for r in ("thigh.L", "shin.L", "thigh.R", "shin.R")}
    half = frames // 2
    out = []
    for t in range(frames):
        s1, s2 = min(1.0, t / half), max(0.0, (t - half) / (frames - 1 - half))
        s1, s2 = s1 * s1 * (3 - 2 * s1), s2 * s2 * (3 - 2 * s2)
        b = basis.copy()
        for side in ("L", "R"):
            th, sh = idx[f"thigh.{side}"], idx[f"shin.{side}"]
            b[th, :3, :3] = basis[th, :3, :3] @ matrix_xyz([-1.5 * s1, 0, 0])
            b[sh, :3, :3] = basis[sh, :3, :3] @ matrix_xyz([1.5 * s1, 0, 0])
        b[idx["thigh.L"], :3, :3] = b[idx["thigh.L"], :3, :3] @ matrix_xyz([-lift * s2, 0, cross * s2])
        b[idx["shin.L"], :3, :3] = b[idx["shin.L"], :3, :3] @ matrix_xyz([-extend * s2, 0, 0])
        out.append(b)
    return np.array(out)
