"""CMU motion capture in the BVH conversion with 1 m units (the clips in shared/data/mocap),
as Blender's BVH importer builds it.

Hips is the root (zero length: its children start at its head); LHipJoint runs from the
pelvis centre to the hip joint and belongs to the pelvis segment; LeftHip is the thigh
(it rotates at the hip joint and spans hip to knee), LeftKnee the shin, LeftAnkle the foot.
lowerback is the spine; Chest spans the thorax up to the shoulders and is the chest;
Chest2 is a zero-length bone at the top of Chest from which neck and collars branch, so it
belongs to the chest segment. lowerneck is the neck (Neck is its upper half).
LeftCollar is the clavicle, LeftShoulder the upper arm, LeftElbow the forearm.
Hand: LeftWrist is zero-length at the wrist and carries both lhand (the palm) and LThumb;
it is the proximal bone rotating at the wrist, so it is the hand, and lhand belongs to the
hand segment. LFingers is a single segment standing for the four fingers together: it is
the index chain (as in the cgspeed conversion of the same skeleton, which names it
LeftHandIndex1); middle, ring and pinky are absent.
"""

from ._util import both_sides

CENTRE = {
    "pelvis": "Hips",
    "spine": ("lowerback",),
    "chest": "Chest",
    "neck": "lowerneck",
    "head": "Head",
}

LEFT = {
    "clavicle.L": "LeftCollar",
    "upper_arm.L": "LeftShoulder",
    "forearm.L": "LeftElbow",
    "hand.L": "LeftWrist",
    "thigh.L": "LeftHip",
    "shin.L": "LeftKnee",
    "foot.L": "LeftAnkle",
    "toe.L": "LeftToe",
    "thumb.L": ("LThumb",),
    "index.L": ("LFingers",),
}


def _swap(name):
    if name.startswith("Left"):
        return "Right" + name[4:]
    if name.startswith("L"):
        return "R" + name[1:]
    return name


TABLES = {"bvh_cmu": both_sides(CENTRE, LEFT, _swap)}
