"""Body colliders from a skeleton: capsules fitted to the bones by body role (any rig with a
pelvis and thighs), their ends per frame from the bones' world matrices, radii from body
proportions or fitted to a skinned mesh, and a closed triangle mesh of capsules (a stand-in
skinned body)."""

from dataclasses import dataclass

import numpy as np

from ..body_roles import sided
from .mesh import ClothError

# radius over the mean thigh length (a proportion that holds across rigs whose hip joints sit
# anywhere between the pelvis centre and the skin)
RADIUS_OF = {"hips": 0.21, "torso": 0.26, "thigh": 0.17, "shin": 0.11, "foot": 0.08, "upper_arm": 0.12,
             "forearm": 0.09, "hand": 0.08}


@dataclass
class CapsuleSpec:
    name: str
    bone_a: int  # the end points live in these bones' frames (bone head at the origin, Y along it)
    local_a: np.ndarray
    bone_b: int
    local_b: np.ndarray
    radius: float
    owner: int  # the bone whose skin the capsule stands for (to fit the radius to a mesh)


def _limb(name, j, end, radius):
    return CapsuleSpec(name, j, np.zeros(3), j, end, radius, j)


def capsules_from_roles(names, lengths, roles, unit=1.0, ends=None):
    """Capsule specs for the body parts a garment can touch. Needs pelvis and both thighs.
    `lengths` are the bones' lengths in their own units, `unit` metres per such unit. ends:
    {bone index: its distal point (3,) in the bone's frame and units} for bones that do not reach
    their tail (an importer's guess: skeleton.reach_of_made_up_tail)."""
    index = {n: i for i, n in enumerate(names)}
    ends = ends or {}

    def bone(role):
        name = roles.bone(role)
        return index.get(name) if name else None

    pelvis, thighs = bone("pelvis"), [bone(sided("thigh", s)) for s in "LR"]
    if pelvis is None or None in thighs:
        raise ClothError("the rig needs pelvis and thigh roles (set them in the Rig panel) for body colliders")
    ref = float(np.mean([lengths[t] for t in thighs])) * unit
    specs = [CapsuleSpec("hips", thighs[0], np.zeros(3), thighs[1], np.zeros(3), RADIUS_OF["hips"] * ref, pelvis)]
    top = bone("chest") or bone("neck")
    spine = roles.chain("spine")
    if top is None and spine:
        top = index.get(spine[-1])
    if top is not None:
        specs.append(CapsuleSpec("torso", pelvis, np.zeros(3), top, np.zeros(3), RADIUS_OF["torso"] * ref,
                                 index.get(spine[0], pelvis) if spine else pelvis))
    for part in ("thigh", "shin", "foot", "upper_arm", "forearm", "hand"):
        for s in "LR":
            j = bone(sided(part, s))
            if j is not None and lengths[j] > 1e-6:
                end = ends.get(j, np.array([0.0, lengths[j], 0.0]))
                specs.append(_limb(f"{part}.{s}", j, end, RADIUS_OF[part] * ref))
    return specs


def capsule_ends(specs, world):
    """Ends a, b (C, 3) of the capsules for bone world matrices (J, 4, 4) in metres."""
    a = np.array([world[c.bone_a, :3, :3] @ c.local_a + world[c.bone_a, :3, 3] for c in specs])
    b = np.array([world[c.bone_b, :3, :3] @ c.local_b + world[c.bone_b, :3, 3] for c in specs])
    return a, b


def fit_radii(specs, world, points, weights, quantile=0.75):
    """Radii from a skinned mesh: the given quantile of the distances from the capsule's segment
    to the vertices weighted (>= 0.5) to its bone; specs whose bone has no such vertices keep theirs."""
    from .collision import closest_on_segments
    a, b = capsule_ends(specs, world)
    out = []
    for c, ca, cb in zip(specs, a, b):
        mine = points[weights[:, c.owner] >= 0.5]
        if len(mine) < 8:
            out.append(c.radius)
            continue
        q, _ = closest_on_segments(mine, ca[None], cb[None])
        out.append(float(np.quantile(np.linalg.norm(mine - q, axis=1), quantile)))
    return np.array(out)


def capsule_mesh(a, b, radius, segments=16, spacing=0.03, rings=None):
    """A closed triangle mesh of a capsule (outward normals): (vertices (V, 3), triangles). Rings
    along the straight part every `spacing`, or exactly `rings` of them (a fixed topology)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    axis = b - a
    length = np.linalg.norm(axis)
    w = axis / length if length > 1e-9 else np.array([0.0, 0.0, 1.0])
    u = np.cross(w, [0.0, 0.0, 1.0] if abs(w[2]) < 0.9 else [1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(w, u)
    cap_rings = max(2, segments // 4)
    # profile: (height along the axis, radius) from the bottom pole to the top pole
    profile = []
    for k in range(1, cap_rings + 1):
        t = -np.pi / 2 + k * (np.pi / 2) / cap_rings
        profile.append((radius * np.sin(t), radius * np.cos(t)))
    body = rings if rings else max(1, int(np.ceil(length / spacing)))
    profile += [(length * k / body, radius) for k in range(1, body + 1)]
    for k in range(1, cap_rings):
        t = k * (np.pi / 2) / cap_rings
        profile.append((length + radius * np.sin(t), radius * np.cos(t)))
    ang = np.linspace(0.0, 2 * np.pi, segments, endpoint=False)
    circle = np.cos(ang)[:, None] * u + np.sin(ang)[:, None] * v
    verts = [a - radius * w]
    for hgt, r in profile:
        verts.extend(a + hgt * w + r * circle)
    verts.append(b + radius * w)
    verts = np.array(verts)
    rings, s = len(profile), segments
    tris = []
    for i in range(s):  # bottom fan, pointing away from the top
        tris.append((0, 1 + (i + 1) % s, 1 + i))
    for r in range(rings - 1):
        for i in range(s):
            p, q = 1 + r * s + i, 1 + r * s + (i + 1) % s
            tris.append((p, q, q + s))
            tris.append((p, q + s, p + s))
    top = len(verts) - 1
    last = 1 + (rings - 1) * s
    for i in range(s):
        tris.append((top, last + i, last + (i + 1) % s))
    return verts, np.array(tris)


# skin radius over the mean thigh length per body role, for a stand-in body grown over the bones
SKIN_RADIUS_OF = dict(RADIUS_OF, pelvis=0.21, chest=0.26, spine=0.26, neck=0.12, head=0.22, clavicle=0.12,
                      thigh=0.17, toe=0.06)


def skin_radii(names, parents, lengths, roles, unit=1.0):
    """Per bone, the radius (metres) of a skin grown over it at its head: by the bone's body
    role (a proportion of the mean thigh length), else its parent's (a finger has its hand's, a
    hip joint bone the pelvis's)."""
    index = {n: i for i, n in enumerate(names)}
    base_of = {}
    for role, bones in roles.bones.items():
        base = role.split(".")[0]
        if base in SKIN_RADIUS_OF:
            for b in bones:
                if b in index:
                    base_of.setdefault(index[b], base)
    thighs = [index.get(roles.bone(sided("thigh", s))) for s in "LR"]
    if None in thighs:
        raise ClothError("the rig needs thigh roles to grow a body over its bones")
    ref = float(np.mean([lengths[t] for t in thighs])) * unit
    radius = np.zeros(len(names))
    for j in range(len(names)):  # parents come first
        if j in base_of:
            radius[j] = SKIN_RADIUS_OF[base_of[j]] * ref
        elif parents[j] >= 0:
            radius[j] = radius[parents[j]]
        else:
            radius[j] = SKIN_RADIUS_OF["pelvis"] * ref
    return radius


def skinning_weights(points, heads, tails, deform, blend=0.08, most=4):
    """Smooth skinning weights (V, J) from the distances of the points to the bone segments:
    the nearest bone and those within `blend` metres of as near, falling off quadratically,
    at most `most` bones a vertex, normalised. (A stand-in for Blender's automatic weights,
    which fail on grown skins in headless Blender.)"""
    from .collision import closest_on_segments
    q, _ = closest_on_segments(points[:, None], heads[None], tails[None])
    d = np.linalg.norm(points[:, None] - q, axis=2)
    d[:, ~np.asarray(deform, bool)] = np.inf
    w = np.clip(1.0 - (d - d.min(axis=1, keepdims=True)) / blend, 0.0, 1.0) ** 2
    if w.shape[1] > most:
        cut = np.partition(w, -most, axis=1)[:, -most][:, None]
        w[w < cut] = 0.0
    return w / w.sum(axis=1, keepdims=True)
