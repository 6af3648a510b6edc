"""The body's hierarchy over a rig's deform bones.

On a control rig the deform bones hang from mechanism bones (a generated Rigify rig's DEF-thigh
from ORG-/MCH- bones), so their own parent chain is not the body's. The physical skeleton keeps a
deform bone's nearest deform ancestor where that chain already passes through the body part the
bone's role hangs from (thigh -> pelvis, shin -> thigh, hand -> forearm, ...), and otherwise takes
the parent from the body roles. Deform bones without a role (twist segments, palms, breasts, face)
keep their nearest deform ancestor or, having none, hang from the role bone nearest to them."""

import numpy as np

from ..body_roles import FINGERS, SIDES, sided
from ..errors import RigError


def _parent_roles():
    """role -> the roles it may hang from, nearest first (a rig may lack clavicles, neck, chest)."""
    table = {
        "spine": ("pelvis",),
        "chest": ("spine", "pelvis"),
        "neck": ("chest", "spine", "pelvis"),
        "head": ("neck", "chest", "spine", "pelvis"),
    }
    for s in SIDES:
        table[sided("thigh", s)] = ("pelvis",)
        table[sided("shin", s)] = (sided("thigh", s),)
        table[sided("foot", s)] = (sided("shin", s),)
        table[sided("toe", s)] = (sided("foot", s),)
        table[sided("clavicle", s)] = ("chest", "spine", "pelvis")
        table[sided("upper_arm", s)] = (sided("clavicle", s), "chest", "spine", "pelvis")
        table[sided("forearm", s)] = (sided("upper_arm", s),)
        table[sided("hand", s)] = (sided("forearm", s),)
        for f in FINGERS:
            table[sided(f, s)] = (sided("hand", s),)
    return table


PARENT_ROLES = _parent_roles()


def _role_bones(roles):
    """bone name -> (role, the bone it hangs from inside a chain role, or None)."""
    out = {}
    for role, names in roles.bones.items():
        for i, name in enumerate(names):
            out[name] = (role, names[i - 1] if i > 0 else None)
    return out


def _segment_distance(points, heads, tails):
    """Mean distance of `points` (P, 3) to each segment (S, 3)-(S, 3): (S,)."""
    d = tails - heads
    t = np.einsum("psk,sk->ps", points[:, None, :] - heads[None], d) / np.maximum((d * d).sum(-1), 1e-12)
    near = heads[None] + np.clip(t, 0.0, 1.0)[..., None] * d[None]
    return np.linalg.norm(points[:, None, :] - near, axis=-1).mean(axis=0)


def body_parents(names, parents, heads, tails, deform, roles):
    """Parent (an index into `names`, -1 for the root) of every deform bone in the body's
    hierarchy; -1 for bones that don't deform. names (J,), parents (J,) the armature's own
    hierarchy, heads/tails (J, 3) at rest, deform (J,) bool, roles a RoleMap over deform bones."""
    names = list(names)
    index = {n: i for i, n in enumerate(names)}
    parents = np.asarray(parents, dtype=int)
    deform = np.asarray(deform, dtype=bool)
    heads, tails = np.asarray(heads, float), np.asarray(tails, float)
    role_of = _role_bones(roles)
    not_deform = [b for b in role_of if b not in index or not deform[index[b]]]
    if not_deform:
        raise RigError(f"the body roles name bones that don't deform: {', '.join(not_deform[:4])}")

    def deform_parent(j):
        p = parents[j]
        while p >= 0 and not deform[p]:
            p = parents[p]
        return p

    def deform_chain(j):
        out, p = [], deform_parent(j)
        while p >= 0:
            out.append(p)
            p = deform_parent(p)
        return out

    role_idx = np.array(sorted(index[b] for b in role_of), dtype=int)
    body = np.full(len(names), -1)
    for j in np.flatnonzero(deform):
        name = names[j]
        if name in role_of:
            role, previous = role_of[name]
            if previous is not None:
                wanted = index[previous]
            else:
                wanted = next((index[roles.bone(r)] for r in PARENT_ROLES.get(role, ()) if roles.bone(r)), -1)
            chain = deform_chain(j)
            if wanted < 0 or wanted in chain:  # e.g. DEF-shin under DEF-thigh.001 under DEF-thigh: the rig's own
                body[j] = chain[0] if chain else -1
            else:
                body[j] = wanted
        else:
            p = deform_parent(j)
            if p >= 0 or len(role_idx) == 0:
                body[j] = p
            else:
                points = np.stack([heads[j], (heads[j] + tails[j]) / 2, tails[j]])
                body[j] = role_idx[np.argmin(_segment_distance(points, heads[role_idx], tails[role_idx]))]
    return body


def parents_first(parents, members):
    """`members` (indices) ordered parents before children under `parents`, keeping their given
    order wherever it already is (a plain FK rig's bones stay in Blender's order); RigError on a loop."""
    inside = set(int(j) for j in members)
    placed, order = set(), []
    pending = [int(j) for j in members]
    while pending:
        left = []
        for j in pending:
            if parents[j] < 0 or parents[j] not in inside or parents[j] in placed:
                placed.add(j)
                order.append(j)
            else:
                left.append(j)
        if len(left) == len(pending):
            raise RigError("the body roles make a loop in the deform bones' hierarchy")
        pending = left
    return order
