"""Segment masses, centres and inertias from anthropometric tables scaled to a rig's bones.

Source: P. de Leva, "Adjustments to Zatsiorsky-Seluyanov's segment inertia parameters",
J. Biomechanics 29(9), 1996, tables 4 (male) and 5 (female): mass as % of body mass, centre
of mass as % of segment length from the proximal end, radii of gyration as % of length
(sagittal = about the medio-lateral axis, transverse = about the antero-posterior axis,
longitudinal = about the segment axis).
"""

from dataclasses import dataclass

import numpy as np

from .body_roles import FINGERS, SIDES, sided
from .skeleton import reach_of_made_up_tail

# segment: (mass %, com % from proximal, r_sagittal %, r_transverse %, r_longitudinal %)
DE_LEVA = {
    "male": {
        "head": (6.94, 40.24, 36.2, 37.6, 31.2),  # includes the neck; com given from the vertex
        "upper_trunk": (15.96, 50.66, 50.5, 32.0, 46.5),
        "mid_trunk": (16.33, 45.02, 48.2, 38.3, 46.8),
        "lower_trunk": (11.17, 38.85, 61.5, 55.1, 58.7),  # measured from the hip centres up
        "upper_arm": (2.71, 57.72, 28.5, 26.9, 15.8),
        "forearm": (1.62, 45.74, 27.6, 26.5, 12.1),
        "hand": (0.61, 79.00, 62.8, 51.3, 40.1),
        "thigh": (14.16, 40.95, 32.9, 32.9, 14.9),
        "shank": (4.33, 44.59, 25.5, 24.9, 10.3),
        "foot": (1.37, 44.15, 25.7, 24.5, 12.4),
    },
    "female": {
        "head": (6.68, 41.06, 33.0, 35.9, 31.8),
        "upper_trunk": (15.45, 50.50, 46.6, 31.4, 44.9),
        "mid_trunk": (14.65, 45.12, 43.3, 35.4, 41.5),
        "lower_trunk": (12.47, 50.80, 43.3, 40.2, 44.4),
        "upper_arm": (2.55, 57.54, 27.8, 26.0, 14.8),
        "forearm": (1.38, 45.59, 26.1, 25.7, 9.4),
        "hand": (0.56, 74.74, 53.1, 45.4, 33.5),
        "thigh": (14.78, 36.12, 36.9, 36.4, 16.2),
        "shank": (4.81, 44.16, 27.1, 26.7, 9.3),
        "foot": (1.29, 40.14, 29.9, 27.9, 13.9),
    },
}

# de Leva's segment lengths (mm, his table 1): the hand from the wrist to the third metacarpal's
# head, the forearm from the elbow to the wrist
HAND_PER_FOREARM = {"male": 86.2 / 268.9, "female": 78.0 / 264.3}
# a hand bone (or its reach) outside these multiples of that proportion is an importer's guess
USABLE_HAND = (0.3, 2.0)

# de Leva's segments are coarser than a rig's: these splits are HumanAnim's own assumptions.
NECK_SHARE_OF_HEAD = 0.15
CLAVICLE_SHARE_OF_BODY = 0.005  # each shoulder girdle, taken from the upper trunk
FINGER_SHARE_OF_HAND = 0.30  # all finger bones together, the rest stays with the palm
TOE_SHARE_OF_FOOT = 0.20

ROLE_SEGMENT = {
    "pelvis": "lower_trunk", "spine": "mid_trunk", "chest": "upper_trunk", "neck": "head",
    "head": "head", "clavicle": "upper_trunk", "upper_arm": "upper_arm", "forearm": "forearm",
    "hand": "hand", "thigh": "thigh", "shin": "shank", "foot": "foot", "toe": "foot",
}
ROLE_SEGMENT.update({f: "hand" for f in FINGERS})

# The published ranges (the male and female tables, widened by 25 %) that a rig's fractions
# should fall in; used by tests and shown to the animator as a plausibility check.
def segment_fraction_range(segment):
    values = [DE_LEVA[s][segment][0] / 100.0 for s in DE_LEVA]
    return 0.75 * min(values), 1.25 * max(values)


@dataclass(frozen=True)
class SegmentInertia:
    mass: float
    com: np.ndarray  # world/armature point
    inertia: np.ndarray  # (3, 3) about com, same axes as com


def segment_inertia(params, total_mass, share, proximal, distal, lateral=(1.0, 0.0, 0.0)):
    """A segment from proximal to distal joint carrying `share` of its table mass."""
    mass_pct, com_pct, r_sag, r_trans, r_long = params
    mass = total_mass * mass_pct / 100.0 * share
    proximal = np.asarray(proximal, float)
    axis = np.asarray(distal, float) - proximal
    length = float(np.linalg.norm(axis))
    com = proximal + com_pct / 100.0 * axis
    if length < 1e-9:
        return SegmentInertia(mass, com, np.zeros((3, 3)))
    frame = _segment_frame(axis / length, np.asarray(lateral, float))
    radii = np.array([r_sag, r_trans, r_long]) / 100.0 * length
    inertia = frame @ np.diag(mass * radii ** 2) @ frame.T
    return SegmentInertia(mass, com, inertia)


def _segment_frame(longitudinal, lateral):
    """Columns: medio-lateral, antero-posterior, longitudinal."""
    lat = lateral - longitudinal * (lateral @ longitudinal)
    if np.linalg.norm(lat) < 1e-6:
        lat = np.array([0.0, 1.0, 0.0]) - longitudinal * longitudinal[1]
    lat /= np.linalg.norm(lat)
    return np.column_stack((lat, np.cross(longitudinal, lat), longitudinal))


def anthropometric_model(skeleton, total_mass=70.0, sex="male"):
    """Per-joint mass (J,), centre (J, 3) and inertia (J, 3, 3) in each joint's rest frame.

    Each role bone carries its whole body segment as one rigid body; bones without a role
    (helpers, twist and face bones) are massless and ride on their segment's joint."""
    table = DE_LEVA[sex]
    roles = skeleton.roles
    heads = skeleton.rest[:, :3, 3]
    tails = heads + skeleton.rest[:, :3, 1] * skeleton.lengths[:, None]

    def head(role):
        bone = roles.bone(role)
        return None if bone is None else heads[skeleton.index(bone)]

    def tail(bone):
        return tails[skeleton.index(bone)]

    parts = []  # (bone, table params, share, proximal, distal)
    chest = roles.bone("chest")
    spine = [b for b in roles.chain("spine") if b != chest]
    if chest is None and spine:
        chest = spine.pop()
    neck_head, head_head = head("neck"), head("head")
    top = neck_head if neck_head is not None else head_head
    clavicle_share = CLAVICLE_SHARE_OF_BODY * 100.0 / table["upper_trunk"][0]
    trunk = spine + ([chest] if chest else [])
    for i, bone in enumerate(trunk):
        distal = heads[skeleton.index(trunk[i + 1])] if i + 1 < len(trunk) else (
            top if top is not None else tail(bone))
        if bone == chest:
            params = table["upper_trunk"] if spine else _merge(table["upper_trunk"], table["mid_trunk"])
            parts.append((bone, params, 1.0 - 2.0 * clavicle_share, heads[skeleton.index(bone)], distal))
        else:
            parts.append((bone, table["mid_trunk"], _length_share(skeleton, spine, bone),
                          heads[skeleton.index(bone)], distal))
    pelvis = roles.bone("pelvis")
    hips = [head(sided("thigh", s)) for s in SIDES if head(sided("thigh", s)) is not None]
    pelvis_bottom = np.mean(hips, axis=0) if hips else heads[skeleton.index(pelvis)]
    pelvis_top = heads[skeleton.index(trunk[0])] if trunk else tail(pelvis)
    if np.linalg.norm(pelvis_top - pelvis_bottom) < 1e-3:
        pelvis_top = tail(pelvis)
    parts.append((pelvis, table["lower_trunk"], 1.0, pelvis_bottom, pelvis_top))
    if roles.bone("neck"):
        parts.append((roles.bone("neck"), table["head"], NECK_SHARE_OF_HEAD, neck_head, head_head
                      if head_head is not None else tail(roles.bone("neck"))))
    if roles.bone("head"):
        share = 1.0 - NECK_SHARE_OF_HEAD if roles.bone("neck") else 1.0
        parts.append((roles.bone("head"), table["head"], share, head_head, tail(roles.bone("head"))))
    for side in SIDES:
        parts.extend(_limb_parts(skeleton, table, side, clavicle_share, head, tail, sex))
    return _assemble(skeleton, total_mass, parts)


def _limb_parts(skeleton, table, side, clavicle_share, head, tail, sex="male"):
    roles = skeleton.roles
    chain = [("clavicle", "upper_trunk", clavicle_share), ("upper_arm", "upper_arm", 1.0),
             ("forearm", "forearm", 1.0), ("thigh", "thigh", 1.0), ("shin", "shank", 1.0)]
    following = {"clavicle": "upper_arm", "upper_arm": "forearm", "forearm": "hand",
                 "thigh": "shin", "shin": "foot"}
    for kind, segment, share in chain:
        bone = roles.bone(sided(kind, side))
        if bone:
            distal = head(sided(following[kind], side))
            yield bone, table[segment], share, head(sided(kind, side)), (
                tail(bone) if distal is None else distal)
    fingers = [b for f in FINGERS for b in roles.chain(sided(f, side))]
    hand = roles.bone(sided("hand", side))
    if hand:
        middle = roles.chain(sided("middle", side))
        distal = (
            skeleton.rest[skeleton.index(middle[0]), :3, 3] if middle else _reach(skeleton, hand, tail))
        distal = _proportionate_hand(head(sided("forearm", side)), head(sided("hand", side)), distal,
                                     HAND_PER_FOREARM[sex])
        yield hand, table["hand"], 1.0 - (FINGER_SHARE_OF_HAND if fingers else 0.0), \
            head(sided("hand", side)), distal
    for bone in fingers:
        rod = (table["hand"][0], 50.0, 30.0, 30.0, 10.0)
        yield bone, rod, FINGER_SHARE_OF_HAND * _length_share(skeleton, fingers, bone), \
            skeleton.rest[skeleton.index(bone), :3, 3], tail(bone)
    foot, toe = roles.bone(sided("foot", side)), roles.bone(sided("toe", side))
    if foot:
        yield foot, table["foot"], 1.0 - (TOE_SHARE_OF_FOOT if toe else 0.0), \
            head(sided("foot", side)), tail(toe) if toe else tail(foot)
    if toe:
        rod = (table["foot"][0], 50.0, 30.0, 30.0, 15.0)
        yield toe, rod, TOE_SHARE_OF_FOOT, head(sided("toe", side)), tail(toe)


def _proportionate_hand(elbow, wrist, distal, per_forearm):
    """The hand's distal end, or where the body's proportions put it when the rig gives no usable
    hand: a zero-length hand an importer lengthened (Blender continues a leaf bone with a zero End
    Site along its parent, at the parent's length: Bandai Namco's clips) or shortened to a stub.
    The hand then reaches along the forearm by de Leva's hand-to-forearm proportion, so that its
    centre, and a load carried in it, sit in the palm whatever the bone's length."""
    if elbow is None:
        return distal
    forearm = wrist - elbow
    length = float(np.linalg.norm(forearm))
    expected = per_forearm * length
    if length <= 0.0 or USABLE_HAND[0] * expected <= np.linalg.norm(distal - wrist) <= USABLE_HAND[1] * expected:
        return distal
    return wrist + forearm / length * expected


def _reach(skeleton, bone, tail):
    """The bone's distal end: its tail, unless an importer made that up (CMU's wrists)."""
    reach = reach_of_made_up_tail(skeleton.parents, skeleton.rest[:, :3, 3], skeleton.index(bone))
    return tail(bone) if reach is None else reach


def _length_share(skeleton, bones, bone):
    lengths = np.array([skeleton.lengths[skeleton.index(b)] for b in bones])
    if lengths.sum() <= 0.0:
        return 1.0 / len(bones)
    return float(lengths[bones.index(bone)] / lengths.sum())


def _merge(a, b):
    """One table segment standing for two (a rig with no separate chest)."""
    return (a[0] + b[0],) + tuple(0.5 * (x + y) for x, y in zip(a[1:], b[1:]))


def _assemble(skeleton, total_mass, parts):
    n = skeleton.joint_count
    mass, com, inertia = np.zeros(n), np.zeros((n, 3)), np.zeros((n, 3, 3))
    for bone, params, share, proximal, distal in parts:
        seg = segment_inertia(params, total_mass, share, proximal, distal)
        j = skeleton.index(bone)
        rot, origin = skeleton.rest[j, :3, :3], skeleton.rest[j, :3, 3]
        mass[j] = seg.mass
        com[j] = rot.T @ (seg.com - origin)
        inertia[j] = rot.T @ seg.inertia @ rot
    # the table's shares sum to 100 % only on a complete body: scale to the set total
    if mass.sum() > 0.0:
        scale = total_mass / mass.sum()
        mass, inertia = mass * scale, inertia * scale
    return mass, com, inertia
