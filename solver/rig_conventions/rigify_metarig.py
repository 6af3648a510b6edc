"""Rigify's human metarig (Add > Armature > Human (Meta-Rig)).

spine = hips (pelvis), spine.001-.002 (spine), spine.003 (chest: the shoulders branch from
it), spine.004 (neck; spine.005 is the upper neck, same segment), spine.006 (head).
Palm bones (palm.01-.04) belong to the hand; each finger chain is its three phalanges.
"""

from ._util import both_sides

CENTRE = {
    "pelvis": "spine",
    "spine": ("spine.001", "spine.002"),
    "chest": "spine.003",
    "neck": "spine.004",
    "head": "spine.006",
}

LEFT = {
    "clavicle.L": "shoulder.L",
    "upper_arm.L": "upper_arm.L",
    "forearm.L": "forearm.L",
    "hand.L": "hand.L",
    "thigh.L": "thigh.L",
    "shin.L": "shin.L",
    "foot.L": "foot.L",
    "toe.L": "toe.L",
    "thumb.L": ("thumb.01.L", "thumb.02.L", "thumb.03.L"),
    "index.L": ("f_index.01.L", "f_index.02.L", "f_index.03.L"),
    "middle.L": ("f_middle.01.L", "f_middle.02.L", "f_middle.03.L"),
    "ring.L": ("f_ring.01.L", "f_ring.02.L", "f_ring.03.L"),
    "pinky.L": ("f_pinky.01.L", "f_pinky.02.L", "f_pinky.03.L"),
}

TABLES = {"rigify_metarig": both_sides(CENTRE, LEFT, lambda n: n.replace(".L", ".R"))}
