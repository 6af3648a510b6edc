"""Writes the rig fixtures of tests/solver/test_dynamics_closed_loop_rigs.py from pickled
(Skeleton, Trajectories) pairs that the Blender bridge built (humananim_addon.armature and
.actions), so that the tests need no Blender:

    python3 tests/data/dynamics/make_fixtures.py CMU.pkl METARIG.pkl

cmu_131_01.npz: CMU clip 131_01 imported by Blender's BVH importer (31 bones, de Leva masses for
70 kg), frames 1-200 of 120 fps. metarig_legs.npz: Rigify's human metarig (159 bones, fingers
included, face bones massless), 90 frames at 30 fps of a keyed leg and arm motion.
"""

import json
import pickle
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).parent


def save(path, skeleton, trajectories, frames=None):
    sk, tr = skeleton, trajectories
    s = slice(None) if frames is None else slice(0, frames)
    np.savez_compressed(
        path, names=np.array(sk.names), parents=sk.parents, rest=sk.rest, lengths=sk.lengths,
        connected=sk.connected, dof=sk.dof, limits=sk.limits, mass=sk.mass, com=sk.com,
        inertia=sk.inertia, roles=json.dumps({k: list(v) for k, v in sk.roles.bones.items()}),
        unit_scale=sk.unit_scale, frames=tr.frames[s], fps=tr.fps, rotations=tr.rotations[s],
        translations=tr.translations[s], armature_to_world=tr.armature_to_world)


if __name__ == "__main__":
    cmu, metarig = sys.argv[1:3]
    save(HERE / "cmu_131_01.npz", *pickle.load(open(cmu, "rb")), frames=200)
    save(HERE / "metarig_legs.npz", *pickle.load(open(metarig, "rb")))
