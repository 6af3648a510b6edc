"""Mixamo (`mixamorig:` names; also without the namespace or with `mixamorig1:` etc.).

Hips, Spine, Spine1, Spine2 (chest), Neck, Head (HeadTop_End is an end bone, no role);
LeftShoulder is the clavicle, LeftArm the upper arm. LeftHandIndex1..3 are the finger chain,
LeftHandIndex4 is an end bone (a tip marker, no segment). LeftToe_End likewise.
"""

from ._util import both_sides

CENTRE = {
    "pelvis": "Hips",
    "spine": ("Spine", "Spine1"),
    "chest": "Spine2",
    "neck": "Neck",
    "head": "Head",
}

LEFT = {
    "clavicle.L": "LeftShoulder",
    "upper_arm.L": "LeftArm",
    "forearm.L": "LeftForeArm",
    "hand.L": "LeftHand",
    "thigh.L": "LeftUpLeg",
    "shin.L": "LeftLeg",
    "foot.L": "LeftFoot",
    "toe.L": "LeftToeBase",
    "thumb.L": ("LeftHandThumb1", "LeftHandThumb2", "LeftHandThumb3"),
    "index.L": ("LeftHandIndex1", "LeftHandIndex2", "LeftHandIndex3"),
    "middle.L": ("LeftHandMiddle1", "LeftHandMiddle2", "LeftHandMiddle3"),
    "ring.L": ("LeftHandRing1", "LeftHandRing2", "LeftHandRing3"),
    "pinky.L": ("LeftHandPinky1", "LeftHandPinky2", "LeftHandPinky3"),
}

TABLES = {"mixamo": both_sides(CENTRE, LEFT, lambda n: n.replace("Left", "Right"))}
