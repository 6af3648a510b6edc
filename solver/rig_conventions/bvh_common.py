"""Other widespread BVH namings, as Blender's BVH importer builds them (bone = joint).

- bvh_cgspeed: the cgspeed "BVH conversion" of the CMU database (Motionbuilder-friendly).
  Hips, LHipJoint (pelvis segment), LeftUpLeg, LeftLeg, LeftFoot, LeftToeBase; LowerBack,
  Spine, Spine1 (chest: the shoulders branch from it), Neck, Neck1 (upper neck), Head;
  LeftShoulder (clavicle), LeftArm, LeftForeArm, LeftHand (the wrist: it carries the finger
  base and the thumb), LeftFingerBase (palm, hand segment), LeftHandIndex1 (the four fingers
  as one segment: index chain), LThumb.
- bvh_motionbuilder: Motionbuilder / HumanIK names as used by Truebones and many BVH
  exporters (and by the LAFAN1 data set): Hips, Spine..Spine3, Neck, Neck1, Head,
  LeftShoulder, LeftArm, LeftForeArm, LeftHand, LeftHandThumb1.., LeftUpLeg, LeftLeg,
  LeftFoot, LeftToeBase (LeftToe in LAFAN1). The chest is the spine bone the shoulders
  branch from; the detector settles it from the hierarchy.
- bvh_daz: the Daz/Poser/Second Life naming (also the cgspeed "Daz-friendly" CMU release):
  hip, abdomen, chest, neck, head, lCollar, lShldr, lForeArm, lHand, lThigh, lShin, lFoot.
- bvh_hip_knee: the plain joint naming Hips, LeftHip, LeftKnee, LeftAnkle, LeftToe,
  Spine.., Neck, Head, LeftShoulder (upper arm here), LeftElbow, LeftWrist.
- unity_humanoid: Unity Mecanim / VRM humanoid names: Hips, Spine, Chest, UpperChest, Neck,
  Head, LeftShoulder, LeftUpperArm, LeftLowerArm, LeftHand, LeftUpperLeg, LeftLowerLeg,
  LeftFoot, LeftToes.
"""

from ._util import both_sides


def _left_right(name):
    return name.replace("Left", "Right")


def _l_r(name):
    if name.startswith("Left"):
        return "Right" + name[4:]
    if name[:1] in "Ll":
        return ("R" if name[0] == "L" else "r") + name[1:]
    return name


CGSPEED = both_sides(
    {
        "pelvis": "Hips",
        "spine": ("LowerBack", "Spine"),
        "chest": "Spine1",
        "neck": "Neck",
        "head": "Head",
    },
    {
        "clavicle.L": "LeftShoulder",
        "upper_arm.L": "LeftArm",
        "forearm.L": "LeftForeArm",
        "hand.L": "LeftHand",
        "thigh.L": "LeftUpLeg",
        "shin.L": "LeftLeg",
        "foot.L": "LeftFoot",
        "toe.L": "LeftToeBase",
        "thumb.L": ("LThumb",),
        "index.L": ("LeftHandIndex1",),
    },
    _l_r,
)

MOTIONBUILDER = both_sides(
    {
        "pelvis": "Hips",
        "spine": ("Spine", "Spine1", "Spine2"),
        "chest": ("Spine3", "Spine2"),
        "neck": "Neck",
        "head": "Head",
    },
    {
        "clavicle.L": "LeftShoulder",
        "upper_arm.L": "LeftArm",
        "forearm.L": "LeftForeArm",
        "hand.L": "LeftHand",
        "thigh.L": "LeftUpLeg",
        "shin.L": "LeftLeg",
        "foot.L": "LeftFoot",
        "toe.L": ("LeftToeBase", "LeftToe"),
        "thumb.L": ("LeftHandThumb1", "LeftHandThumb2", "LeftHandThumb3"),
        "index.L": ("LeftHandIndex1", "LeftHandIndex2", "LeftHandIndex3"),
        "middle.L": ("LeftHandMiddle1", "LeftHandMiddle2", "LeftHandMiddle3"),
        "ring.L": ("LeftHandRing1", "LeftHandRing2", "LeftHandRing3"),
        "pinky.L": ("LeftHandPinky1", "LeftHandPinky2", "LeftHandPinky3"),
    },
    _left_right,
)

DAZ = both_sides(
    {
        "pelvis": "hip",
        "spine": ("abdomen", "abdomen2"),
        "chest": "chest",
        "neck": "neck",
        "head": "head",
    },
    {
        "clavicle.L": "lCollar",
        "upper_arm.L": "lShldr",
        "forearm.L": "lForeArm",
        "hand.L": "lHand",
        "thigh.L": "lThigh",
        "shin.L": "lShin",
        "foot.L": "lFoot",
        "toe.L": "lToe",
        "thumb.L": ("lThumb1", "lThumb2", "lThumb3"),
        "index.L": ("lIndex1", "lIndex2", "lIndex3"),
        "middle.L": ("lMid1", "lMid2", "lMid3"),
        "ring.L": ("lRing1", "lRing2", "lRing3"),
        "pinky.L": ("lPinky1", "lPinky2", "lPinky3"),
    },
    _l_r,
)

HIP_KNEE = both_sides(
    {
        "pelvis": "Hips",
        "spine": ("Spine", "Spine1", "Spine2"),
        "chest": ("Chest", "Spine3"),
        "neck": "Neck",
        "head": "Head",
    },
    {
        "clavicle.L": ("LeftCollar", "LeftClavicle"),
        "upper_arm.L": "LeftShoulder",
        "forearm.L": "LeftElbow",
        "hand.L": "LeftWrist",
        "thigh.L": "LeftHip",
        "shin.L": "LeftKnee",
        "foot.L": "LeftAnkle",
        "toe.L": "LeftToe",
    },
    _left_right,
)

UNITY = both_sides(
    {
        "pelvis": "Hips",
        "spine": ("Spine", "Chest"),
        "chest": ("UpperChest", "Chest"),
        "neck": "Neck",
        "head": "Head",
    },
    {
        "clavicle.L": "LeftShoulder",
        "upper_arm.L": "LeftUpperArm",
        "forearm.L": "LeftLowerArm",
        "hand.L": "LeftHand",
        "thigh.L": "LeftUpperLeg",
        "shin.L": "LeftLowerLeg",
        "foot.L": "LeftFoot",
        "toe.L": "LeftToes",
        "thumb.L": ("LeftThumbProximal", "LeftThumbIntermediate", "LeftThumbDistal"),
        "index.L": ("LeftIndexProximal", "LeftIndexIntermediate", "LeftIndexDistal"),
        "middle.L": ("LeftMiddleProximal", "LeftMiddleIntermediate", "LeftMiddleDistal"),
        "ring.L": ("LeftRingProximal", "LeftRingIntermediate", "LeftRingDistal"),
        "pinky.L": ("LeftLittleProximal", "LeftLittleIntermediate", "LeftLittleDistal"),
    },
    _left_right,
)

TABLES = {
    "bvh_cgspeed": CGSPEED,
    "bvh_motionbuilder": MOTIONBUILDER,
    "bvh_daz": DAZ,
    "bvh_hip_knee": HIP_KNEE,
    "unity_humanoid": UNITY,
}
