"""Automatic body-role detection: which bone is the pelvis, the left thigh, the right index finger.

Works on plain arrays (no bpy): bone names in parents-before-children order, parent indices
(-1 for a root) and rest heads/tails in armature space (Z up; Blender's front is -Y, so the
character's left is +X; a rig whose toes point +Y is taken to face +Y and its left is -X).

Detection runs in four stages, each filling only the roles still missing:

1. Convention tables (solver/rig_conventions, one module per rig convention). Every table is
   scored by the distinct bones it finds (required roles count double), plus a bonus for each
   pair of roles in the right parent order and a penalty for each pair in the reverse order;
   the best table above a minimum is applied.
2. A name-keyword matcher: names are split at `. _ - : space`, camelCase and digits,
   namespaces (`mixamorig:`) and rig prefixes (`DEF`, `J_Bip_C`, `Bip01`, `CC_Base`,
   `Character1_`) are dropped, and so are unknown leading words when the whole does not match, the side is read from L/R, Left/Right, l_/r_, .L/.R, _l/_r
   (or `left`/`right` anywhere), and the rest is matched to a kind of bone (thigh, calf,
   upperarm, ...). Roles are then assembled down each chain by the hierarchy: a shin is the
   most proximal shin-like bone below the thigh, and so on.
3. A structure fallback from geometry and hierarchy only: the pelvis is the common ancestor
   of the two lowest bones (the feet, one each side) and the highest bone near the midline
   (the head); each leg runs from the pelvis to its lowest bone (thigh = first long downward
   bone, foot = first bone starting near the ground, shin = the bone starting nearest the
   middle between them, toe = the foot's child reaching farthest forward); the arms are the
   two side branches of the pelvis-to-head chain that reach farthest; the hand is where the
   arm branches into fingers (else its fourth joint), forearm, upper arm and clavicle are the
   joints before it; fingers are ordered front to back (thumb first).
4. Validation: the chest is the trunk bone the clavicles branch from, the spine chain is what
   lies between pelvis and chest, roles in the wrong parent order are dropped, sides follow
   geometry where names disagree, and no bone carries two roles.

Rules for which bone carries a role:

- A role names the proximal bone of its body segment, the one rotating at the joint where
  the segment starts; bones following it in a row belong to the same segment (Rigify's
  DEF-thigh.L.001 belongs to the thigh; CMU's lhand follows the zero-length LeftWrist, which
  carries the thumb too, so hand = LeftWrist). Bones between two roles belong to the
  proximal role (CMU LHipJoint is part of the pelvis, Rigify palm bones part of the hand).
- chest = the trunk bone from which the clavicles branch; when that bone has zero length
  (its children start at its head, like CMU's Chest2) or is a neck bone (3ds Max Biped
  hangs the clavicles on the neck), the chest is the bone below it.
- spine = the bones strictly between pelvis and chest, proximal to distal. When there is no
  bone between them, the chest bone alone forms the spine and the chest role stays empty
  (the spine is required, the chest is not); when there is no chest (no arms), the spine is
  the bones between pelvis and neck (or head).
- neck = the first bone above the chest segment (Rigify spine.004, CMU lowerneck); further
  neck bones (spine.005, Neck1) belong to it. head = the bone carrying the skull; an end
  bone at the top of the head (HeadTop_End) carries no role.
- Finger chains list the phalanges proximal to distal: metacarpal/palm bones belong to the
  hand, and a fourth bone at the tip (Mixamo's LeftHandIndex4) is an end marker, not a
  phalanx. A finger chain is at most three bones long.
"""

import re
from dataclasses import dataclass

import numpy as np

from . import rig_conventions
from .body_roles import ALL_ROLES, CHAIN_ROLES, FINGERS, REQUIRED_ROLES, SIDES, RoleMap, sided
from .errors import RigError


@dataclass(frozen=True)
class RoleDetection:
    roles: RoleMap
    convention: str  # a table name (e.g. "rigify_metarig", "mixamo"), "names" or "structure"
    missing: tuple  # required roles not found
    notes: tuple  # human-readable remarks


# Pairs (proximal role, distal role) that must sit in this parent order.
def _order_pairs():
    pairs = [("pelvis", "spine"), ("spine", "chest"), ("chest", "neck"), ("neck", "head")]
    for s in SIDES:
        r = lambda name: sided(name, s)  # noqa: E731
        pairs += [("pelvis", r("thigh")), (r("thigh"), r("shin")), (r("shin"), r("foot")),
                  (r("foot"), r("toe")), ("chest", r("clavicle")), (r("clavicle"), r("upper_arm")),
                  (r("upper_arm"), r("forearm")), (r("forearm"), r("hand"))]
        pairs += [(r("hand"), r(f)) for f in FINGERS]
    return tuple(pairs)


ORDER_PAIRS = _order_pairs()
LIMB_ROLES = {
    "leg": ("thigh", "shin", "foot", "toe"),
    "arm": ("clavicle", "upper_arm", "forearm", "hand") + FINGERS,
}
_SIDE_WORDS = {"L": "left", "R": "right"}
_PLAIN = {"upper_arm": "upper arm", "pinky": "little finger", "thumb": "thumb",
          "index": "index finger", "middle": "middle finger", "ring": "ring finger"}


def describe_role(role):
    """Plain words for a role: 'thigh.L' -> 'left thigh', 'spine' -> 'spine'."""
    base, _, side = role.partition(".")
    words = _PLAIN.get(base, base.replace("_", " "))
    return f"{_SIDE_WORDS[side]} {words}" if side else words


def detect_roles(names, parents, heads, tails, deform=None):
    """Find the body roles of an armature; see the module docstring.

    `deform` (optional, one bool a bone) limits the name matcher and the structure fallback
    to deforming bones when some bones do not deform (control rigs).
    """
    rig = _Rig(names, parents, heads, tails, deform)
    notes = []
    roles = {}
    used = set()
    source = {}

    convention, table_roles = _best_table(rig)
    if convention:
        for role, idx in table_roles.items():
            _assign(roles, used, role, idx)
            source[role] = convention

    before = set(roles)
    _keyword_fill(rig, roles, used)
    for role in set(roles) - before:
        source[role] = "names"

    before = set(roles)
    _structure_fill(rig, roles, used, notes)
    for role in set(roles) - before:
        source[role] = "structure"

    _finalize(rig, roles, used, notes)

    found = {r: src for r, src in source.items() if r in roles}
    by_stage = {}
    for role in REQUIRED_ROLES:
        if role in found:
            by_stage[found[role]] = by_stage.get(found[role], 0) + 1
    # the stage that found most required roles names the convention (a table wins ties)
    if by_stage:
        label = max(by_stage, key=lambda k: (by_stage[k], k == convention))
    else:
        label = convention or "structure"
    filled = sorted({describe_role(r) for r, src in found.items() if src == "names" and label != "names"})
    if filled:
        notes.append("found by name: " + ", ".join(filled))
    filled = sorted({describe_role(r) for r, src in found.items()
                     if src == "structure" and label != "structure"})
    if filled:
        notes.append("inferred from the hierarchy and geometry: " + ", ".join(filled))

    ordered = {r: tuple(rig.names[i] for i in roles[r]) for r in ALL_ROLES if roles.get(r)}
    role_map = RoleMap(ordered)
    return RoleDetection(role_map, label, tuple(role_map.missing()), tuple(notes))


def require_roles(detection):
    """The detected RoleMap, or RigError naming every missing required role."""
    missing = detection.missing if isinstance(detection, RoleDetection) else detection.missing()
    roles = detection.roles if isinstance(detection, RoleDetection) else detection
    if missing:
        words = ", ".join("no " + describe_role(r) for r in missing)
        raise RigError(f"This armature cannot be used as a body: {words}. "
                       "Assign the missing body roles by hand.")
    return roles


# ----------------------------------------------------------------------------- the rig


class _Rig:
    def __init__(self, names, parents, heads, tails, deform):
        self.names = [str(n) for n in names]
        n = len(self.names)
        self.parents = np.asarray(parents, dtype=int).reshape(n)
        self.heads = np.asarray(heads, dtype=float).reshape(n, 3)
        self.tails = np.asarray(tails, dtype=float).reshape(n, 3)
        if n == 0:
            raise RigError("the armature has no bones")
        if np.any(self.parents >= np.arange(n)):
            raise RigError("bones must be ordered parents before children")
        self.n = n
        self.children = [[] for _ in range(n)]
        self.depth = np.zeros(n, dtype=int)
        for j, p in enumerate(self.parents):
            if p >= 0:
                self.children[p].append(j)
                self.depth[j] = self.depth[p] + 1
        body = np.ones(n, bool) if deform is None else np.asarray(deform, bool).reshape(n)
        if not body.any():
            body = np.ones(n, bool)
        self.mid = 0.5 * (self.heads + self.tails)
        # helpers: leaves lying inside their parent's segment (twist, roll, correctives)
        for j, p in enumerate(self.parents):
            if p >= 0 and not self.children[j] and self._inside(p, j):
                body[j] = False
        self.body = body
        pts = np.concatenate([self.heads[body], self.tails[body]])
        self.zmin = float(pts[:, 2].min())
        self.height = max(float(pts[:, 2].max()) - self.zmin, 1e-9)
        self.eps = 0.004 * self.height
        self.lookup_exact = {}
        self.lookup_plain = {}
        self.lookup_lower = {}
        for i, name in enumerate(self.names):
            plain = name.rsplit(":", 1)[-1]
            self.lookup_exact.setdefault(name, i)
            self.lookup_plain.setdefault(plain, i)
            self.lookup_lower.setdefault(plain.lower(), i)

    def _inside(self, p, j):
        axis = self.tails[p] - self.heads[p]
        length2 = float(axis @ axis)
        if length2 <= 0:
            return False
        for point in (self.heads[j], self.tails[j]):
            t = float((point - self.heads[p]) @ axis) / length2
            off = point - self.heads[p] - t * axis
            if not -0.02 <= t <= 1.02 or float(off @ off) > 0.01 * length2:
                return False
        return True

    def find(self, name):
        for table, key in ((self.lookup_exact, name), (self.lookup_plain, name),
                           (self.lookup_lower, name.lower())):
            if key in table:
                return table[key]
        return None

    def is_ancestor(self, a, b):
        """True when a is a proper ancestor of b."""
        b = self.parents[b]
        while b >= 0:
            if b == a:
                return True
            b = self.parents[b]
        return False

    def path(self, a, b):
        """Bones from a (exclusive) down to b (inclusive); None when a is not an ancestor."""
        out = []
        while b >= 0 and b != a:
            out.append(b)
            b = self.parents[b]
        return out[::-1] if b == a else None

    def chain_up(self, b):
        out = [b]
        while self.parents[out[-1]] >= 0:
            out.append(self.parents[out[-1]])
        return out

    def lca(self, bones):
        bones = list(bones)
        common = self.chain_up(bones[0])
        for b in bones[1:]:
            up = set(self.chain_up(b))
            common = [c for c in common if c in up]
        return common[0] if common else None

    def subtree(self, b):
        out, stack = [], [b]
        while stack:
            k = stack.pop()
            out.append(k)
            stack.extend(self.children[k])
        return out

    def zero_length(self, b):
        """A bone whose children all start at its own head: a joint without a segment."""
        kids = self.children[b]
        if not kids:
            return float(np.linalg.norm(self.tails[b] - self.heads[b])) < self.eps
        return all(np.linalg.norm(self.heads[k] - self.heads[b]) < self.eps for k in kids)

    def same_joint(self, a, b):
        return float(np.linalg.norm(self.heads[a] - self.heads[b])) < self.eps


def _assign(roles, used, role, idx):
    idx = [i for i in idx if i is not None and i not in used]
    if role in roles or not idx:
        return False
    roles[role] = idx
    used.update(idx)
    return True


def _clear(roles, used, role):
    for i in roles.pop(role, ()):
        used.discard(i)


def _first(roles, role):
    v = roles.get(role)
    return v[0] if v else None


# ----------------------------------------------------------------------------- 1. tables

_MIN_TABLE_SCORE = 6.0


def _apply_table(rig, table):
    roles, used = {}, set()
    # singles first: chains may list a bone a single role also names (alternatives)
    for role, names in sorted(table.items(), key=lambda kv: kv[0] in CHAIN_ROLES):
        names = (names,) if isinstance(names, str) else tuple(names)
        if role in CHAIN_ROLES:
            _assign(roles, used, role, [rig.find(n) for n in names])
        else:
            found = [rig.find(n) for n in names]
            found = [i for i in found if i is not None and i not in used]
            _assign(roles, used, role, found[:1])
    return roles


def _order_score(rig, roles):
    ordered = inverted = 0
    for a, b in ORDER_PAIRS:
        ia, ib = _first(roles, a), _first(roles, b)
        if ia is None or ib is None:
            continue
        if rig.is_ancestor(ia, ib):
            ordered += 1
        elif ia == ib or rig.is_ancestor(ib, ia):
            inverted += 1
    return ordered, inverted


def _table_score(rig, roles):
    score = 0.0
    for role, idx in roles.items():
        score += len(idx) * (2.0 if role in REQUIRED_ROLES else 1.0)
    ordered, inverted = _order_score(rig, roles)
    return score + 0.5 * ordered - 3.0 * inverted


def _best_table(rig):
    best, best_score, best_roles = None, _MIN_TABLE_SCORE, None
    for name, table in rig_conventions.all_tables().items():
        roles = _apply_table(rig, table)
        score = _table_score(rig, roles)
        if score > best_score:
            best, best_score, best_roles = name, score, roles
    return best, best_roles or {}


# ----------------------------------------------------------------------------- 2. names

_SEPARATORS = re.compile(r"[.\-_:\s|/\\]+")
_WORDS = re.compile(r"[A-Z]+(?=[A-Z][a-z])|[A-Z]?[a-z]+|[A-Z]+|\d+")
_NOISE = {"def", "deform", "j", "bip", "c", "cc", "base", "mixamorig", "character", "rig", "b",
          "bn", "jnt", "bone", "bones", "skel", "sk", "armature", "f", "m", "g", "mhx", "x", "valve",
          "biped", "ctr", "center", "centre", "mid"}
_EXCLUDE = {"twist", "roll", "end", "nub", "tip", "top", "ik", "fk", "pole", "target", "mch", "org",
            "ctrl", "control", "con", "helper", "aux", "corrective", "prop", "weapon", "socket",
            "offset", "parent", "tweak", "jiggle", "bend", "hair", "skirt", "ear", "eye", "eyes",
            "jaw", "breast", "bust", "tongue", "teeth", "lip", "lid", "brow", "cheek", "nose", "chin",
            "face", "heel", "root", "world", "master", "ground", "trajectory", "metacarpal", "meta",
            "palm", "carpal", "rot", "snap", "gizmo", "wgt", "ref", "pivot", "mouth", "eyelid",
            "share", "upv", "vis", "mesh", "cloth", "armor", "attach", "attachment"}
_LEFT = {"l", "left", "lft", "lt"}
_RIGHT = {"r", "right", "rgt", "rt"}

_FINGER_WORDS = {"thumb": r"thumb", "index": r"index|pointer|fore", "middle": r"middle|mid",
                 "ring": r"ring", "pinky": r"pinky|pinkie|little|small|baby"}
_KINDS = (
    # kind, pattern (full match of the core words), sided
    ("pelvis", r"hips?|pelvis|hipscenter|hipcenter", False),
    ("trunk", r"spine\w*|\w*back|abdomen\w*|abs|torso|waist|\w*chest\w*|thorax|ribcage|belly|stomach",
     False),
    ("neck", r"\w*neck\w*", False),
    ("head", r"head", False),
    ("clavicle", r"clavicle|collar\w*|scapula|clav", True),
    ("shoulder", r"shoulder|shldr", True),
    ("forearm", r"forearm|lowerarm|loarm|armlower|elbow|radius|ulna|lowarm", True),
    ("upper_arm", r"upperarm|uparm|arm|armupper|humerus|bicep", True),
    ("hand", r"hand|wrist", True),
    ("thigh", r"thigh|upleg|upperleg|legupper|femur|hip", True),
    ("shin", r"shin|calf|leg|lowerleg|loleg|leglower|lowleg|knee|crus|tibia", True),
    ("foot", r"foot|ankle", True),
    ("toe", r"toes?|toebase|toesbase|ball|toe[a-z]*base", True),
) + tuple(
    (f, rf"(hand|finger)?({w})(finger)?(proximal|intermediate|distal|prox|inter|dist)?", True)
    for f, w in _FINGER_WORDS.items()
) + (("fingers", r"fingers", True),)
_KIND_RE = tuple((k, re.compile(p), s) for k, p, s in _KINDS)


def _tokens(name):
    name = name.rsplit(":", 1)[-1]
    out = []
    for part in _SEPARATORS.split(name):
        for word in _WORDS.findall(part):
            out.append(word.lower())
    return out


def _kind_of_core(core, is_sided):
    for kind, regex, needs_side in _KIND_RE:
        if needs_side == is_sided and regex.fullmatch(core):
            return kind
    return None


def _classify(name):
    """(kind, side, digits) for a bone name, or (None, side, digits)."""
    tokens = _tokens(name)
    side = None
    words, digits = [], []
    for t in tokens:
        if t in _LEFT or t in _RIGHT:
            s = "L" if t in _LEFT else "R"
            side = s if side in (None, s) else "?"
            continue
        if t.isdigit():
            digits.append(t)
            continue
        # "lhand", "rShldr" (split already), "leftupleg"
        for prefix, s in (("left", "L"), ("right", "R")):
            if t.startswith(prefix) and len(t) > len(prefix):
                t = t[len(prefix):]
                side = s if side in (None, s) else "?"
                break
        else:
            if (len(t) > 2 and t[0] in "lr" and _kind_of_core(t, False) is None
                    and _kind_of_core(t, True) is None
                    and (_kind_of_core(t[1:], True) or t[1:] in _EXCLUDE)):
                side = ("L" if t[0] == "l" else "R") if side is None else side
                t = t[1:]
        words.append(t)
    if side == "?":
        return None, None, digits
    if any(w in _EXCLUDE for w in words):
        return None, side, digits
    words = [w for w in words if w not in _NOISE]
    if "".join(words) == "finger" and side and digits:
        # 3ds Max Biped: Finger0 thumb, Finger1 index, ... Finger01 second phalanx of the thumb
        k = int(digits[-1][0])
        return (FINGERS[k] if k < len(FINGERS) else None), side, digits
    # the whole name, else without its leading words (an unknown prefix like "Genesis_")
    for start in range(len(words)):
        kind = _kind_of_core("".join(words[start:]), side is not None)
        if kind:
            return kind, side, digits
    return None, side, digits


def _keyword_fill(rig, roles, used):
    kinds = {}
    for i, name in enumerate(rig.names):
        if not rig.body[i]:
            continue
        kind, side, _ = _classify(name)
        if kind:
            kinds.setdefault((kind, side), []).append(i)

    def pick(kind, side=None, under=None, extra=()):
        cands = [i for i in list(kinds.get((kind, side), ())) + list(extra) if i not in used]
        if under is not None:
            cands = [i for i in cands if rig.is_ancestor(under, i)]
        if not cands:
            return None
        return min(cands, key=lambda i: (rig.depth[i], i))

    thighs = [i for s in SIDES for i in kinds.get(("thigh", s), ())]
    if "pelvis" not in roles:
        cands = [i for i in kinds.get(("pelvis", None), ()) if i not in used]
        over = [i for i in cands if any(rig.is_ancestor(i, t) for t in thighs)]
        cands = over or cands
        if cands:
            _assign(roles, used, "pelvis", [min(cands, key=lambda i: (rig.depth[i], i))])
    pelvis = _first(roles, "pelvis")

    for s in SIDES:
        anchor = pelvis
        for part in LIMB_ROLES["leg"]:
            role = sided(part, s)
            if role not in roles:
                found = pick(part, s, under=anchor)
                if found is None:  # a control rig may hang its deform bones elsewhere
                    found = pick(part, s)
                _assign(roles, used, role, [found])
            anchor = _first(roles, role) if role in roles else anchor

        # "shoulder" is the clavicle when an upper-arm bone hangs below it, else the upper arm
        as_clavicle, as_upper = [], []
        uppers = kinds.get(("upper_arm", s), ())
        for b in kinds.get(("shoulder", s), ()):
            (as_clavicle if any(rig.is_ancestor(b, u) for u in uppers) else as_upper).append(b)
        anchor = None
        for part, extra in (("clavicle", as_clavicle), ("upper_arm", as_upper),
                            ("forearm", ()), ("hand", ())):
            role = sided(part, s)
            if role not in roles:
                found = pick(part, s, under=anchor, extra=extra)
                if found is None and anchor is not None:  # deform arms hung from mechanism bones
                    found = pick(part, s, extra=extra)
                _assign(roles, used, role, [found])
            anchor = _first(roles, role) if role in roles else anchor

        hand = _first(roles, sided("hand", s))
        if hand is not None:
            for f in FINGERS:
                role = sided(f, s)
                if role in roles:
                    continue
                cands = [i for i in kinds.get((f, s), ()) if i not in used and rig.is_ancestor(hand, i)]
                if not cands and f == "index":
                    cands = [i for i in kinds.get(("fingers", s), ())
                             if i not in used and rig.is_ancestor(hand, i)]
                _assign(roles, used, role, _finger_chain(rig, cands))

    if "neck" not in roles:
        _assign(roles, used, "neck", [pick("neck", None, under=pelvis)])
    if "head" not in roles:
        _assign(roles, used, "head", [pick("head", None, under=_first(roles, "neck") or pelvis)])
    if "chest" not in roles:
        trunk = [i for i in kinds.get(("trunk", None), ()) if i not in used]
        clav = [_first(roles, sided(p, s)) for s in SIDES for p in ("clavicle", "upper_arm")]
        clav = [c for c in clav if c is not None]
        if trunk and clav:
            holders = [t for t in trunk if all(rig.is_ancestor(t, c) for c in clav)]
            if holders:
                _assign(roles, used, "chest", [max(holders, key=lambda i: rig.depth[i])])
    if "spine" not in roles and pelvis is not None:
        trunk = sorted((i for i in kinds.get(("trunk", None), ())
                        if i not in used and rig.is_ancestor(pelvis, i)), key=lambda i: rig.depth[i])
        _assign(roles, used, "spine", trunk)


def _finger_chain(rig, cands):
    """The longest run of candidates each the ancestor of the next, at most 3 phalanges."""
    if not cands:
        return []
    cands = sorted(cands, key=lambda i: (rig.depth[i], i))
    chain = [cands[0]]
    for c in cands[1:]:
        if rig.is_ancestor(chain[-1], c):
            chain.append(c)
    if len(chain) > 3 and not rig.children[chain[-1]]:
        chain = chain[:-1]  # an end bone at the tip (Mixamo LeftHandIndex4)
    return chain[-3:]


# ----------------------------------------------------------------------------- 3. structure


def _structure_fill(rig, roles, used, notes):
    H, z0 = rig.height, rig.zmin
    body = np.flatnonzero(rig.body)
    low = np.minimum(rig.heads[:, 2], rig.tails[:, 2])
    high = np.maximum(rig.heads[:, 2], rig.tails[:, 2])

    # head top: the highest bone near the midline
    mid = [i for i in body if abs(rig.mid[i, 0]) < 0.1 * H]
    if not mid:
        return
    top = max(mid, key=lambda i: (high[i], -rig.depth[i]))

    # feet: the lowest bone on each side
    tips = {}
    for sign in (1, -1):
        cands = [i for i in body if sign * rig.mid[i, 0] > 0.02 * H and low[i] < z0 + 0.1 * H]
        if cands:
            tips[sign] = min(cands, key=lambda i: (round(low[i] / rig.eps), -rig.depth[i]))
    pelvis = _first(roles, "pelvis")
    if pelvis is None:
        if len(tips) < 2:
            return
        pelvis = rig.lca([tips[1], tips[-1], top])
        if pelvis is None or rig.heads[pelvis, 2] < z0 + 0.25 * H:
            return
        _assign(roles, used, "pelvis", [pelvis])

    legs = {sign: rig.path(pelvis, tip) for sign, tip in tips.items()}
    legs = {sign: path for sign, path in legs.items() if path}
    forward = _forward(rig, roles, legs)
    left_sign = 1 if forward[1] <= 0 else -1
    side_of = {left_sign: "L", -left_sign: "R"}
    for sign, path in legs.items():
        _structure_leg(rig, roles, used, side_of[sign], path, forward)

    trunk = rig.path(pelvis, top) or []
    leg_bones = {b for path in legs.values() for b in path}
    if top not in trunk:
        return
    # an end bone on top of the skull (HeadTop_End, HeadNub) starts above where a head joint can
    # be: the hip joint is at about 0.53 of the stature, the skull base at about 0.87-0.9.
    hip_height = [rig.heads[_first(roles, sided("thigh", s)), 2] - z0 for s in SIDES
                  if _first(roles, sided("thigh", s)) is not None]
    if hip_height and len(trunk) > 1 and not rig.children[trunk[-1]]:
        stature = float(np.mean(hip_height)) / 0.53
        if rig.heads[trunk[-1], 2] - z0 > 0.97 * stature:
            trunk = trunk[:-1]
    head = trunk[-1] if trunk else None

    arms = {}
    for b in [pelvis] + trunk:
        for c in rig.children[b]:
            if c in trunk or c in leg_bones or not rig.body[c]:
                continue
            sub = [k for k in rig.subtree(c) if rig.body[k]]
            if any(t in sub for t in tips.values()):
                continue
            pts = np.concatenate([rig.heads[sub], rig.tails[sub]])
            dist = np.linalg.norm(pts - rig.heads[c], axis=1)
            k = int(np.argmax(dist))
            if dist[k] < 0.2 * H or abs(pts[k, 0]) < 0.08 * H:
                continue
            sign = 1 if pts[k, 0] > 0 else -1
            far = sub[k % len(sub)]
            if sign not in arms or dist[k] > arms[sign][0]:
                arms[sign] = (dist[k], b, far)
    branch_points = []
    for sign, (_, b, far) in arms.items():
        branch_points.append(b)
        _structure_arm(rig, roles, used, side_of[sign], rig.path(b, far), forward)

    if branch_points:
        branch = min(branch_points, key=lambda b: rig.depth[b])
        above = [t for t in trunk if rig.depth[t] > rig.depth[branch]]
        if branch != pelvis:
            chest = branch
            while rig.zero_length(chest) and rig.parents[chest] >= 0 and rig.parents[chest] != pelvis:
                chest = rig.parents[chest]
            _assign(roles, used, "chest", [chest])
        above = [t for t in above if not (rig.zero_length(t) and rig.same_joint(t, branch))]
        if head is not None and "head" not in roles:
            _assign(roles, used, "head", [head])
        if above and above[0] != _first(roles, "head"):
            _assign(roles, used, "neck", [above[0]])
    elif head is not None and head != pelvis:
        _assign(roles, used, "head", [head])


def _forward(rig, roles, legs):
    """Unit horizontal direction the character faces: where the feet point (default -Y).

    Feet are the foot roles, else on each leg path the first bone starting near the ground.
    """
    v = np.zeros(3)
    for s in SIDES:
        foot = _first(roles, sided("foot", s))
        if foot is not None:
            v += rig.tails[foot] - rig.heads[foot]
    if not v.any():
        for path in legs.values():
            feet = [b for b in path if rig.heads[b, 2] < rig.zmin + 0.1 * rig.height]
            if feet:
                v += rig.tails[feet[0]] - rig.heads[feet[0]]
    v[2] = 0.0
    if abs(v[1]) < 1e-3 * rig.height:
        return np.array([0.0, -1.0, 0.0])
    return np.array([0.0, -1.0 if v[1] < 0 else 1.0, 0.0])


def _segment_starts(rig, path):
    """The first bone at each distinct joint along a path (zero-length bones join the next)."""
    out = []
    for b in path:
        if out and rig.same_joint(out[-1], b):
            continue
        out.append(b)
    return out


def _structure_leg(rig, roles, used, side, path, forward):
    H, z0 = rig.height, rig.zmin
    names = {p: sided(p, side) for p in LIMB_ROLES["leg"]}
    known = {p: _first(roles, r) for p, r in names.items()}
    thigh = known["thigh"]
    if thigh is None:
        down = [b for b in path if rig.heads[b, 2] - rig.tails[b, 2] > 0.12 * H]
        thigh = down[0] if down else None
        if thigh is None:
            return
        _assign(roles, used, names["thigh"], [thigh])
    if thigh not in path:
        return
    after = path[path.index(thigh) + 1:]
    foot = known["foot"]
    if foot is None:
        feet = [b for b in _segment_starts(rig, after) if rig.heads[b, 2] < z0 + 0.1 * H]
        foot = feet[0] if feet else None
        if foot is not None:
            _assign(roles, used, names["foot"], [foot])
    if known["shin"] is None and foot is not None and foot in after:
        between = _segment_starts(rig, after[:after.index(foot)])
        if between:
            knee = 0.5 * (rig.heads[thigh, 2] + rig.heads[foot, 2])
            shin = min(between, key=lambda b: abs(rig.heads[b, 2] - knee))
            _assign(roles, used, names["shin"], [shin])
    if known["toe"] is None and foot is not None:
        seg = [foot] + [k for k in rig.subtree(foot) if k != foot and rig.same_joint(k, foot)]
        kids = [k for b in seg for k in rig.children[b] if not rig.same_joint(k, foot) and rig.body[k]]
        if kids:
            ahead = lambda k: float(np.dot(rig.heads[k] - rig.heads[foot], forward))  # noqa: E731
            toe = max(kids, key=ahead)
            if ahead(toe) > 0.02 * H:
                _assign(roles, used, names["toe"], [toe])


def _structure_arm(rig, roles, used, side, path, forward):
    if not path:
        return
    names = {p: sided(p, side) for p in LIMB_ROLES["arm"]}
    hand = _first(roles, names["hand"])
    if hand is None:
        starts = _segment_starts(rig, path)
        for b in starts:
            seg = [b] + [k for k in rig.subtree(b) if k != b and rig.same_joint(k, b)]
            kids = {k for s in seg for k in rig.children[s] if k not in seg and rig.body[k]}
            if len(kids) >= 2 and starts.index(b) >= 2:
                hand = b
                break
        if hand is None and len(starts) >= 4:
            hand = starts[3]
        if hand is None:
            return
        _assign(roles, used, names["hand"], [hand])
    if hand in path:
        before = _segment_starts(rig, path[:path.index(hand)])
        for part, k in (("forearm", 1), ("upper_arm", 2), ("clavicle", 3)):
            if len(before) >= k and names[part] not in roles:
                _assign(roles, used, names[part], [before[-k]])
    # fingers: chains from the hand to each leaf, ordered front to back (thumb first)
    if any(names[f] in roles for f in FINGERS):
        return
    leaves = [k for k in rig.subtree(hand) if not rig.children[k] and k != hand and rig.body[k]]
    chains = []
    for leaf in leaves:
        c = rig.path(hand, leaf)
        while len(c) > 1 and rig.same_joint(c[0], hand):
            c = c[1:]  # the palm starting at the wrist (CMU lhand) belongs to the hand
        chains.append(c)
    counts = {}
    for c in chains:
        for b in c:
            counts[b] = counts.get(b, 0) + 1
    chains = [[b for b in c if counts[b] == 1] for c in chains]
    chains = [c for c in chains if c]
    if not chains or len(chains) > len(FINGERS):
        return
    trimmed = []
    for c in chains:
        if len(c) > 3:
            to_first = np.linalg.norm(rig.heads[c[0]] - rig.heads[hand])
            to_tip = np.linalg.norm(rig.tails[c[-1]] - rig.heads[hand])
            c = c[len(c) - 3:] if to_first < 0.35 * to_tip else c[:3]
        trimmed.append(c)
    trimmed.sort(key=lambda c: -float(np.dot(rig.tails[c[-1]], forward)))
    for f, c in zip(FINGERS, trimmed):
        _assign(roles, used, names[f], c)


# ----------------------------------------------------------------------------- 4. validation


def _finalize(rig, roles, used, notes):
    pelvis = _first(roles, "pelvis")

    # chest: the trunk bone the clavicles (else upper arms) branch from
    tops = [t for t in (_first(roles, "neck"), _first(roles, "head")) if t is not None]
    arms = []
    for s in SIDES:
        a = _first(roles, sided("clavicle", s))
        a = a if a is not None else _first(roles, sided("upper_arm", s))
        if a is not None:
            arms.append(a)
    if pelvis is not None and arms:
        branch = rig.lca(arms) if len(arms) > 1 else rig.parents[arms[0]]
        if branch is not None and branch >= 0 and branch in arms:
            branch = rig.parents[branch]
        on_trunk = (branch is not None and branch >= 0 and rig.is_ancestor(pelvis, branch)
                    and all(rig.is_ancestor(branch, t) or branch == t for t in tops))
        if on_trunk:
            chest = branch
            while chest != pelvis and (rig.zero_length(chest) or _classify(rig.names[chest])[0] == "neck"
                                       or chest == _first(roles, "neck")):
                chest = rig.parents[chest]
            current = _first(roles, "chest")
            if chest != pelvis and chest != current:
                if current is not None:
                    notes.append(f"chest moved from {rig.names[current]} to {rig.names[chest]}, "
                                 "where the clavicles branch")
                    _clear(roles, used, "chest")
                owner = _owner(roles, chest)
                if owner is not None:
                    _clear(roles, used, owner)  # a spine chain is rebuilt below
                _assign(roles, used, "chest", [chest])

    # neck: the first bone above the chest segment
    chest = _first(roles, "chest")
    head = _first(roles, "head")
    neck = _first(roles, "neck")
    if chest is not None and head is not None and rig.is_ancestor(chest, head) and (
            neck is None or not rig.is_ancestor(chest, neck)):
        above = [b for b in rig.path(chest, head)[:-1] if not rig.zero_length(b)]
        if above and _owner(roles, above[0]) in (None, "neck"):
            _clear(roles, used, "neck")
            _assign(roles, used, "neck", [above[0]])

    # spine: the bones strictly between pelvis and chest (else neck, else head)
    if pelvis is not None:
        upper = next((r for r in ("chest", "neck", "head") if roles.get(r)
                      and rig.is_ancestor(pelvis, roles[r][0])), None)
        if upper is not None:
            between = rig.path(pelvis, roles[upper][0])[:-1]
            between = [b for b in between if _owner(roles, b) in (None, "spine")]
            if between:
                _clear(roles, used, "spine")
                _assign(roles, used, "spine", between)
            elif upper == "chest":
                chest_bone = roles["chest"][0]
                _clear(roles, used, "spine")
                _clear(roles, used, "chest")
                _assign(roles, used, "spine", [chest_bone])
                notes.append(f"no bone between pelvis and chest: {rig.names[chest_bone]} is the spine "
                             "and there is no separate chest")
        elif roles.get("spine") and not rig.is_ancestor(pelvis, roles["spine"][0]):
            pass  # parented elsewhere (e.g. through control bones): keep what was found

    # parent order: drop the distal role of any pair in reverse order
    changed = True
    while changed:
        changed = False
        for a, b in ORDER_PAIRS:
            ia, ib = _first(roles, a), _first(roles, b)
            if ia is None or ib is None:
                continue
            if ia == ib or rig.is_ancestor(ib, ia):
                notes.append(f"{describe_role(b)} ({rig.names[ib]}) is not below the "
                             f"{describe_role(a)} ({rig.names[ia]}): role dropped")
                _clear(roles, used, b)
                changed = True
    unlinked = [(a, b) for a, b in ORDER_PAIRS if _first(roles, a) is not None
                and _first(roles, b) is not None and not rig.is_ancestor(_first(roles, a), _first(roles, b))]
    if unlinked:
        notes.append(f"{len(unlinked)} role pairs are not linked by parenting "
                     f"(e.g. {describe_role(unlinked[0][0])} and {describe_role(unlinked[0][1])})")

    _check_sides(rig, roles, notes)


def _owner(roles, bone):
    for role, idx in roles.items():
        if bone in idx:
            return role
    return None


def _check_sides(rig, roles, notes):
    forward = _forward(rig, roles, {})
    left_sign = 1.0 if forward[1] <= 0 else -1.0
    if left_sign < 0:
        notes.append("the feet point to +Y: the character is taken to face +Y (its left is -X)")
    tol = 0.01 * rig.height
    for limb, parts in LIMB_ROLES.items():
        xs = {}
        for s in SIDES:
            idx = [i for p in parts for i in roles.get(sided(p, s), ())]
            if idx:
                xs[s] = float(np.mean(rig.mid[idx, 0])) * left_sign
        wrong = {s for s, x in xs.items() if (x < -tol if s == "L" else x > tol)}
        if not wrong:
            continue
        if wrong == set(xs):
            for p in parts:
                left, right = roles.pop(sided(p, "L"), None), roles.pop(sided(p, "R"), None)
                if right:
                    roles[sided(p, "L")] = right
                if left:
                    roles[sided(p, "R")] = left
            notes.append(f"{limb} sides swapped to match geometry (the character's left is "
                         f"{'+' if left_sign > 0 else '-'}X)")
        else:
            notes.append(f"both {limb}s are on one side of the body: check their roles")
