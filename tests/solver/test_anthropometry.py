"""de Leva's segments on rigs whose bone tails are the importer's guess (the CMU wrists)."""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from humananim.solver import bvh
from humananim.solver.anthropometry import DE_LEVA, anthropometric_model
from humananim.solver.dynamics.figures import bone_frame
from humananim.solver.skeleton import reach_of_made_up_tail

CMU = Path(__file__).resolve().parents[2] / "humananim_addon" / "data" / "mocap" / "cmu_131_01.bvh"


def _with_tail(skeleton, bone, tail):
    j = skeleton.index(bone)
    rest, lengths = skeleton.rest.copy(), skeleton.lengths.copy()
    rest[j] = bone_frame(rest[j, :3, 3], tail)
    lengths[j] = np.linalg.norm(tail - rest[j, :3, 3])
    return replace(skeleton, rest=rest, lengths=lengths)


def _world_com(skeleton, com, bone):
    j = skeleton.index(bone)
    return skeleton.rest[j, :3, :3] @ com[j] + skeleton.rest[j, :3, 3]


@pytest.mark.parametrize("side", ["L", "R"])
def test_cmu_hand_centre_does_not_depend_on_the_importers_wrist_tail(side):
    """CMU's wrist has two children that start at the wrist (hand, thumb) and the fingers 3.7 cm
    further: the wrist's tail is made up by the importer. Blender 4.2 continues the forearm's line
    (18.5 cm), 5.0 points it 10 cm up the forearm; the hand's centre of mass (where a carried load
    sits) must be the same for both, on the line from the wrist to the fingers' base."""
    sk = bvh.skeleton(bvh.read(CMU))
    hand = sk.roles.bone(f"hand.{side}")
    j = sk.index(hand)
    wrist = sk.rest[j, :3, 3]
    forearm = wrist - sk.rest[sk.parents[j], :3, 3]
    guesses = [wrist + 0.185 * forearm / np.linalg.norm(forearm), wrist + np.array([0.0, 0.0, 0.1])]
    centres = []
    for tail in guesses:
        rig = _with_tail(sk, hand, tail)
        mass, com, _ = anthropometric_model(rig, 70.0)
        centres.append(_world_com(rig, com, hand))
    assert np.allclose(centres[0], centres[1], atol=1e-9)
    fingers = sk.rest[sk.index(f"{side}Fingers"), :3, 3]
    along = (centres[0] - wrist) @ (fingers - wrist) / np.sum((fingers - wrist) ** 2)
    assert along == pytest.approx(DE_LEVA["male"]["hand"][1] / 100.0)  # wrist to finger base
    assert np.linalg.norm(np.cross(centres[0] - wrist, fingers - wrist)) < 1e-9


def test_reach_of_made_up_tail_only_where_every_child_starts_at_the_head():
    sk = bvh.skeleton(bvh.read(CMU))
    heads = sk.rest[:, :3, 3]
    for side in "LR":
        wrist = sk.index(f"{side.replace('L', 'Left').replace('R', 'Right')}Wrist")
        reach = reach_of_made_up_tail(sk.parents, heads, wrist)
        assert np.allclose(reach, heads[sk.index(f"{side}Fingers")])  # past hand and thumb at the wrist
    for bone in ("LeftElbow", "LFingers", "LThumb", "LHipJoint", "LeftHip"):
        # a child away from the head (the elbow, the hip joint), a leaf (an End Site's tail)
        assert reach_of_made_up_tail(sk.parents, heads, sk.index(bone)) is None, bone
    # the hips' three children start at its head too: the hip joints and the lower back beyond
    grand = [sk.index(n) for n in ("LeftHip", "RightHip", "Chest")]
    assert np.allclose(reach_of_made_up_tail(sk.parents, heads, sk.index("Hips")), heads[grand].mean(axis=0))
