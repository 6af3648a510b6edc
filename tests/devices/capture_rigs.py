"""Small synthetic rigs for the capture tests: a right hand (palm up, fingers along +X, curling
toward +Z) and access to the CMU clip's skeleton."""

import numpy as np

from humananim.solver import rotations
from humananim.solver.body_roles import RoleMap
from humananim.solver.dynamics.figures import bone_frame
from humananim.solver.skeleton import Skeleton

FINGER_ROOTS = {"index": (0.03, 0.0), "middle": (0.01, 0.0), "ring": (-0.01, 0.0), "pinky": (-0.03, 0.0)}


def hand_skeleton():
    names, parents, heads, tails = ["hand"], [-1], [np.zeros(3)], [np.array([0.08, 0.0, 0.0])]
    roles = {"hand.R": ("hand",)}
    for f, (y, _) in FINGER_ROOTS.items():
        start, parent = np.array([0.08, y, 0.0]), 0
        chain = []
        for k, length in enumerate((0.03, 0.025, 0.02)):
            name = f"{f}.{k}"
            names.append(name), parents.append(parent), heads.append(start)
            tails.append(start + [length, 0, 0])
            parent, start = len(names) - 1, start + [length, 0, 0]
            chain.append(name)
        roles[f"{f}.R"] = tuple(chain)
    d = np.array([0.6, -1.0, 0.0]) / np.linalg.norm([0.6, -1.0, 0.0])  # opposed thumb across the palm
    start, parent, chain = np.array([0.02, 0.05, 0.0]), 0, []
    for k, length in enumerate((0.03, 0.028, 0.022)):
        name = f"thumb.{k}"
        names.append(name), parents.append(parent), heads.append(start), tails.append(start + length * d)
        parent, start = len(names) - 1, start + length * d
        chain.append(name)
    roles["thumb.R"] = tuple(chain)
    rest = np.array([bone_frame(h, t) for h, t in zip(heads, tails)])
    # roll so that +X rotations curl every finger toward +Z (the palm's side)
    for j, (h, t) in enumerate(zip(heads, tails)):
        y = (t - h) / np.linalg.norm(t - h)
        x = np.cross(y, [0, 0, 1.0])
        x /= np.linalg.norm(x)
        rest[j, :3, :3] = np.column_stack((x, y, np.cross(x, y)))
    n = len(names)
    lengths = np.linalg.norm(np.array(tails) - np.array(heads), axis=1)
    lim = np.zeros((n, 3, 2))
    lim[..., 0], lim[..., 1] = -np.inf, np.inf
    return Skeleton(names, np.array(parents), rest, lengths, np.array([p >= 0 for p in parents]),
                    np.ones((n, 3), bool), lim, np.ones(n), np.zeros((n, 3)), np.tile(np.eye(3), (n, 1, 1)),
                    RoleMap(roles))


def curled_basis(skeleton, amount):
    """Every finger joint flexed by `amount` of a fist about its X axis (toward the palm's side)."""
    basis = np.tile(np.eye(4), (skeleton.joint_count, 1, 1))
    for j, name in enumerate(skeleton.names):
        if name == "hand":
            continue
        k = int(name.split(".")[1])
        angle = np.radians((50, 70, 60)[k] if name.startswith("thumb") else (85, 100, 70)[k]) * amount
        basis[j, :3, :3] = rotations.to_matrix(rotations.axis_rotation(0, angle))
    return basis
