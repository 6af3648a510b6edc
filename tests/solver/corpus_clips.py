"""Clips of Bandai Namco's motion dataset (../shared/data/mocap/bandai-namco-1/ beside the repo;
CC BY-NC 4.0: read in tests only, never copied into the repo) as the solver's skeleton and
trajectories, read the way the add-on sees them after Blender's BVH importer: bones found by role
detection, de Leva's segment masses, and a zero-length leaf bone (Bandai's hands, toes and head
end in a zero End Site) continuing its parent's line at its parent's length, as Blender makes it.
Tests skip with a reason when the corpus is absent."""

from dataclasses import replace
from functools import lru_cache
from pathlib import Path

import numpy as np
import pytest

from humananim.solver import bvh
from humananim.solver.anthropometry import anthropometric_model
from humananim.solver.dynamics.figures import bone_frame
from humananim.solver.role_detection import detect_roles

CORPUS = Path(__file__).resolve().parents[3] / "shared" / "data" / "mocap" / "bandai-namco-1"


def path(name):
    p = CORPUS / f"dataset-1_{name}.bvh"
    if not p.exists():
        pytest.skip(f"the Bandai Namco corpus is not at {CORPUS} (clip {p.name})")
    return p


def blender_tails(clip):
    """Tails as Blender's importer makes them: a zero-length bone continues its parent's line."""
    heads, tails = bvh.rest_heads(clip), bvh.rest_tails(clip, min_length=0.0)
    for j, p in enumerate(clip.parents):
        if np.linalg.norm(tails[j] - heads[j]) < 1e-6 and p >= 0:
            tails[j] = heads[j] + (tails[p] - heads[p])
    return heads, tails


@lru_cache(maxsize=None)
def load(name, total_mass=70.0):
    """(skeleton, trajectories) of a corpus clip, e.g. load("walk_normal_001")."""
    clip = bvh.read(str(path(name)), 0.01)  # the corpus is in centimetres
    heads, tails = blender_tails(clip)
    roles = detect_roles(clip.names, clip.parents, heads, tails).roles
    sk = bvh.skeleton(clip, roles=roles)
    rest = np.array([bone_frame(h, t) for h, t in zip(heads, tails)])
    sk = replace(sk, rest=rest, lengths=np.linalg.norm(tails - heads, axis=1))
    sk = sk.with_mass_model(*anthropometric_model(sk, total_mass))
    return sk, with_joint_positions(clip, sk, bvh.trajectories(clip, sk))


def with_joint_positions(clip, sk, traj):
    """The position channels of joints below the root (Bandai's hips move by them) as pose-bone
    locations, as Blender's importer keys them: the head's offset from its rest place, in the
    bone's rest axes."""
    trans = traj.translations.copy()
    col = 0
    for j, chans in enumerate(clip.channels):
        pos = [i for i, c in enumerate(chans) if c.lower().endswith("position")]
        if pos and clip.parents[j] >= 0:
            p = np.zeros((len(clip.values), 3))
            for i in pos:
                p[:, bvh._AXES[chans[i][0].upper()]] = clip.values[:, col + i]
            d = p @ bvh.Y_UP_TO_Z_UP.T * 0.01 - clip.offsets[j]
            trans[:, j] = d @ sk.rest[j, :3, :3]
        col += len(chans)
    return replace(traj, translations=trans)


def window(traj, start, stop):
    """Frames [start, stop) of a motion (0-based indices), renumbered from 1."""
    return replace(traj, frames=np.arange(1, stop - start + 1), rotations=traj.rotations[start:stop],
                   translations=traj.translations[start:stop])
