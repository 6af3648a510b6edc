"""Body-role detection on real rigs dumped from Blender and on hand-made and unseen rigs."""

import json
from pathlib import Path

import numpy as np
import pytest

from humananim.solver.body_roles import ALL_ROLES, REQUIRED_ROLES, RoleMap
from humananim.solver.errors import RigError
from humananim.solver.role_detection import RoleDetection, detect_roles, require_roles

RIGS = Path(__file__).resolve().parents[1] / "data" / "rigs"


def load(name):
    return json.loads((RIGS / f"{name}.json").read_text())


def detect(data, names=None, **kw):
    return detect_roles(names or data["names"], data["parents"], data["heads"], data["tails"],
                        kw.pop("deform", data.get("deform")), **kw)


def both_sides(left, swap):
    out = {}
    for role, bones in left.items():
        out[role] = bones
        if role.endswith(".L"):
            out[role[:-2] + ".R"] = tuple(swap(b) for b in bones)
    return out


def expect(centre, left, swap):
    table = {r: (v,) if isinstance(v, str) else tuple(v) for r, v in {**centre, **left}.items()}
    return both_sides(table, swap)


RIGIFY_METARIG = expect(
    {"pelvis": "spine", "spine": ("spine.001", "spine.002"), "chest": "spine.003",
     "neck": "spine.004", "head": "spine.006"},
    {"clavicle.L": "shoulder.L", "upper_arm.L": "upper_arm.L", "forearm.L": "forearm.L",
     "hand.L": "hand.L", "thigh.L": "thigh.L", "shin.L": "shin.L", "foot.L": "foot.L", "toe.L": "toe.L",
     "thumb.L": ("thumb.01.L", "thumb.02.L", "thumb.03.L"),
     "index.L": ("f_index.01.L", "f_index.02.L", "f_index.03.L"),
     "middle.L": ("f_middle.01.L", "f_middle.02.L", "f_middle.03.L"),
     "ring.L": ("f_ring.01.L", "f_ring.02.L", "f_ring.03.L"),
     "pinky.L": ("f_pinky.01.L", "f_pinky.02.L", "f_pinky.03.L")},
    lambda n: n.replace(".L", ".R"),
)
RIGIFY_GENERATED = {r: tuple("DEF-" + b for b in v) for r, v in RIGIFY_METARIG.items()}

CMU = expect(
    {"pelvis": "Hips", "spine": ("lowerback",), "chest": "Chest", "neck": "lowerneck", "head": "Head"},
    {"clavicle.L": "LeftCollar", "upper_arm.L": "LeftShoulder", "forearm.L": "LeftElbow",
     "hand.L": "LeftWrist", "thigh.L": "LeftHip", "shin.L": "LeftKnee", "foot.L": "LeftAnkle",
     "toe.L": "LeftToe", "thumb.L": ("LThumb",), "index.L": ("LFingers",)},
    lambda n: "Right" + n[4:] if n.startswith("Left") else "R" + n[1:],
)


def mixamo(ns):
    return expect(
        {"pelvis": ns + "Hips", "spine": (ns + "Spine", ns + "Spine1"), "chest": ns + "Spine2",
         "neck": ns + "Neck", "head": ns + "Head"},
        {"clavicle.L": ns + "LeftShoulder", "upper_arm.L": ns + "LeftArm",
         "forearm.L": ns + "LeftForeArm", "hand.L": ns + "LeftHand", "thigh.L": ns + "LeftUpLeg",
         "shin.L": ns + "LeftLeg", "foot.L": ns + "LeftFoot", "toe.L": ns + "LeftToeBase",
         **{f"{f}.L": tuple(f"{ns}LeftHand{f.capitalize()}{k}" for k in (1, 2, 3))
            for f in ("thumb", "index", "middle", "ring", "pinky")}},
        lambda n: n.replace("Left", "Right"),
    )


CGSPEED = expect(
    {"pelvis": "Hips", "spine": ("LowerBack", "Spine"), "chest": "Spine1", "neck": "Neck", "head": "Head"},
    {"clavicle.L": "LeftShoulder", "upper_arm.L": "LeftArm", "forearm.L": "LeftForeArm",
     "hand.L": "LeftHand", "thigh.L": "LeftUpLeg", "shin.L": "LeftLeg", "foot.L": "LeftFoot",
     "toe.L": "LeftToeBase", "thumb.L": ("LThumb",), "index.L": ("LeftHandIndex1",)},
    lambda n: "Right" + n[4:] if n.startswith("Left") else "R" + n[1:],
)

UNREAL = expect(
    {"pelvis": "pelvis", "spine": ("spine_01", "spine_02"), "chest": "spine_03", "neck": "neck_01",
     "head": "head"},
    {"clavicle.L": "clavicle_l", "upper_arm.L": "upperarm_l", "forearm.L": "lowerarm_l",
     "hand.L": "hand_l", "thigh.L": "thigh_l", "shin.L": "calf_l", "foot.L": "foot_l", "toe.L": "ball_l",
     **{f"{f}.L": tuple(f"{f}_0{k}_l" for k in (1, 2, 3))
        for f in ("thumb", "index", "middle", "ring", "pinky")}},
    lambda n: n[:-2] + "_r",
)

VROID = expect(
    {"pelvis": "J_Bip_C_Hips", "spine": ("J_Bip_C_Spine", "J_Bip_C_Chest"),
     "chest": "J_Bip_C_UpperChest", "neck": "J_Bip_C_Neck", "head": "J_Bip_C_Head"},
    {"clavicle.L": "J_Bip_L_Shoulder", "upper_arm.L": "J_Bip_L_UpperArm",
     "forearm.L": "J_Bip_L_LowerArm", "hand.L": "J_Bip_L_Hand", "thigh.L": "J_Bip_L_UpperLeg",
     "shin.L": "J_Bip_L_LowerLeg", "foot.L": "J_Bip_L_Foot", "toe.L": "J_Bip_L_ToeBase",
     **{f"{f}.L": tuple(f"J_Bip_L_{w}{k}" for k in (1, 2, 3))
        for f, w in (("thumb", "Thumb"), ("index", "Index"), ("middle", "Middle"), ("ring", "Ring"),
                     ("pinky", "Little"))}},
    lambda n: n.replace("_L_", "_R_"),
)

BIPED = expect(
    {"pelvis": "Bip01 Pelvis", "spine": ("Bip01 Spine", "Bip01 Spine1"), "chest": "Bip01 Spine2",
     "neck": "Bip01 Neck", "head": "Bip01 Head"},
    {"clavicle.L": "Bip01 L Clavicle", "upper_arm.L": "Bip01 L UpperArm",
     "forearm.L": "Bip01 L Forearm", "hand.L": "Bip01 L Hand", "thigh.L": "Bip01 L Thigh",
     "shin.L": "Bip01 L Calf", "foot.L": "Bip01 L Foot", "toe.L": "Bip01 L Toe0",
     **{f"{f}.L": tuple(f"Bip01 L Finger{i}{k}" for k in ("", "1", "2"))
        for i, f in enumerate(("thumb", "index", "middle", "ring", "pinky"))}},
    lambda n: n.replace(" L ", " R "),
)

LOWERCASE = expect(
    {"pelvis": "hips", "spine": ("spine",), "chest": "chest", "neck": "neck", "head": "head"},
    {"clavicle.L": "shoulder_l", "upper_arm.L": "upperarm_l", "forearm.L": "lowerarm_l",
     "hand.L": "hand_l", "thigh.L": "upperleg_l", "shin.L": "lowerleg_l", "foot.L": "foot_l",
     "toe.L": "toes_l"},
    lambda n: n[:-2] + "_r",
)

CASES = [
    # fixture, expected roles, convention
    ("rigify_metarig", RIGIFY_METARIG, "rigify_metarig"),
    ("rigify_generated", RIGIFY_GENERATED, "rigify_generated"),
    ("bvh_cmu_131", CMU, "bvh_cmu"),
    ("bvh_cmu_131_b42", CMU, "bvh_cmu"),
    ("handmade_mixamo", mixamo("mixamorig:"), "mixamo"),
    ("handmade_mixamo_ns1", mixamo("mixamorig1:"), "mixamo"),
    ("handmade_mixamo_plain", mixamo(""), "mixamo"),
    ("handmade_bvh_cgspeed", CGSPEED, "bvh_cgspeed"),
    ("handmade_unreal", UNREAL, "names"),
    ("handmade_vroid", VROID, "names"),
    ("handmade_biped", BIPED, "names"),
    ("handmade_lowercase_suffix", LOWERCASE, "names"),
]


@pytest.mark.parametrize("fixture,expected,convention", CASES, ids=[c[0] for c in CASES])
def test_roles_of_known_rigs(fixture, expected, convention):
    result = detect(load(fixture))
    assert isinstance(result, RoleDetection)
    assert dict(result.roles.bones) == expected
    assert result.convention == convention
    assert result.missing == ()
    assert require_roles(result) is result.roles


def test_fixtures_are_what_they_say():
    for name in ("rigify_metarig", "rigify_generated", "bvh_cmu_131", "bvh_cmu_131_b42"):
        data = load(name)
        assert data["handmade"] is False and data["blender"]
    for path in RIGS.glob("handmade_*.json"):
        data = json.loads(path.read_text())
        assert data["handmade"] is True and "hand-made" in data["source"]
    for path in RIGS.glob("*.json"):
        data = json.loads(path.read_text())
        n = len(data["names"])
        parents = np.asarray(data["parents"])
        assert len(data["heads"]) == len(data["tails"]) == n
        assert np.all(parents < np.arange(n))


def test_the_two_blender_versions_give_the_same_cmu_skeleton_but_for_zero_length_tails():
    a, b = load("bvh_cmu_131"), load("bvh_cmu_131_b42")
    assert a["names"] == b["names"] and a["parents"] == b["parents"] and a["heads"] == b["heads"]
    differ = [n for n, ta, tb in zip(a["names"], a["tails"], b["tails"]) if ta != tb]
    assert differ == ["Chest2", "LeftWrist", "RightWrist"]


def renamed(data):
    names = [f"bone_{i:03d}" for i in range(len(data["names"]))]
    back = dict(zip(names, data["names"]))
    return names, back


@pytest.mark.parametrize("fixture,expected", [
    ("rigify_metarig", RIGIFY_METARIG), ("bvh_cmu_131", CMU), ("bvh_cmu_131_b42", CMU),
    ("handmade_mixamo", mixamo("mixamorig:")), ("handmade_bvh_cgspeed", CGSPEED),
    ("handmade_unreal", UNREAL), ("handmade_vroid", VROID),
])
def test_structure_alone_finds_every_role_of_unseen_names(fixture, expected):
    data = load(fixture)
    names, back = renamed(data)
    result = detect(data, names)
    assert result.convention == "structure"
    assert result.missing == ()
    found = {r: tuple(back[b] for b in v) for r, v in result.roles.bones.items()}
    assert found == expected


def test_structure_on_biped_finds_the_required_roles_with_right_sides():
    data = load("handmade_biped")
    names, back = renamed(data)
    result = detect(data, names)
    roles = {r: tuple(back[b] for b in v) for r, v in result.roles.bones.items()}
    assert result.missing == ()
    # without names the pelvis is where legs and spine meet; Biped hangs the thighs on Bip01 Spine
    assert roles["pelvis"] == ("Bip01 Spine",)
    for side in "LR":
        assert roles[f"thigh.{side}"] == (f"Bip01 {side} Thigh",)
        assert roles[f"foot.{side}"] == (f"Bip01 {side} Foot",)
        assert roles[f"hand.{side}"] == (f"Bip01 {side} Hand",)
    assert roles["head"] == ("Bip01 Head",)


def test_namespaced_and_prefixed_names_go_through_the_name_matcher():
    data = load("bvh_cmu_131")
    names = ["Character1_" + n for n in data["names"]]
    result = detect(data, names)
    assert result.convention == "names"
    assert {r: tuple(b[len("Character1_"):] for b in v) for r, v in result.roles.bones.items()} == CMU


def test_sides_follow_geometry_when_names_disagree():
    data = load("rigify_metarig")
    heads = np.asarray(data["heads"]) * [-1, 1, 1]
    tails = np.asarray(data["tails"]) * [-1, 1, 1]
    result = detect_roles(data["names"], data["parents"], heads, tails)
    assert result.roles.bone("thigh.L") == "thigh.R"
    assert result.roles.bone("hand.R") == "hand.L"
    assert result.roles.chain("index.L") == ("f_index.01.R", "f_index.02.R", "f_index.03.R")
    assert any("leg sides swapped" in n for n in result.notes)
    assert any("arm sides swapped" in n for n in result.notes)


def test_a_rig_facing_plus_y_keeps_its_named_sides():
    data = load("rigify_metarig")
    turn = np.array([-1.0, -1.0, 1.0])  # half a turn about Z
    heads, tails = np.asarray(data["heads"]) * turn, np.asarray(data["tails"]) * turn
    result = detect_roles(data["names"], data["parents"], heads, tails)
    assert dict(result.roles.bones) == RIGIFY_METARIG
    names, back = renamed(data)
    result = detect_roles(names, data["parents"], heads, tails)
    assert {r: tuple(back[b] for b in v) for r, v in result.roles.bones.items()} == RIGIFY_METARIG


def drop_bones(data, drop):
    """Remove bones whose names satisfy drop (and their children), keeping the order."""
    keep = []
    removed = set()
    for i, (name, p) in enumerate(zip(data["names"], data["parents"])):
        if drop(name) or p in removed:
            removed.add(i)
        else:
            keep.append(i)
    new = {old: k for k, old in enumerate(keep)}
    return {
        "names": [data["names"][i] for i in keep],
        "parents": [new[data["parents"][i]] if data["parents"][i] >= 0 else -1 for i in keep],
        "heads": [data["heads"][i] for i in keep],
        "tails": [data["tails"][i] for i in keep],
    }


def test_a_rig_without_legs_is_refused_naming_them():
    data = drop_bones(load("rigify_metarig"), lambda n: n.startswith("thigh."))
    result = detect(data)
    assert set(result.missing) == {"thigh.L", "shin.L", "foot.L", "thigh.R", "shin.R", "foot.R"}
    with pytest.raises(RigError) as err:
        require_roles(result)
    message = str(err.value)
    for words in ("no left thigh", "no left shin", "no left foot", "no right thigh", "no right shin",
                  "no right foot"):
        assert words in message
    assert "pelvis" not in message and "spine" not in message
    # and the same without names
    names, _ = renamed(data)
    with pytest.raises(RigError, match="no left thigh.*no right foot"):
        require_roles(detect(data, names))


def test_a_rig_without_one_foot_names_just_that():
    data = drop_bones(load("handmade_mixamo"), lambda n: n.endswith("RightFoot"))
    with pytest.raises(RigError) as err:
        require_roles(detect(data))
    assert "no right foot" in str(err.value)
    assert "left" not in str(err.value)


def test_a_pile_of_bones_is_refused_with_every_required_role():
    rng = np.random.default_rng(0)
    heads = rng.normal(size=(6, 3))
    result = detect_roles([f"b{i}" for i in range(6)], [-1, 0, 1, 2, 3, 4], heads, heads + 0.1)
    with pytest.raises(RigError) as err:
        require_roles(result)
    assert "no pelvis" in str(err.value) and "no spine" in str(err.value)
    assert len(result.missing) == len(REQUIRED_ROLES)


def test_no_bone_between_pelvis_and_chest_makes_the_chest_the_spine():
    data = drop_bones(load("handmade_lowercase_suffix"), lambda n: False)  # a copy
    # re-parent the chest on the hips and drop the spine bone
    chest = data["names"].index("chest")
    data["parents"][chest] = data["names"].index("hips")
    data = drop_bones(data, lambda n: n == "spine")
    result = detect(data)
    assert result.roles.chain("spine") == ("chest",)
    assert result.roles.bone("chest") is None
    assert result.missing == ()
    assert any("no separate chest" in n for n in result.notes)


def test_overrides_and_role_map_round_trip():
    result = detect(load("bvh_cmu_131"))
    roles = result.roles.with_overrides({"hand.L": "lhand", "index.L": ()})
    assert roles.bone("hand.L") == "lhand" and roles.chain("index.L") == ()
    assert isinstance(roles, RoleMap)
    assert set(result.roles.bones) <= set(ALL_ROLES)


def test_every_bone_has_at_most_one_role():
    for path in RIGS.glob("*.json"):
        data = json.loads(path.read_text())
        bones = [b for v in detect(data).roles.bones.values() for b in v]
        assert len(bones) == len(set(bones)), path.name


def test_inputs_as_numpy_arrays_and_tuples():
    data = load("handmade_unreal")
    a = detect_roles(tuple(data["names"]), np.asarray(data["parents"]), np.asarray(data["heads"]),
                     np.asarray(data["tails"], dtype=np.float32))
    assert dict(a.roles.bones) == UNREAL
    with pytest.raises(RigError):
        detect_roles([], [], np.zeros((0, 3)), np.zeros((0, 3)))


DAZ_NAMES = {"hips": "hip", "spine": "abdomen", "chest": "chest", "neck": "neck", "head": "head",
             "shoulder_l": "lCollar", "upperarm_l": "lShldr", "lowerarm_l": "lForeArm", "hand_l": "lHand",
             "upperleg_l": "lThigh", "lowerleg_l": "lShin", "foot_l": "lFoot", "toes_l": "lToe"}


@pytest.mark.parametrize("style", ["bvh_daz", "names"])
def test_daz_poser_names(style):
    data = load("handmade_lowercase_suffix")
    rename = {**DAZ_NAMES, **{k[:-2] + "_r": "r" + v[1:] for k, v in DAZ_NAMES.items() if k.endswith("_l")}}
    names = [rename[n] for n in data["names"]]
    if style == "names":  # not in any table once prefixed
        names = ["Genesis_" + n for n in names]
    result = detect(data, names)
    assert result.convention == style
    expected = {r: tuple(("Genesis_" if style == "names" else "") + rename[b] for b in v)
                for r, v in LOWERCASE.items()}
    assert dict(result.roles.bones) == expected
