"""A solved pose written back to the controls an animator keys, on any rig.

Input: the physical skeleton's solved frames (armature space, metres) of its deform bones. Output:
a NEW action keying the controls (the source action is copied, never changed), and Blender's own
evaluation of the deform bones compared with the solved pose, per role.

Which control moves which body part, found by structure (rig/bones.py, rig/controls.py):
- the pelvis: the outermost control upstream of it that carries it, short of the rig's root (a
  torso control), and, where another control nearer to it carries it too (Rigify's FK hips, hung
  from the FK spine), that one, placed last through the rig as Blender evaluates it;
- a limb that an active IK constraint bends: its IK target control (the control that carries the
  hand or foot) placed where the solved pose puts the hand or foot, and the knee or elbow plane set
  by the pole control (or, with no pole, by turning the IK chain's top bone about the hip-ankle
  line), unless the animator asks for FK; where its deform bones copy controls of their own (tweak
  controls), the lower one's is placed where the solve puts the knee or elbow (an IK with stretch
  shows the chain short) and the upper one's turned by the roll Blender shows off the solve;
- every other role bone: the FK control that turns it (the switch values that make it drive are
  keyed), else the nearest control that carries it.
Each control is placed from its parent as Blender evaluates it, frame by frame, until nothing
changes; the knee plane is corrected by the angle Blender shows off it."""

from dataclasses import dataclass, field

import bpy
import numpy as np

from ...solver import rotations
from ...solver.errors import HumanAnimError
from ...solver.progress import run_to_end
from . import controls as rc
from .bones import classify
from .physical import evaluated_pose

REACH_M = 0.01  # how far an IK target may be put beyond the hand or foot for the chain to reach it
_LIMBS = (("thigh", "shin", "foot"), ("upper_arm", "forearm", "hand"))


@dataclass
class Handle:
    """One control to key. kind 'carry': placed where joint's solved frame puts it (`offset`: the
    control's rest in the joint's rest); 'pole': an IK pole placed in the limb's plane (`local`:
    its rest position in the limb's rest frame); 'twist': the top of a pole-less IK chain, turned
    about the hip-ankle line; 'settle': placed, after the others, where the joint's solved frame
    puts it through the rig as Blender evaluates it (its frame in the joint's frame, measured);
    'roll': the control a deform bone copies, turned about the bone's own axis by the roll Blender
    shows off the solve (the bone's direction comes from elsewhere: a Stretch To). `chain`: the
    limb's (upper, lower, end) joints; `bend`: the direction the middle joint bends to in rest
    (unit, in the upper bone's rest frame)."""

    control: str
    kind: str
    joint: int
    offset: np.ndarray = None
    chain: tuple = ()
    local: np.ndarray = None
    bend: np.ndarray = None


@dataclass
class ControlPlan:
    handles: list = field(default_factory=list)
    switches: dict = field(default_factory=dict)  # (bone, property) -> value the plan relies on
    changed: dict = field(default_factory=dict)  # those of `switches` that differ from the rig's
    unmapped: list = field(default_factory=list)  # role bones no control moves
    modes: dict = field(default_factory=dict)  # limb ('thigh.L') -> 'IK' or 'FK'

    @property
    def controls(self):
        return [h.control for h in self.handles]


def _rest(obj, name):
    """Armature-space rest matrix (Blender units, orthonormal)."""
    m = np.array(obj.data.bones[name].matrix_local, dtype=float)
    m[:3, :3] /= np.linalg.norm(m[:3, :3], axis=0)
    return m


def _shown(obj, name):
    from .bones import _shown as shown
    return shown(obj, name)


def _active_ik(obj, bone):
    """(owner, constraint) of the first active IK constraint upstream of `bone`, or None."""
    for name in rc.upstream(obj, bone):
        for con in obj.pose.bones[name].constraints:
            if con.type == "IK" and not con.mute and con.influence > 0 and con.target == obj and con.subtarget:
                return name, con
    return None


def _carrier(obj, bone, candidates, used, moves=True, not_carrying=None):
    """The first of `candidates` (names) that is a control, not used yet, and carries `bone`;
    `moves`: its location is free; `not_carrying`: a bone it must not carry (an IK target carries
    the foot, not the thigh)."""
    for c in candidates:
        if c in used or not rc.is_control(obj, c) or (moves and all(obj.pose.bones[c].lock_location)):
            continue
        if rc.carries(obj, bone, c) and not (not_carrying and rc.carries(obj, not_carrying, c)):
            return c
    return None


def _nearest_first(obj, name):
    up = rc.upstream(obj, name)
    return [n for n, _ in sorted(up.items(), key=lambda kv: kv[1]) if n != name]


BEND_WEIGHT = 0.01  # share of the limb's length the upper bone's bend direction counts for beside the knee's offset


def _bend_vector(heads, upper_rotation=None, bend=None):
    """The direction (..., 3) from the limb's root-end line to its middle joint, unnormalised: the
    middle joint's offset from that line plus BEND_WEIGHT x the limb's length along the upper
    bone's own bend direction (`upper_rotation` @ `bend`). On a bent limb the offset decides; on a
    straight one (a leg the foot repair stretched) the upper bone's turn about its axis does, where
    the middle joint alone says nothing (the pole then flipped by up to 90 deg)."""
    h, k, a = heads
    x = a - h
    length = np.linalg.norm(x, axis=-1, keepdims=True)
    x = x / length

    def perp(v):
        return v - np.sum(v * x, axis=-1, keepdims=True) * x
    u = perp(k - h)
    if bend is not None:
        u = u + BEND_WEIGHT * length * perp(upper_rotation @ bend)
    return x, u


def _chain_frame(heads, upper_rotation=None, bend=None):
    """Frames (..., 4, 4) with origin at the limb's root, x to its end, y toward its middle joint
    (as `_bend_vector` gives it)."""
    h = heads[0]
    x, u = _bend_vector(heads, upper_rotation, bend)
    y = u / np.maximum(np.linalg.norm(u, axis=-1, keepdims=True), 1e-12)
    out = np.zeros(h.shape[:-1] + (4, 4))
    out[..., :3, 0], out[..., :3, 1], out[..., :3, 2], out[..., :3, 3] = x, y, np.cross(x, y), h
    out[..., 3, 3] = 1.0
    return out


def plan_controls(obj, skeleton, fk=False):
    """The ControlPlan of the role bones of `skeleton` (a physical skeleton of `obj`). `fk`: key
    the limbs through their FK controls (switching the rig's IK/FK switch when needed)."""
    classes = classify(obj)
    roles = skeleton.roles
    pbs = obj.pose.bones
    drivers = rc.switch_drivers(obj)
    saved = {k: pbs[k[0]][k[1]] for k in rc.switches_of(drivers, set(pbs.keys()))}
    plan, used, done = ControlPlan(), set(), set()
    role_joints = [j for j, n in enumerate(skeleton.names) if roles.role_of(n) is not None]
    scale = skeleton.unit_scale
    try:
        if all(skeleton.names[j] in classes.control for j in role_joints):  # a plain FK rig
            plan.handles = [Handle(skeleton.names[j], "carry", j, np.eye(4)) for j in role_joints]
            return plan
        pelvis = skeleton.role_index("pelvis")
        if pelvis is not None:
            name = skeleton.names[pelvis]
            ups = _nearest_first(obj, name)[::-1]  # outermost first
            ups = [c for c in ups if pbs[c].parent is not None]  # a torso control, not the rig's root
            c = name if name in classes.control else _carrier(obj, name, ups, used)
            if c is not None:
                plan.handles.append(Handle(c, "carry", pelvis, np.linalg.solve(_rest(obj, name), _rest(obj, c))))
                used.add(c)
                done.add(pelvis)
                # the nearest control carrying it too: on Rigify the hips hang from the FK spine
                # (torso -> ... -> spine_fk.001 -> MCH-spine -> spine_fk -> tweak_spine -> DEF-spine),
                # which the spine's own placement turns: the torso, at its rest offset, can't undo it
                near = None if c == name else _carrier(obj, name, ups[::-1], used)
                if near is not None:
                    plan.handles.append(Handle(near, "settle", pelvis))
                    used.add(near)
        for limb in _LIMBS:
            for s in ("L", "R"):
                joints = [skeleton.role_index(f"{r}.{s}") for r in limb]
                if None in joints or fk:
                    continue
                handles = _ik_limb(obj, skeleton, joints, used)
                if handles:  # the switches as they are keep the limb in IK
                    lower = skeleton.names[joints[1]]
                    plan.switches.update((k, saved[k]) for k in rc.switches_of(drivers, set(rc.upstream(obj, lower))))
                    plan.handles += handles
                    plan.modes[f"{limb[0]}.{s}"] = "IK"
                    used.update(h.control for h in handles)
                    done.update(joints)
        for j in role_joints:
            if j in done:
                continue
            name = skeleton.names[j]
            if name in classes.control:
                plan.handles.append(Handle(name, "carry", j, np.eye(4)))
                used.add(name)
                continue
            found = rc._search_control(obj, name, scale, saved, drivers, plan.switches)
            if found is not None and found.name not in used:
                plan.switches.update(found.switches)
                off = np.linalg.solve(_rest(obj, name), _rest(obj, found.name))
                plan.handles.append(Handle(found.name, "carry", j, off))
                used.add(found.name)
                continue
            p = skeleton.parents[j]  # a control that turns this bone, not its body parent too
            ups = [c for c in _nearest_first(obj, name) if pbs[c].parent is not None]
            c = (_carrier(obj, name, ups, used, moves=False, not_carrying=skeleton.names[p] if p >= 0 else None)
                 or _carrier(obj, name, ups, used, moves=False))
            if c is None:
                plan.unmapped.append(name)
                continue
            plan.handles.append(Handle(c, "carry", j, np.linalg.solve(_rest(obj, name), _rest(obj, c))))
            used.add(c)
        # bones a Stretch To aims, that take the rest of their frame from the control they copy:
        # - an IK limb's lower bone: that control (Rigify's knee tweak) is placed where the solve
        #   puts the bone, whatever the IK shows (a chain with IK stretch shows it up to 2 % short,
        #   the knee 20 mm off);
        # - an IK limb's upper bone, and one the pelvis's settled control carries: that control
        #   is turned about the bone (Rigify's DEF-upper_arm copies a tweak a Damped Track swings
        #   from the shoulder, so the IK's own roll never reaches it; DEF-spine.001 copies a child
        #   of the FK hips)
        settle = [h.control for h in plan.handles if h.kind == "settle"]
        limbs = [h.chain for h in plan.handles if h.kind == "carry" and h.chain]
        for j in role_joints:
            ctl = _copied_control(obj, skeleton.names[j]) if j != pelvis else None
            if ctl is None or ctl in used:
                continue
            if any(j == chain[1] for chain in limbs) and not all(pbs[ctl].lock_location):
                kind = "settle"
            elif any(j == chain[0] for chain in limbs) or (settle and rc.carries(obj, ctl, settle[0])):
                kind = "roll"
            else:
                continue
            plan.handles.append(Handle(ctl, kind, j))
            used.add(ctl)
        for limb in _LIMBS:
            for s in ("L", "R"):
                if f"{limb[0]}.{s}" not in plan.modes and skeleton.role_index(f"{limb[0]}.{s}") is not None:
                    plan.modes[f"{limb[0]}.{s}"] = "FK"
    finally:
        for (b, p), v in saved.items():
            pbs[b][p] = v
        bpy.context.view_layer.update()
    plan.changed = {k: v for k, v in plan.switches.items() if float(v) != float(saved[k])}
    order = {b.name: i for i, b in enumerate(obj.data.bones)}  # parents come before children
    rank = {"carry": 0, "pole": 1, "twist": 2, "settle": 3, "roll": 4}
    plan.handles.sort(key=lambda h: (rank[h.kind], order[h.control]))
    return plan


def _copied(obj, pb):
    """The bones of `obj` whose transforms pose bone `pb` copies (its active Copy Transforms
    targets, in order)."""
    return [c.subtarget for c in pb.constraints if c.type == "COPY_TRANSFORMS" and not c.mute
            and c.influence > 0 and c.target == obj and c.subtarget in obj.pose.bones]


def _copied_control(obj, name):
    """The control whose transforms deform bone `name` copies (its first active Copy Transforms
    target) when that control turns about its own axis, else None."""
    copied = _copied(obj, obj.pose.bones[name])
    if not copied:
        return None
    c = copied[0]
    return c if rc.is_control(obj, c) and not obj.pose.bones[c].lock_rotation[1] else None


def _ik_limb(obj, skeleton, joints, used):
    """Handles of an IK-driven limb (target, then pole or twist), or [] when no active IK with a
    control carrying the limb's end bends it."""
    upper, lower, end = (skeleton.names[j] for j in joints)
    found = _active_ik(obj, lower)
    if found is None:
        return []
    owner, con = found
    end_ctl = _carrier(obj, end, [con.subtarget] + _nearest_first(obj, con.subtarget), used, not_carrying=upper)
    if end_ctl is None:
        return []
    heads = [_rest(obj, n)[:3, 3] for n in (upper, lower, end)]
    frame = _chain_frame(heads)
    bend = _rest(obj, upper)[:3, :3].T @ frame[:3, 1]  # the rest bend, in the upper bone's frame
    out = [Handle(end_ctl, "carry", joints[2], np.linalg.solve(_rest(obj, end), _rest(obj, end_ctl)), tuple(joints))]
    pole = con.pole_subtarget if con.pole_target == obj else ""
    if pole:
        ctl = next((c for c in [pole] + _nearest_first(obj, pole) if rc.is_control(obj, c)), None)
        if ctl is not None and ctl not in used:
            local = np.linalg.solve(frame, np.append(_rest(obj, ctl)[:3, 3], 1.0))
            out.append(Handle(ctl, "pole", joints[2], chain=tuple(joints), local=local, bend=bend))
        return out
    top, n = obj.pose.bones[owner], con.chain_count
    while n > 1 and top.parent is not None:
        top, n = top.parent, n - 1
    if _shown(obj, top.name) and not all(top.lock_rotation):
        out.append(Handle(top.name, "twist", joints[2], chain=tuple(joints), bend=bend))
    return out


def ik_limbs(obj, skeleton):
    """[(upper, lower, end) joints, upper bone's rest bend] of the limbs an active IK constraint
    bends (whatever the pole), with the rest bend (unit, upper bone's rest frame: `Handle.bend`)."""
    out = []
    for limb in _LIMBS:
        for s in ("L", "R"):
            joints = [skeleton.role_index(f"{r}.{s}") for r in limb]
            if None in joints or _active_ik(obj, skeleton.names[joints[1]]) is None:
                continue
            heads = [_rest(obj, skeleton.names[j])[:3, 3] for j in joints]
            bend = _rest(obj, skeleton.names[joints[0]])[:3, :3].T @ _chain_frame(heads)[:3, 1]
            out.append((tuple(joints), bend))
    return out


# constraints that give a bone its rotation: a Stretch To after one of them is no swing from the rest
_TURNING = {"COPY_ROTATION", "COPY_TRANSFORMS", "TRACK_TO", "DAMPED_TRACK", "LOCKED_TRACK", "IK", "CHILD_OF",
            "ARMATURE", "TRANSFORM", "ACTION"}


def swung_bones(obj, skeleton):
    """The role joints whose deform bone (through its Copy Transforms) a Stretch To (swing only)
    aims from a mechanism bone hung, through mechanism bones only, from the joint's body parent
    (Rigify's first finger and thumb segments: DEF-thumb.01 copies MCH-thumb.01, which hangs from
    the palm and is stretched to the next segment's control). No control turns such a bone about
    its own axis: the rig shows it swung from its rest on its parent onto where it points."""
    pbs = obj.pose.bones
    out = []
    for j, name in enumerate(skeleton.names):
        p = skeleton.parents[j]
        if skeleton.roles.role_of(name) is None or p < 0:
            continue
        bone, seen = name, set()
        while bone not in seen:
            seen.add(bone)
            if _swing_aimed(obj, pbs[bone], skeleton.names[p]):
                out.append(j)
                break
            copied = _copied(obj, pbs[bone])
            if not copied:
                break
            bone = copied[0]
    return out


def _swing_aimed(obj, pb, parent_name):
    """True when pose bone `pb` is no control, takes no rotation from a constraint before its
    active swing-only Stretch To, and hangs from `parent_name` through mechanism bones only."""
    if rc.is_control(obj, pb.name):
        return False
    for con in pb.constraints:
        if con.mute or con.influence <= 0:
            continue
        if con.type == "STRETCH_TO":
            if con.keep_axis != "SWING_Y":
                return False
            up = pb.parent
            while up is not None and up.name != parent_name and not rc.is_control(obj, up.name):
                up = up.parent
            return up is not None and up.name == parent_name
        if con.type in _TURNING:
            return False
    return False


def _about_axis(rotation, axis, have, want):
    """`rotation` (F, 3, 3) turned about `axis` (F, 3, unit) so that `have` (F, 3) points, around
    that axis, where `want` does."""
    def perp(v):
        return v - np.sum(v * axis, axis=-1, keepdims=True) * axis
    a, b = perp(have), perp(want)
    angle = np.arctan2(np.sum(np.cross(a, b) * axis, axis=-1), np.sum(a * b, axis=-1))
    c, s = np.cos(angle)[:, None, None], np.sin(angle)[:, None, None]
    k = np.zeros(axis.shape[:-1] + (3, 3))
    k[:, 0, 1], k[:, 0, 2], k[:, 1, 2] = -axis[:, 2], axis[:, 1], -axis[:, 0]
    k -= np.swapaxes(k, -1, -2)
    turn = np.eye(3) + s * k + (1 - c) * (k @ k)
    return turn @ rotation


def as_ik_shows(skeleton, solved, limbs):
    """`solved` (F, J, 4, 4, armature space) with each IK limb's upper and lower bones turned into
    the plane an IK chain shows them in (`limbs` from `ik_limbs`): a two-bone IK bends its chain in
    one plane, through the knee and, on a straight leg, where the upper bone's own turn puts it
    (`_bend_vector`), so a pose whose thigh or shin is rolled otherwise can't be shown. The knee
    turns about the hip-ankle line into that plane (by a fraction of a degree but on a nearly
    straight leg), each bone about its own axis; hip and ankle and every other bone unchanged."""
    out = np.array(solved, dtype=float, copy=True)
    rest = skeleton.rest
    for (u, m, e), bend in limbs:
        heads = [out[:, j, :3, 3] for j in (u, m, e)]
        x, y = _bend_vector(heads, out[:, u, :3, :3], bend)
        # the knee (elbow) turned about the root-end line into that plane: on a nearly straight limb
        # its own side of the line is noise, and the IK puts it where the pole says
        hip = heads[0]
        swing = _about_axis(np.broadcast_to(np.eye(3), x.shape[:-1] + (3, 3)), x, heads[1] - hip, y)
        for j in (u, m):
            out[:, j, :3, :3] = swing @ out[:, j, :3, :3]
        out[:, m, :3, 3] = hip + np.einsum("fij,fj->fi", swing, heads[1] - hip)
        normal = np.cross(x, y / np.linalg.norm(y, axis=-1, keepdims=True))
        rest_frame = _chain_frame([rest[j, :3, 3] for j in (u, m, e)])
        for j, child in ((u, m), (m, e)):
            along = out[:, child, :3, 3] - out[:, j, :3, 3]
            along /= np.linalg.norm(along, axis=-1, keepdims=True)
            have = out[:, j, :3, :3] @ (rest[j, :3, :3].T @ rest_frame[:3, 2])
            out[:, j, :3, :3] = _about_axis(out[:, j, :3, :3], along, have, normal)
    return out


# --- placing the controls, frame by frame, from Blender's evaluation ---------------------------
def _rest_local(obj, name):
    b = obj.data.bones[name]
    rest = _rest(obj, name)
    return rest if b.parent is None else np.linalg.solve(_rest(obj, b.parent.name), rest)


def _matrix(pb):
    m = np.array(pb.matrix, dtype=float)
    m[:3, :3] /= np.linalg.norm(m[:3, :3], axis=0)
    return m


def _set_world(obj, name, target):
    """Sets the bone's basis so that (its parent as evaluated now) it shows `target` (units), by
    Blender's own conversion (which honours local location and the inherit options)."""
    from mathutils import Matrix
    pb = obj.pose.bones[name]
    old = np.array(pb.matrix_basis, dtype=float)
    pb.matrix = Matrix(target.tolist())
    return float(np.abs(np.array(pb.matrix_basis, dtype=float) - old).max())


def _shown_offset(obj, bone, control):
    """The control's frame in the bone's frame (units) as Blender evaluates the rig now."""
    pbs = obj.pose.bones
    return np.linalg.solve(_matrix(pbs[bone]), _matrix(pbs[control]))


WARM_PASSES = 4  # passes before a settling control that brings its joint no closer is left alone
NEAR_PLANE = 1e-3  # radians: a limb's bend this close that turning brings no closer is left alone
SETTLED = 1e-6  # a joint this close to the solve (units, and radians) is left as Blender shows it


def _off_by(shown, want):
    """How far frame `shown` is from `want` (4, 4): the larger of the origins' distance and the
    angle between them (radians)."""
    cos = (np.trace(shown[:3, :3].T @ want[:3, :3]) - 1.0) / 2.0
    return max(float(np.linalg.norm(shown[:3, 3] - want[:3, 3])), float(np.arccos(np.clip(cos, -1.0, 1.0))))


def _roll(obj, bone, control, want):
    """Turns `control` about deform bone `bone`'s axis (as Blender shows it now) by the angle
    that rolls the bone onto `want` (units) about that axis; returns that angle's size (0 when
    under SETTLED: nothing turned)."""
    shown = _matrix(obj.pose.bones[bone])
    rel = shown[:3, :3].T @ want[:3, :3]  # the bone's turn to the solve, in its own frame
    angle = float(np.arctan2(rel[0, 2] - rel[2, 0], rel[0, 0] + rel[2, 2]))
    if abs(angle) < SETTLED:
        return 0.0
    c = _matrix(obj.pose.bones[control])
    _set_world(obj, control, _rotation_about(c[:3, 3], shown[:3, 1], angle) @ c)
    return abs(angle)


def _one_free_axis(pb):
    """The one axis (0-2) a control turns about when its other two are locked, else None."""
    free = [i for i in range(3) if not pb.lock_rotation[i]]
    return free[0] if len(free) == 1 else None


def _settle_about_free_axis(obj, bone, control, want):
    """Settles a control that turns about one of its own axes only: moved by the distance the
    deform bone's head is off `want` (units), then rolled about the bone's axis by the angle it
    shows off `want` (`_roll`), its turn about its locked axes dropped (`_turn_about_free_axis`)."""
    pb = obj.pose.bones[control]
    c = _matrix(pb)
    c[:3, 3] += want[:3, 3] - np.array(obj.pose.bones[bone].head, dtype=float)
    _set_world(obj, control, c)
    bpy.context.view_layer.update()
    _roll(obj, bone, control, want)
    _turn_about_free_axis(pb)


def _turn_about_free_axis(pb):
    """A control the animator can turn about one of its own axes only (the other two locked:
    Rigify's forearm tweak turns about Y) keeps only its turn about that axis (the twist of a
    swing-twist split of its basis rotation), its location kept. Placed freely, such a control
    picks up turns about its locked axes that the Stretch To of the deform bone copying it swings
    away again, so the placement that shows the solve is no single one: pass after pass and frame
    after frame it drifts (the forearm tweak's turn reached -74 deg about X on the CMU walk's first
    frame and 2,000 deg about Y by frame 150), and once its axis points nearly away from the
    Stretch To's target the swing flips the deform bone up to 180 deg about its own axis."""
    axis = _one_free_axis(pb)
    if axis is None:
        return
    from mathutils import Matrix
    basis = np.array(pb.matrix_basis, dtype=float)
    q = rotations.from_matrix(basis[:3, :3] / np.linalg.norm(basis[:3, :3], axis=0))
    twist = np.zeros(4)
    twist[0], twist[1 + axis] = q[0], q[1 + axis]
    if np.linalg.norm(twist) < 1e-9:  # half a turn about a locked axis: no twist to keep
        twist[0] = 1.0
    basis[:3, :3] = rotations.to_matrix(twist / np.linalg.norm(twist)) * np.linalg.norm(basis[:3, :3], axis=0)
    pb.matrix_basis = Matrix(basis.tolist())


def _plain_child(obj, name):
    """True when the bone's frame is its parent's frame times its rest offset times its basis (full
    inheritance, local location, no constraint), so it can be placed from the parent's new frame."""
    b, pb = obj.data.bones[name], obj.pose.bones[name]
    return (b.parent is not None and b.use_inherit_rotation and b.inherit_scale == "FULL" and b.use_local_location
            and not any(not c.mute for c in pb.constraints))


def _set_basis(pb, parent, rest_local, target):
    """Sets the basis so that the bone shows `target` under a parent showing `parent` (units)."""
    from mathutils import Matrix
    old = np.array(pb.matrix_basis, dtype=float)
    b = np.linalg.solve(parent @ rest_local, target)
    b[:3, :3] /= np.linalg.norm(b[:3, :3], axis=0)
    pb.matrix_basis = Matrix(b.tolist())
    return float(np.abs(b - old).max())


def _plane_error(obj, skeleton, h, solved):
    """(axis point, axis direction, signed angle) turning the limb's bend (`_bend_vector`: the
    knee's side of the root-end line, and the upper bone's turn) as Blender shows it into the
    solved one (`solved`: the skeleton's frames of the frame), about the shown root-end line."""
    pbs = obj.pose.bones
    upper = _matrix(pbs[skeleton.names[h.chain[0]]])[:3, :3]
    shown = [np.array(pbs[skeleton.names[j]].head, dtype=float) for j in h.chain]
    x, u = _bend_vector(shown, upper, h.bend)
    w = _bend_vector(solved[list(h.chain), :3, 3], solved[h.chain[0], :3, :3], h.bend)[1]
    w = w - np.dot(w, x) * x
    if np.linalg.norm(w) < 1e-9 or np.linalg.norm(u) < 1e-9:
        return None
    angle = np.arctan2(np.dot(np.cross(u, w), x), np.dot(u, w))
    return shown[0], x, float(angle)


def _rotation_about(point, axis, angle):
    from mathutils import Matrix, Vector
    r = np.array(Matrix.Rotation(angle, 4, Vector(axis.tolist())), dtype=float)
    t = np.eye(4)
    t[:3, 3] = point
    return t @ r @ np.linalg.inv(t)


class _Secant:
    """The turn (radians) about the limb's root-end line that zeroes the knee-plane error Blender
    shows. An IK solve is no linear function of its pole or its chain's start (the turn may even
    act backwards), so the turn is found by secant steps, at most 0.3 rad each, starting from the
    previous frame's turn and slope."""

    def __init__(self):
        self.turn, self.slope, self.last = 0.0, -1.0, None

    def next_frame(self):
        self.last = None

    def step(self, error):
        if self.last is not None and abs(self.turn - self.last[0]) > 1e-9:
            slope = (error - self.last[1]) / (self.turn - self.last[0])
            if abs(slope) > 0.05:
                self.slope = slope
        self.last = (self.turn, error)
        self.turn -= float(np.clip(error / self.slope, -0.3, 0.3))
        return self.turn


def solve_bases(obj, scene, skeleton, plan, frames, solved):
    """{control: (F, 4, 4) basis (Blender units)} showing the solved frames `solved` (F, J, 4, 4,
    armature space, metres) on `frames`, with the plan's switch values set while solving."""
    return run_to_end(iter_solve_bases(obj, scene, skeleton, plan, frames, solved))


def iter_solve_bases(obj, scene, skeleton, plan, frames, solved):
    """solve_bases as a job step: yields the share of frames done."""
    pbs = obj.pose.bones
    view_layer = bpy.context.view_layer
    units = solved.copy()
    units[..., :3, 3] /= skeleton.unit_scale
    rest_local = {h.control: _rest_local(obj, h.control) for h in plan.handles}
    out = {h.control: np.empty((len(frames), 4, 4)) for h in plan.handles}
    saved_switch = {k: pbs[k[0]][k[1]] for k in plan.switches}
    saved_basis = {h.control: pbs[h.control].matrix_basis.copy() for h in plan.handles}  # the rig's pose, left as found
    turning = [h for h in plan.handles if h.kind in ("pole", "twist")]
    settling = [h for h in plan.handles if h.kind == "settle"]
    rolling = [h for h in plan.handles if h.kind == "roll"]
    secant = {h.control: _Secant() for h in turning}
    targets = [h for h in plan.handles if h.kind == "carry" and h.chain]  # IK targets
    pelvis = next((h for h in plan.handles if h.kind == "carry" and h.joint == skeleton.role_index("pelvis")), None)
    # a control whose parent is another plain control placed in the same pass is placed from that
    # parent's new frame, not from its evaluation: an FK chain settles in one pass, not one per bone
    plain = {h.control: _plain_child(obj, h.control) for h in plan.handles}
    controls = {h.control for h in plan.handles}
    reset_pelvis = pelvis is not None and any(a.name in controls for a in pbs[pelvis.control].parent_recursive)
    keep = scene.frame_current
    try:
        for k, f in enumerate(frames):
            scene.frame_set(int(f))
            for (b, p), v in plan.switches.items():
                pbs[b][p] = v
            for h in turning:
                secant[h.control].next_frame()
                # a pole-less chain's top the action doesn't key keeps the previous frame's turned
                # basis: turned again by that frame's turn it would spin (5 deg a frame on the
                # CMU walk's left arm onto Rigify, which the tweaks then undid up to 180 deg)
                if h.kind == "twist" and k > 0 and np.allclose(
                        np.array(pbs[h.control].matrix_basis, dtype=float), out[h.control][k - 1], atol=1e-9):
                    secant[h.control].turn = 0.0
            start = {}  # a twist control's evaluated frame before any turn
            reach = {h.control: np.zeros(3) for h in targets}
            missed, last_shift, stuck = {}, {}, set()
            best, left = {}, set()  # a settling control's closest approach; those left alone
            for passes in range(24):
                change, placed = 0.0, {}
                for h in plan.handles:
                    if h.kind == "carry":
                        t = units[k, h.joint] @ h.offset
                        if h.control in reach:
                            t[:3, 3] += reach[h.control]
                        parent = pbs[h.control].parent
                        if parent is not None and parent.name in placed and plain[h.control]:
                            moved = _set_basis(pbs[h.control], placed[parent.name], rest_local[h.control], t)
                        else:
                            moved = _set_world(obj, h.control, t)
                        change = max(change, moved)
                        placed[h.control] = t
                    elif h.kind in ("pole", "twist"):
                        change = max(change, _turn(obj, h, units[k], secant[h.control].turn, start,
                                                   rest_local[h.control]))
                if reset_pelvis:  # again: a spine control that also turns the pelvis (Rigify's FK
                    view_layer.update()  # spine) is undone, the pelvis ends each pass where the solve puts it
                    change = max(change, _set_world(obj, pelvis.control, units[k, pelvis.joint] @ pelvis.offset))
                view_layer.update()
                # placed while Blender shows the joint off the solve and, once the other controls
                # have settled (WARM_PASSES), each placing brings it closer: Rigify's forearm tweak,
                # which its elbow's mechanism also blends in, stays 0.5-1 deg off and would creep
                # pass after pass
                moved = 0.0
                for h in settling:  # through the rig as it now stands: its frame in the joint's, measured
                    off = _off_by(_matrix(pbs[skeleton.names[h.joint]]), units[k, h.joint])
                    if off <= SETTLED or h.control in left:
                        continue
                    if passes >= WARM_PASSES and off > 0.9 * best.get(h.control, np.inf):
                        left.add(h.control)
                        continue
                    best[h.control] = min(off, best.get(h.control, np.inf))
                    if _one_free_axis(pbs[h.control]) is None:
                        offset = _shown_offset(obj, skeleton.names[h.joint], h.control)
                        _set_world(obj, h.control, units[k, h.joint] @ offset)
                    else:  # moved by the head's miss, then rolled about the bone: its turn kept about its free axis
                        _settle_about_free_axis(obj, skeleton.names[h.joint], h.control, units[k, h.joint])
                    moved = max(moved, off)
                if moved > 0.0:
                    view_layer.update()
                # a rolled control carries nothing another handle measures: Blender shows it next pass
                rolled = max((_roll(obj, skeleton.names[h.joint], h.control, units[k, h.joint]) for h in rolling),
                             default=0.0)
                change = max(change, moved, rolled)
                for h in turning:
                    err = _plane_error(obj, skeleton, h, units[k])
                    if err is None or abs(err[2]) < 5e-5 or h.control in left:
                        continue
                    if passes >= WARM_PASSES and abs(err[2]) < NEAR_PLANE and abs(err[2]) > 0.9 * best.get(h.control, np.inf):
                        left.add(h.control)  # a knee its tweak control settles: the chain's turn no longer moves it
                        continue
                    best[h.control] = min(abs(err[2]), best.get(h.control, np.inf))
                    change = max(change, abs(err[2]))
                    secant[h.control].step(err[2])
                for h in targets:  # an IK chain that falls short of its target: the target a little further
                    miss = units[k, h.joint, :3, 3] - np.array(pbs[skeleton.names[h.joint]].head, dtype=float)
                    change = max(change, _reach_further(h.control, miss, reach, missed, last_shift, stuck,
                                                        REACH_M / skeleton.unit_scale))
                if change < 1e-6:
                    break
            for h in plan.handles:
                out[h.control][k] = np.array(pbs[h.control].matrix_basis, dtype=float)
            yield (k + 1) / len(frames)
    finally:
        for (b, p), v in saved_switch.items():
            pbs[b][p] = v
        for c, m in saved_basis.items():
            pbs[c].matrix_basis = m
        scene.frame_set(keep)
    return out


def _reach_further(c, miss, reach, missed, last_shift, stuck, limit):
    """Moves IK target `c`'s shift (`reach`) by the chain's `miss` (units) while the chain
    follows and the shift stays under `limit`; back to the best shift, and `stuck`, when it
    stops following. Updates the per-frame state in place; returns how far the target moved."""
    dist = float(np.linalg.norm(miss))
    if c in stuck or dist < 1e-5:
        return 0.0
    if dist > 0.7 * missed.get(c, np.inf):  # the chain doesn't follow: back to the best shift
        reach[c] -= last_shift[c]
        stuck.add(c)
        return float(np.abs(last_shift[c]).max())
    if np.linalg.norm(reach[c] + miss) < limit:
        reach[c] += miss
        missed[c], last_shift[c] = dist, miss
        return float(np.abs(miss).max())
    return 0.0


def _turn(obj, h, units, turn, start, rest_local):
    """Places a pole (in the solved limb plane, turned by `turn` about the limb's root-end line),
    or turns a pole-less IK chain's top before the IK solves it: its basis on the frame (`start`)
    turned by `turn` about that line, so the IK starts from the rig's own bend, turned."""
    from mathutils import Matrix
    heads = units[list(h.chain), :3, 3]
    root, x = heads[0], (heads[2] - heads[0]) / np.linalg.norm(heads[2] - heads[0])
    spin = _rotation_about(root, x, turn)
    pb = obj.pose.bones[h.control]
    if h.kind == "pole":
        t = _matrix(pb)
        t[:3, 3] = (spin @ _chain_frame(heads, units[h.chain[0], :3, :3], h.bend) @ h.local)[:3]
        return _set_world(obj, h.control, t)
    b0 = start.setdefault(h.control, np.array(pb.matrix_basis, dtype=float))
    parent = _matrix(pb.parent) if pb.parent is not None else np.eye(4)
    pre = parent @ rest_local @ b0  # where the chain's top is before the IK turns it
    spin = _rotation_about(pre[:3, 3], x, turn)  # about its own head: the top turns, never moves
    r = np.linalg.solve(pre, spin @ pre)
    b = b0 @ r
    old = np.array(pb.matrix_basis, dtype=float)
    pb.matrix_basis = Matrix(b.tolist())
    return float(np.abs(b - old).max())


def mismatch(obj, scene, skeleton, frames, solved, action=None):
    """{role: (largest head distance mm, largest angle deg)} between Blender's evaluation of the
    deform role bones (with `action`) and the solved frames (armature space, metres)."""
    shown = evaluated_pose(obj, scene, skeleton, frames, action)
    shown[..., :3, :3] /= np.linalg.norm(shown[..., :3, :3], axis=-2, keepdims=True)
    shown[..., :3, 3] *= skeleton.unit_scale
    out = {}
    for j, name in enumerate(skeleton.names):
        role = skeleton.roles.role_of(name)
        if role is None:
            continue
        d = np.linalg.norm(shown[:, j, :3, 3] - solved[:, j, :3, 3], axis=-1).max()
        rel = np.swapaxes(shown[:, j, :3, :3], -1, -2) @ solved[:, j, :3, :3]
        cos = np.clip((np.trace(rel, axis1=-2, axis2=-1) - 1.0) / 2.0, -1.0, 1.0)
        ang = np.degrees(np.arccos(cos)).max()
        mm, deg = out.get(role, (0.0, 0.0))
        out[role] = (round(max(mm, 1000 * float(d)), 3), round(max(deg, float(ang)), 3))
    return out


def write_pose(obj, scene, skeleton, frames, solved, name, fk=False, plan=None):
    """The NEW action keying the controls of `obj` so that its deform bones show `solved` (F, J,
    4, 4: the physical skeleton's frames in armature space, metres) on `frames`; and the report
    {"controls", "modes", "switches", "mismatch": {role: (mm, deg)}}. The source action is
    copied (its other keys kept), never changed; the scene's output setting (new action or NLA
    track) applies. Raises HumanAnimError when some role bone the solve moves has no control."""
    return run_to_end(write_pose_steps(obj, scene, skeleton, frames, solved, name, fk, plan))


def write_pose_steps(obj, scene, skeleton, frames, solved, name, fk=False, plan=None):
    """write_pose as a job step: yields progress (0-1) while solving the controls frame by frame."""
    from .posing import write_controls
    frames = np.asarray(frames)
    solved = np.asarray(solved, dtype=float)
    plan = plan or plan_controls(obj, skeleton, fk)
    moving = np.abs(solved - solved[:1]).max(axis=(0, 2, 3)) > 1e-6
    lost = [n for n in plan.unmapped if moving[skeleton.index(n)]]
    if lost:
        raise HumanAnimError(f"no control of '{obj.name}' moves {', '.join(lost[:4])}"
                             f"{' ...' if len(lost) > 4 else ''}: the result can't be keyed on this rig")
    bases = yield from iter_solve_bases(obj, scene, skeleton, plan, frames, solved)
    keys = write_controls(obj, scene, _Switches(plan.changed), frames, bases, name)
    action = keys.action
    report = {"controls": plan.controls, "modes": dict(plan.modes),
              "switches": {f"{b}:{p}": v for (b, p), v in plan.changed.items()},
              "mismatch": mismatch(obj, scene, skeleton, frames, solved, action)}
    return action, report


@dataclass
class _Switches:
    switches: dict
