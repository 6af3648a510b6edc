"""What each bone of a rig is for: deform, control or mechanism, by structure and constraints.

- deform bones are what the mesh follows (`use_deform`);
- control bones are what the animator keys: no active constraint, no driver and no IK chain
  moves them (an IK chain's top may: the IK starts from its rotation), some channel is free,
  they are shown (not hidden, in a visible collection or in
  none), and a deform bone follows them (through parents, constraint targets, IK poles,
  Armature constraint targets or the bones a driver reads);
- mechanism bones are everything else (Rigify's ORG-/MCH-, a studio's helpers).

A plain FK skeleton (a BVH import, a metarig) is all deform and control. Nothing here reads names."""

import re
from dataclasses import dataclass

import bpy

_BONE_PATH = re.compile(r'^pose\.bones\["((?:[^"\\]|\\.)*)"\]')


@dataclass(frozen=True)
class BoneClasses:
    deform: frozenset
    control: frozenset
    mechanism: frozenset

    def of(self, name):
        """'deform+control', 'deform', 'control' or 'mechanism'."""
        kinds = [k for k in ("deform", "control") if name in getattr(self, k)]
        return "+".join(kinds) or "mechanism"


def _constraint_targets(obj, con):
    pairs = [(getattr(con, "target", None), getattr(con, "subtarget", "")),
             (getattr(con, "pole_target", None), getattr(con, "pole_subtarget", ""))]
    pairs += [(t.target, t.subtarget) for t in getattr(con, "targets", ())]  # Armature constraint
    return [n for t, n in pairs if t == obj and n in obj.pose.bones]


def _active(con):
    return not con.mute and con.influence > 0 and getattr(con, "enabled", True)


def _driver_links(obj):
    """{driven bone: bones its drivers read} and the bones some driver moves."""
    links, moved = {}, set()
    ad = obj.animation_data
    for d in (ad.drivers if ad else ()):
        m = _BONE_PATH.match(d.data_path)
        if not m:
            continue
        bone = bpy.utils.unescape_identifier(m.group(1))
        if bone not in obj.pose.bones:
            continue
        rest = d.data_path[m.end():]
        if rest.startswith(".") and rest[1:].split("[")[0] in {
                "location", "rotation_euler", "rotation_quaternion", "rotation_axis_angle", "scale"}:
            moved.add(bone)
        for v in d.driver.variables:
            for t in v.targets:
                if t.id != obj:
                    continue
                src = getattr(t, "bone_target", "") or ""
                p = _BONE_PATH.match(t.data_path or "")
                if p:
                    src = bpy.utils.unescape_identifier(p.group(1))
                if src in obj.pose.bones and src != bone:
                    links.setdefault(bone, set()).add(src)
    return links, moved


def _ik_chains(obj):
    """Bones an IK constraint turns without owning it (the chain above its owner), but the chain's
    top: its own rotation is where the IK starts from, how an animator turns a pole-less limb
    (Rigify's thigh_ik)."""
    out = set()
    for pb in obj.pose.bones:
        for con in pb.constraints:
            if con.type == "IK" and _active(con):
                n, p, chain = con.chain_count, pb.parent, []
                while p is not None and (n == 0 or n > 1):
                    chain.append(p.name)
                    p, n = p.parent, n - 1 if n else 0
                out.update(chain[:-1] if con.chain_count else chain)
    return out


def _shown(obj, name):
    bone = obj.data.bones[name]
    if bone.hide:
        return False
    collections = list(getattr(bone, "collections", ()))
    # a collection inside a hidden one is hidden too (is_visible_effectively, Blender 4.1+)
    return not collections or any(getattr(c, "is_visible_effectively", c.is_visible) for c in collections)


def _free(pb):
    locked = list(pb.lock_rotation) + [pb.lock_rotation_w] + list(pb.lock_location) + list(pb.lock_scale)
    if pb.bone.use_connect:
        locked[4:7] = [True] * 3  # a connected bone's location is ignored
    return not all(locked)


def classify(obj):
    """The BoneClasses of an armature object."""
    pbs = obj.pose.bones
    links, driver_moved = _driver_links(obj)
    ik_moved = _ik_chains(obj)
    follows = {}
    driven = set(driver_moved) | ik_moved
    for pb in pbs:
        ups = set(links.get(pb.name, ()))
        for con in pb.constraints:
            if _active(con):
                driven.add(pb.name)
                ups.update(_constraint_targets(obj, con))
        if pb.parent is not None:
            ups.add(pb.parent.name)
        follows[pb.name] = ups
    deform = frozenset(b.name for b in obj.data.bones if b.use_deform)
    reach, queue = set(deform), list(deform)  # every bone a deform bone follows, itself included
    while queue:
        for up in follows[queue.pop()]:
            if up not in reach:
                reach.add(up)
                queue.append(up)
    control = frozenset(n for n in reach if n not in driven and _free(pbs[n]) and _shown(obj, n))
    mechanism = frozenset(b.name for b in obj.data.bones) - deform - control
    return BoneClasses(deform, control, mechanism)
