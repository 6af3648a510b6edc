"""Write the hand-made rig fixtures (no bpy needed): python3 make_handmade.py [outdir].

Real Mixamo, UE, VRoid, 3ds Max Biped and cgspeed files cannot be downloaded here, so these
rigs follow the published bone hierarchies and names, on one plausible 1.76 m human in
T-pose (armature space, Z up, facing -Y, character's left +X). Every file says so in
"source" and has "handmade": true. The geometry is made up; only names and parenting
follow the conventions.
"""

import json
import os
import sys

# Joint positions of the left side (x > 0) and the midline, metres.
J = {
    "origin": (0, 0, 0), "pelvis": (0, 0.0, 0.95), "hip": (0.09, 0.0, 0.90),
    "knee": (0.095, -0.01, 0.50), "ankle": (0.10, 0.02, 0.08), "ball": (0.10, -0.10, 0.02),
    "toetip": (0.10, -0.17, 0.02), "heel": (0.10, 0.05, 0.0),
    "spine0": (0, 0.0, 1.02), "spine1": (0, 0.0, 1.12), "spine2": (0, 0.0, 1.24),
    "spine3": (0, 0.0, 1.36), "neck": (0, 0.01, 1.48), "neckmid": (0, 0.0, 1.54),
    "headj": (0, -0.01, 1.60), "headtop": (0, -0.01, 1.76), "eye": (0.03, -0.09, 1.66),
    "clav": (0.03, -0.02, 1.44), "shoulder": (0.17, 0.01, 1.43), "elbow": (0.44, 0.02, 1.41),
    "wrist": (0.69, 0.0, 1.40),
    "thumb0": (0.705, -0.02, 1.39), "thumb1": (0.735, -0.05, 1.385), "thumb2": (0.765, -0.065, 1.38),
    "thumb3": (0.785, -0.075, 1.38), "thumb4": (0.80, -0.08, 1.38),
    "thumb5": (0.812, -0.083, 1.38),
}
for finger, y, scale in (("index", -0.025, 1.0), ("middle", 0.0, 1.05), ("ring", 0.02, 1.0),
                         ("pinky", 0.038, 0.8)):
    x = 0.78 if finger != "pinky" else 0.77
    J[finger + "m"] = (0.705, y * 0.5, 1.40)  # metacarpal start
    J[finger + "1"] = (x, y, 1.40)
    J[finger + "2"] = (x + 0.045 * scale, y, 1.40)
    J[finger + "3"] = (x + 0.073 * scale, y, 1.40)
    J[finger + "4"] = (x + 0.095 * scale, y, 1.40)
    J[finger + "5"] = (x + 0.11 * scale, y, 1.40)
CENTRE = {k for k, v in J.items() if v[0] == 0}


def pos(key, side):
    if isinstance(key, tuple):  # (key, offset)
        base = pos(key[0], side)
        return tuple(round(a + b, 4) for a, b in zip(base, key[1]))
    x, y, z = J[key]
    return (-x if side == "R" and key not in CENTRE else x, y, z)


def lerp(a, b, t):
    return ("__lerp", a, b, t)


def point(key, side):
    if isinstance(key, tuple) and key and key[0] == "__lerp":
        pa, pb = pos(key[1], side), pos(key[2], side)
        return tuple(round(u + key[3] * (v - u), 4) for u, v in zip(pa, pb))
    return tuple(round(v, 4) for v in pos(key, side))


def build(spec, sides, source):
    """spec: (name, parent, head, tail); names with {x} placeholders are made for each side
    with the substitutions sides[side]; parents before children."""
    names, parents, heads, tails = [], [], [], []
    index = {}
    for name, parent, head, tail in spec:
        for side in (("L", "R") if "{" in name else (None,)):
            sub = sides[side] if side else {}
            n = name.format(**sub)
            p = parent.format(**sub) if parent else None
            index[n] = len(names)
            names.append(n)
            parents.append(index[p] if p else -1)
            heads.append(point(head, side or "L"))
            tails.append(point(tail, side or "L"))
    return {"source": source, "handmade": True, "names": names, "parents": parents,
            "heads": [list(h) for h in heads], "tails": [list(t) for t in tails]}


UP = (0, 0, 0.08)


def fingers(fmt, parent, count=3, end=False, thumb_fmt=None):
    out = []
    for finger in ("thumb", "index", "middle", "ring", "pinky"):
        prev = parent
        for k in range(1, count + 1 + (1 if end else 0)):
            name = fmt.format(finger=finger, Finger=finger.capitalize(), k=k, x="{x}", X="{X}")
            out.append((name, prev, f"{finger}{k}", f"{finger}{k + 1}"))
            prev = name
    return out


def mixamo(ns="mixamorig:"):
    s = [
        (ns + "Hips", None, "pelvis", "spine1"),
        (ns + "Spine", ns + "Hips", "spine1", "spine2"),
        (ns + "Spine1", ns + "Spine", "spine2", "spine3"),
        (ns + "Spine2", ns + "Spine1", "spine3", "neck"),
        (ns + "Neck", ns + "Spine2", "neck", "headj"),
        (ns + "Head", ns + "Neck", "headj", "headtop"),
        (ns + "HeadTop_End", ns + "Head", "headtop", ("headtop", UP)),
        (ns + "{X}Eye", ns + "Head", "eye", ("eye", (0, -0.02, 0))),
        (ns + "{X}Shoulder", ns + "Spine2", "clav", "shoulder"),
        (ns + "{X}Arm", ns + "{X}Shoulder", "shoulder", "elbow"),
        (ns + "{X}ForeArm", ns + "{X}Arm", "elbow", "wrist"),
        (ns + "{X}Hand", ns + "{X}ForeArm", "wrist", "middle1"),
    ]
    s += fingers(ns + "{X}Hand{Finger}{k}", ns + "{X}Hand", 3, end=True)
    s += [
        (ns + "{X}UpLeg", ns + "Hips", "hip", "knee"),
        (ns + "{X}Leg", ns + "{X}UpLeg", "knee", "ankle"),
        (ns + "{X}Foot", ns + "{X}Leg", "ankle", "ball"),
        (ns + "{X}ToeBase", ns + "{X}Foot", "ball", "toetip"),
        (ns + "{X}Toe_End", ns + "{X}ToeBase", "toetip", ("toetip", (0, -0.03, 0))),
    ]
    return build(s, {"L": {"X": "Left"}, "R": {"X": "Right"}},
                 "hand-made from the published Mixamo hierarchy (mixamorig: names, end bones included)")


def cgspeed():
    s = [
        ("Hips", None, "pelvis", ("pelvis", UP)),
        ("{S}HipJoint", "Hips", "pelvis", "hip"),
        ("{X}UpLeg", "{S}HipJoint", "hip", "knee"),
        ("{X}Leg", "{X}UpLeg", "knee", "ankle"),
        ("{X}Foot", "{X}Leg", "ankle", "ball"),
        ("{X}ToeBase", "{X}Foot", "ball", "toetip"),
        ("LowerBack", "Hips", "pelvis", "spine2"),
        ("Spine", "LowerBack", "spine2", "spine3"),
        ("Spine1", "Spine", "spine3", "neck"),
        ("Neck", "Spine1", "neck", "neckmid"),
        ("Neck1", "Neck", "neckmid", "headj"),
        ("Head", "Neck1", "headj", "headtop"),
        ("{X}Shoulder", "Spine1", "neck", "shoulder"),
        ("{X}Arm", "{X}Shoulder", "shoulder", "elbow"),
        ("{X}ForeArm", "{X}Arm", "elbow", "wrist"),
        ("{X}Hand", "{X}ForeArm", "wrist", ("wrist", (0.1, 0, 0))),
        ("{X}FingerBase", "{X}Hand", "wrist", "index1"),
        ("{X}HandIndex1", "{X}FingerBase", "index1", "index3"),
        ("{S}Thumb", "{X}Hand", "wrist", "thumb3"),
    ]
    return build(s, {"L": {"X": "Left", "S": "L"}, "R": {"X": "Right", "S": "R"}},
                 "hand-made from the cgspeed BVH conversion of the CMU database "
                 "(as Blender's BVH importer builds it)")


def unreal():
    s = [
        ("root", None, "origin", ("origin", (0, 0.2, 0))),
        ("pelvis", "root", "pelvis", "spine1"),
        ("spine_01", "pelvis", "spine1", "spine2"),
        ("spine_02", "spine_01", "spine2", "spine3"),
        ("spine_03", "spine_02", "spine3", "neck"),
        ("clavicle_{x}", "spine_03", "clav", "shoulder"),
        ("upperarm_{x}", "clavicle_{x}", "shoulder", "elbow"),
        ("lowerarm_{x}", "upperarm_{x}", "elbow", "wrist"),
        ("hand_{x}", "lowerarm_{x}", "wrist", "middle1"),
    ]
    s += fingers("{finger}_0{k}_{x}", "hand_{x}", 3)
    s += [
        ("lowerarm_twist_01_{x}", "lowerarm_{x}", lerp("elbow", "wrist", 0.5), "wrist"),
        ("upperarm_twist_01_{x}", "upperarm_{x}", "shoulder", lerp("shoulder", "elbow", 0.5)),
        ("neck_01", "spine_03", "neck", "headj"),
        ("head", "neck_01", "headj", "headtop"),
        ("thigh_{x}", "pelvis", "hip", "knee"),
        ("calf_{x}", "thigh_{x}", "knee", "ankle"),
        ("calf_twist_01_{x}", "calf_{x}", lerp("knee", "ankle", 0.5), "ankle"),
        ("foot_{x}", "calf_{x}", "ankle", "ball"),
        ("ball_{x}", "foot_{x}", "ball", "toetip"),
        ("thigh_twist_01_{x}", "thigh_{x}", "hip", lerp("hip", "knee", 0.5)),
        ("ik_foot_root", "root", "origin", ("origin", (0, 0, 0.1))),
        ("ik_foot_{x}", "ik_foot_root", "ankle", "ball"),
        ("ik_hand_root", "root", "origin", ("origin", (0, 0, 0.1))),
        ("ik_hand_gun", "ik_hand_root", "wrist", "middle1"),
    ]
    return build(s, {"L": {"x": "l"}, "R": {"x": "r"}},
                 "hand-made from the published Unreal Engine 4 mannequin hierarchy (twist and IK bones included)")


def vroid():
    s = [
        ("Root", None, "origin", ("origin", (0, 0, 0.1))),
        ("J_Bip_C_Hips", "Root", "pelvis", "spine1"),
        ("J_Bip_C_Spine", "J_Bip_C_Hips", "spine1", "spine2"),
        ("J_Bip_C_Chest", "J_Bip_C_Spine", "spine2", "spine3"),
        ("J_Bip_C_UpperChest", "J_Bip_C_Chest", "spine3", "neck"),
        ("J_Sec_{X}_Bust1", "J_Bip_C_UpperChest", ("spine3", (0.08, -0.05, 0)), ("spine3", (0.08, -0.12, 0))),
        ("J_Bip_C_Neck", "J_Bip_C_UpperChest", "neck", "headj"),
        ("J_Bip_C_Head", "J_Bip_C_Neck", "headj", "headtop"),
        ("J_Adj_{X}_FaceEye", "J_Bip_C_Head", "eye", ("eye", (0, -0.02, 0))),
        ("J_Sec_Hair1_01", "J_Bip_C_Head", ("headtop", (0, 0.08, -0.02)), ("headtop", (0, 0.12, -0.25))),
        ("J_Sec_Hair1_02", "J_Sec_Hair1_01", ("headtop", (0, 0.12, -0.25)), ("headtop", (0, 0.14, -0.5))),
        ("J_Bip_{X}_Shoulder", "J_Bip_C_UpperChest", "clav", "shoulder"),
        ("J_Bip_{X}_UpperArm", "J_Bip_{X}_Shoulder", "shoulder", "elbow"),
        ("J_Bip_{X}_LowerArm", "J_Bip_{X}_UpperArm", "elbow", "wrist"),
        ("J_Bip_{X}_Hand", "J_Bip_{X}_LowerArm", "wrist", "middle1"),
    ]
    s += [(n.replace("Pinky", "Little"), p.replace("Pinky", "Little"), h, t)
          for n, p, h, t in fingers("J_Bip_{X}_{Finger}{k}", "J_Bip_{X}_Hand", 3)]
    s += [
        ("J_Bip_{X}_UpperLeg", "J_Bip_C_Hips", "hip", "knee"),
        ("J_Bip_{X}_LowerLeg", "J_Bip_{X}_UpperLeg", "knee", "ankle"),
        ("J_Bip_{X}_Foot", "J_Bip_{X}_LowerLeg", "ankle", "ball"),
        ("J_Bip_{X}_ToeBase", "J_Bip_{X}_Foot", "ball", "toetip"),
    ]
    return build(s, {"L": {"X": "L"}, "R": {"X": "R"}},
                 "hand-made from the published VRoid Studio VRM hierarchy (J_Bip_ bones, some J_Sec_/J_Adj_ extras)")


def biped():
    s = [
        ("Bip01", None, "pelvis", ("pelvis", (0, -0.1, 0))),
        ("Bip01 Pelvis", "Bip01", "pelvis", ("pelvis", (0, 0, 0.05))),
        ("Bip01 Spine", "Bip01 Pelvis", "spine0", "spine1"),
        ("Bip01 {X} Thigh", "Bip01 Spine", "hip", "knee"),
        ("Bip01 {X} Calf", "Bip01 {X} Thigh", "knee", "ankle"),
        ("Bip01 {X} Foot", "Bip01 {X} Calf", "ankle", "ball"),
        ("Bip01 {X} Toe0", "Bip01 {X} Foot", "ball", "toetip"),
        ("Bip01 {X} Toe0Nub", "Bip01 {X} Toe0", "toetip", ("toetip", (0, -0.02, 0))),
        ("Bip01 Spine1", "Bip01 Spine", "spine1", "spine2"),
        ("Bip01 Spine2", "Bip01 Spine1", "spine2", "neck"),
        ("Bip01 Neck", "Bip01 Spine2", "neck", "headj"),
        ("Bip01 {X} Clavicle", "Bip01 Neck", "clav", "shoulder"),
        ("Bip01 {X} UpperArm", "Bip01 {X} Clavicle", "shoulder", "elbow"),
        ("Bip01 {X} Forearm", "Bip01 {X} UpperArm", "elbow", "wrist"),
        ("Bip01 {X} Hand", "Bip01 {X} Forearm", "wrist", "middle1"),
    ]
    for f, finger in enumerate(("thumb", "index", "middle", "ring", "pinky")):
        prev = "Bip01 {X} Hand"
        for k, suffix in enumerate(("", "1", "2")):
            name = f"Bip01 {{X}} Finger{f}{suffix}"
            s.append((name, prev, f"{finger}{k + 1}", f"{finger}{k + 2}"))
            prev = name
        s.append((f"Bip01 {{X}} Finger{f}Nub", prev, f"{finger}4", f"{finger}5"))
    s += [
        ("Bip01 Head", "Bip01 Neck", "headj", "headtop"),
        ("Bip01 HeadNub", "Bip01 Head", "headtop", ("headtop", UP)),
    ]
    return build(s, {"L": {"X": "L"}, "R": {"X": "R"}},
                 "hand-made from the 3ds Max Biped hierarchy (thighs under Bip01 Spine, clavicles under Bip01 Neck)")


def lowercase_suffix():
    s = [
        ("hips", None, "pelvis", "spine1"),
        ("spine", "hips", "spine1", "spine3"),
        ("chest", "spine", "spine3", "neck"),
        ("neck", "chest", "neck", "headj"),
        ("head", "neck", "headj", "headtop"),
        ("shoulder_{x}", "chest", "clav", "shoulder"),
        ("upperarm_{x}", "shoulder_{x}", "shoulder", "elbow"),
        ("lowerarm_{x}", "upperarm_{x}", "elbow", "wrist"),
        ("hand_{x}", "lowerarm_{x}", "wrist", "middle1"),
        ("upperleg_{x}", "hips", "hip", "knee"),
        ("lowerleg_{x}", "upperleg_{x}", "knee", "ankle"),
        ("foot_{x}", "lowerleg_{x}", "ankle", "ball"),
        ("toes_{x}", "foot_{x}", "ball", "toetip"),
    ]
    return build(s, {"L": {"x": "l"}, "R": {"x": "r"}},
                 "hand-made generic game rig with lower-case names and _l/_r suffixes")


def main(outdir):
    rigs = {"mixamo": mixamo(), "mixamo_plain": mixamo(ns=""), "mixamo_ns1": mixamo(ns="mixamorig1:"),
            "bvh_cgspeed": cgspeed(), "unreal": unreal(), "vroid": vroid(), "biped": biped(),
            "lowercase_suffix": lowercase_suffix()}
    for name, data in rigs.items():
        path = os.path.join(outdir, f"handmade_{name}.json")
        with open(path, "w") as f:
            json.dump(data, f, separators=(",", ":"))
            f.write("\n")
        print("wrote", path, len(data["names"]), "bones")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else os.path.dirname(os.path.abspath(__file__)))
