"""Retarget Motion: one armature's motion (a BVH or FBX import, another rig in the scene) put onto
another rig, through both rigs' body roles, written to the target's controls in a NEW action.

Per role, the source joint's rotation relative to its rest frame is carried onto the target's role
joint relative to the target's rest frame, after the target's rest direction (head to the next
role joint's head) is turned onto the source's: so T-pose against A-pose, bone rolls and bones
laid along X or Y don't matter. The pelvis travels the source's path scaled by the ratio of the
legs' lengths (hip to knee to ankle), its height over the source's floor scaled the same way.
Then, where the source plants a foot, the target's foot is held planted on the ground (Z = 0) by
the clean-up's foot-skate repair (solver.cleanup.feet: leg IK, the pelvis lowered where a leg
can't reach). The source is read only (never changed)."""

import json
import time

import numpy as np

from ...solver import rotations
from ...solver.body_roles import CHAIN_ROLES, SINGLE_ROLES
from ...solver.cleanup import feet
from ...solver.errors import MotionError, RigError
from ...solver.skeleton import Skeleton, decompose
from ...solver.trajectories import Trajectories
from ..rig.capability import RigView

PROPERTY = "humananim_retarget"  # the last retarget's summary, JSON, on the target armature
GROUND = 0.0
REST_BEND_DEG = 20.0  # a source rest with a knee bent further, or its sides differing more, is a captured pose
TWIST_WARNING_DEG = 5.0  # a role the rig shows turned this far from the retargeted pose is named
# the role whose head gives a role bone's direction (the bone's own axis where there is none)
NEXT = {"pelvis": "spine", "chest": "neck", "neck": "head", "clavicle": "upper_arm", "upper_arm": "forearm",
        "forearm": "hand", "thigh": "shin", "shin": "foot", "foot": "toe"}


def role_pairs(src, tgt):
    """[(source joint, target joint, source next joint or None, target next joint or None)] for
    every role both skeletons have; chains (spine, fingers) matched along their length."""
    pairs = []

    def next_of(skel, role, chain_next=None):
        if chain_next is not None:
            return chain_next
        base, _, side = role.partition(".")
        nxt = NEXT.get(base)
        if nxt is None:
            return None
        r = f"{nxt}.{side}" if side else nxt
        if r == "spine":
            ch = skel.roles.chain("spine")
            return skel.index(ch[0]) if ch else None
        return skel.role_index(r)

    for role in SINGLE_ROLES:
        a, b = src.role_index(role), tgt.role_index(role)
        if a is not None and b is not None:
            pairs.append((a, b, next_of(src, role), next_of(tgt, role)))
    for role in CHAIN_ROLES:
        sa, ta = src.roles.chain(role), tgt.roles.chain(role)
        if not sa or not ta:
            continue
        after = "chest" if role == "spine" else None
        for i, name in enumerate(ta):
            k = int(round(i * (len(sa) - 1) / max(len(ta) - 1, 1)))
            sn = src.index(sa[k + 1]) if k + 1 < len(sa) else (src.role_index(after) if after else None)
            tn = tgt.index(ta[i + 1]) if i + 1 < len(ta) else (tgt.role_index(after) if after else None)
            pairs.append((src.index(sa[k]), tgt.index(name), sn, tn))
    return pairs


def _direction(skel, rest, j, nxt):
    """Unit direction of joint j in rest (world frames): towards the next role joint's head, else the
    bone's own axis; but where every child of the bone starts at its head (a zero-length joint in
    the file, CMU's wrists: the importer gives it an axis of its own choosing: up the forearm in Blender 5.0),
    towards the nearest descendants' heads away from it."""
    head = rest[j, :3, 3]
    if nxt is not None:
        d = rest[nxt, :3, 3] - head
        if np.linalg.norm(d) > 0.01:
            return d / np.linalg.norm(d)
    away = _heads_away(skel, rest, j)
    if away is not None:
        return away
    return rest[j, :3, 1] / np.linalg.norm(rest[j, :3, 1])


def _heads_away(skel, rest, j):
    """Direction (unit) from joint j's head to the mean head of its nearest descendants more than
    1 cm away (those with a role, where some have one), when all its children start at its head;
    None otherwise (or with no children)."""
    head = rest[j, :3, 3]

    def far(k):
        return np.linalg.norm(rest[k, :3, 3] - head) > 0.01
    level = list(skel.children(j))
    if not level or any(far(k) for k in level):
        return None
    while level:
        found = [k for k in level if far(k)]
        # role joints first: an exporter's leaf bones (FBX's "_end") at the same depth would pull it
        found = [k for k in found if skel.roles.role_of(skel.names[k]) is not None] or found
        if found:
            d = np.mean(rest[found, :3, 3], axis=0) - head
            return d / np.linalg.norm(d)
        level = [c for k in level for c in skel.children(k)]
    return None


def _arc(a, b):
    """The smallest rotation (3, 3) turning unit vector a onto unit vector b."""
    v, c = np.cross(a, b), float(np.dot(a, b))
    if c < -1 + 1e-9:  # opposite: half a turn about any perpendicular
        p = np.cross(a, [1.0, 0, 0]) if abs(a[0]) < 0.9 else np.cross(a, [0, 1.0, 0])
        p /= np.linalg.norm(p)
        return 2 * np.outer(p, p) - np.eye(3)
    k = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + k + k @ k / (1 + c)


def leg_length(skel, rest):
    """Hip-to-knee-to-ankle length (m), the mean of both legs."""
    out = []
    for s in ("L", "R"):
        t, k, f = (skel.role_index(f"{r}.{s}") for r in ("thigh", "shin", "foot"))
        out.append(np.linalg.norm(rest[k, :3, 3] - rest[t, :3, 3]) + np.linalg.norm(rest[f, :3, 3] - rest[k, :3, 3]))
    return float(np.mean(out))


def _heading_turn(src, s_rest, tgt, t_rest):
    """A turn about Z (3, 3) bringing the source's rest facing (its hips' left-right line) onto the target's."""
    def across(skel, rest):
        d = rest[skel.role_index("thigh.L"), :3, 3] - rest[skel.role_index("thigh.R"), :3, 3]
        return np.array([d[0], d[1], 0.0]) / max(np.hypot(d[0], d[1]), 1e-9)
    return _arc(across(src, s_rest), across(tgt, t_rest))


def map_motion(src, src_traj, tgt, tgt_to_world):
    """The target's Trajectories (on `tgt`, over the source's frames) and the leg-length ratio."""
    s_rest = src_traj.armature_to_world @ src.rest
    t_rest = tgt_to_world @ tgt.rest
    s_world = src_traj.world_frames(src)
    ratio = leg_length(tgt, t_rest) / leg_length(src, s_rest)
    turn = _heading_turn(src, s_rest, tgt, t_rest)
    F = src_traj.frame_count
    rot = {}  # target joint -> (F, 3, 3) world rotation
    for a, b, an, bn in role_pairs(src, tgt):
        align = _arc(_direction(tgt, t_rest, b, bn), turn @ _direction(src, s_rest, a, an))
        delta = turn @ s_world[:, a, :3, :3] @ s_rest[a, :3, :3].T @ turn.T
        rot[b] = delta @ (align @ t_rest[b, :3, :3])
    pelvis_s, pelvis_t = src.role_index("pelvis"), tgt.role_index("pelvis")
    floor = _source_floor(src, s_world, src_traj.fps)
    p = ratio * (s_world[:, pelvis_s, :3, 3] - [0.0, 0.0, floor]) @ turn.T
    # the target sets out where the source does: its path turned and scaled about that first point
    # (not about the world's origin, which moves the start wherever the rests' facings differ)
    p[:, :2] += s_world[0, pelvis_s, :2, 3] - p[0, :2]
    p[:, 2] += GROUND
    world = np.empty((F, tgt.joint_count, 4, 4))
    basis = np.empty_like(world)
    for j, parent in enumerate(tgt.parents):
        base = (np.broadcast_to(tgt_to_world, (F, 4, 4)) if parent < 0 else world[:, parent]) @ tgt.rest_local[j]
        want = base.copy()
        if j in rot:
            want[:, :3, :3] = rot[j]
        if j == pelvis_t:
            want[:, :3, 3] = p
        world[:, j] = want
        basis[:, j] = np.linalg.solve(base, want)
    trans, quats = decompose(basis)
    return Trajectories(src_traj.frames, src_traj.fps, rotations.make_continuous(quats), trans, tgt_to_world), ratio


def rest_pose_warning(skel, rest):
    """A sentence when the source's rest (world frames) reads as a captured pose, not a T- or
    A-pose: a knee bent more than REST_BEND_DEG, or the left and right knees or upper arms more
    than that apart (a neutral rest is symmetric). Each bone's turn is measured from the rest, so
    such a rest turns the result (docs/rigs.md, Sources). None otherwise, or without the roles."""
    def head(role):
        j = skel.role_index(role)
        return None if j is None else rest[j, :3, 3]

    def angle(u, v):
        return float(np.degrees(np.arccos(np.clip(np.dot(u, v) / (np.linalg.norm(u) * np.linalg.norm(v)), -1, 1))))
    knee, arm = {}, {}
    for side in ("L", "R"):
        hip, k, ankle = (head(f"{r}.{side}") for r in ("thigh", "shin", "foot"))
        if hip is not None and k is not None and ankle is not None:
            knee[side] = angle(k - hip, ankle - k)
        shoulder, elbow = head(f"upper_arm.{side}"), head(f"forearm.{side}")
        if shoulder is not None and elbow is not None:
            rise = (elbow - shoulder)[2] / np.linalg.norm(elbow - shoulder)
            arm[side] = float(np.degrees(np.arcsin(np.clip(rise, -1, 1))))
    found = [f"a knee bent {max(knee.values()):.0f} deg"] if knee and max(knee.values()) > REST_BEND_DEG else []
    for name, values in (("knees", knee), ("upper arms", arm)):
        if len(values) == 2 and abs(values["L"] - values["R"]) > REST_BEND_DEG:
            found.append(f"its {name} {abs(values['L'] - values['R']):.0f} deg apart")
    if not found:
        return None
    return (f"the source's rest pose looks captured, not a T- or A-pose ({', '.join(found)}): each bone's turn is "
            "measured from it, so the result is turned by as much (docs/rigs.md, Sources)")


def _source_floor(src, s_world, fps):
    points = feet.foot_points(src, s_world)
    return float(feet.find_floor(points, feet.find_contacts(points, fps)))


def source_contacts(src, src_traj):
    """{side: (F, k) bool}: where the source plants each foot point (ball, toe tip)."""
    return feet.planted_points(feet.foot_points(src, src_traj.world_frames(src)), src_traj.fps)


def plant_feet(tgt, traj, planted_src):
    """The target's feet held where they land and on the ground wherever the source's are planted.
    Returns (trajectories, planted as the target's foot points)."""
    points = feet.foot_points(tgt, traj.world_frames(tgt))
    planted = {}
    for side, p in points.items():
        down = planted_src.get(side)
        if down is None:
            continue
        if down.shape[1] == p.shape[1]:
            planted[side] = down
        else:  # one rig has toes, the other not: the foot's ball holds while the source's foot is down
            planted[side] = np.zeros(p.shape[:2], bool)
            planted[side][:, 0] = down.any(axis=1)
    # the target's own floor (its ankles sit higher or lower than the source's) put on the ground
    contacts = {s: d.any(axis=1) for s, d in planted.items()}
    lift = GROUND - float(feet.find_floor({s: points[s] for s in planted}, contacts))
    position, orientation = traj.root_pose(tgt)
    traj = traj.with_root_pose(tgt, position + [0.0, 0.0, lift], orientation)
    points = {s: p + [0.0, 0.0, lift] for s, p in points.items()}
    offsets = feet.foot_offsets({s: points[s] for s in planted}, traj.fps, floor=GROUND, skate=True, planted=planted)
    # hold_feet, not move_feet then pin_toes: where a held toe tip would go under the ground the foot
    # is raised instead, so the tip stays where it landed rather than sliding (14 mm on CMU 131_01)
    traj, moved = feet.hold_feet(tgt, traj, offsets, floor=GROUND, planted=planted)
    return traj, planted, float(moved["pelvis_drop"].max()) if "pelvis_drop" in moved else 0.0


def retarget(source, target, scene, action=None, frame_range=None, name=None, output="ACTION"):
    """Retarget `action` (the source's active one by default) of armature `source` onto armature
    `target`; returns the summary (the new action, the leg ratio, the feet's measures and, on a
    control rig, the write-back's mismatch per role)."""
    t0 = time.perf_counter()
    if source is None or target is None or source.type != "ARMATURE" or target.type != "ARMATURE":
        raise RigError("retargeting needs a source armature and a target armature")
    if source == target:
        raise RigError(f"'{source.name}' is both the source and the target: pick another armature as the source")
    ad = source.animation_data
    action = action or (ad.action if ad else None)
    if action is None:
        raise MotionError(f"the source '{source.name}' has no action to retarget")
    src_view, tgt_view = RigView(source, scene), RigView(target, scene)
    src, tgt = src_view.skeleton, tgt_view.skeleton
    src_traj = src_view.read(action, frame_range)
    if src_traj.frame_count < 3:
        raise MotionError(f"'{action.name}' has {src_traj.frame_count} frames: retargeting needs at least 3")
    traj, ratio = map_motion(src, src_traj, tgt, _to_world(target, scene))
    legs, keep = role_skeleton(tgt)
    planted_traj, planted, drop = plant_feet(legs, _columns(traj, keep), source_contacts(src, src_traj))
    measures = foot_measures(legs, planted_traj, planted)
    rot, trans = traj.rotations.copy(), traj.translations.copy()
    rot[:, keep], trans[:, keep] = planted_traj.rotations, planted_traj.translations
    traj = Trajectories(traj.frames, traj.fps, rot, trans, traj.armature_to_world)
    traj = ik_bends(tgt_view, traj)
    traj = swung_from_rest(tgt_view, traj)
    result = tgt_view.write(traj, name or f"{action.name}.{target.name}", output)
    # the source's action is "source_motion", not "source_action": the motion QA would read it on the target
    summary = {"command": "retarget", "armature": target.name, "source": source.name, "source_motion": action.name,
               "action": result.name, "frame_range": [float(traj.frames[0]), float(traj.frames[-1])],
               "fps": traj.fps, "roles_mapped": len(role_pairs(src, tgt)), "leg_ratio": round(ratio, 4),
               "pelvis_lowered_cm": round(100 * drop, 2), **measures, **tgt_view.summary(),
               "ms": round(1000 * (time.perf_counter() - t0), 1)}
    warning = rest_pose_warning(src, src_traj.armature_to_world @ src.rest)
    if warning:
        summary["source_rest_warning"] = warning
    target[PROPERTY] = json.dumps(summary)
    return summary


def ik_bends(view, traj):
    """`traj` with the thighs and shins (upper arms and forearms) of the target's IK limbs turned
    into the plane the rig's IK bends them in (rig.writeback.as_ik_shows: the knee about the
    hip-ankle line, each bone about its own axis; hips and ankles unchanged), so the retargeted
    pose is one the rig can show."""
    from ..rig.writeback import as_ik_shows, ik_limbs
    limbs = ik_limbs(view.obj, view.skeleton) if view.control_rig else []
    if not limbs:
        return traj
    skel = view.skeleton
    world = as_ik_shows(skel, skel.world_frames(traj.basis()), limbs)
    changed = sorted({j for (u, m, _), _ in limbs for j in (u, m, *skel.children(u), *skel.children(m))})
    rot = traj.rotations.copy()
    for j in changed:
        p = skel.parents[j]
        base = skel.rest_local[j] if p < 0 else world[:, p] @ skel.rest_local[j]
        rot[:, j] = rotations.from_matrix(np.linalg.solve(base, world[:, j])[:, :3, :3])
    rot[:, changed] = rotations.make_continuous(rot[:, changed])
    return Trajectories(traj.frames, traj.fps, rot, traj.translations, traj.armature_to_world)


def swung_from_rest(view, traj):
    """`traj` with the target's role bones that the rig only swings (rig.writeback.swung_bones:
    a Stretch To aims them, no control rolls them) given the roll the rig gives them: their rest
    on their parent's retargeted frame, turned by the smallest rotation onto their retargeted
    direction. Their direction, and every other bone's frame, unchanged. The source's turn of such
    a bone about its own axis (up to 20 deg on CMU's thumbs onto Rigify) can't be shown there."""
    from ..rig.writeback import swung_bones
    joints = swung_bones(view.obj, view.skeleton) if view.control_rig else []
    if not joints:
        return traj
    skel = view.skeleton
    world = skel.world_frames(traj.basis())
    for j in joints:  # parents first: a swung bone's parent may be swung too
        base = world[:, skel.parents[j]] @ skel.rest_local[j]
        world[:, j, :3, :3] = rotations.rotation_between(base[:, :3, 1], world[:, j, :3, 1]) @ base[:, :3, :3]
    changed = sorted({k for j in joints for k in (j, *skel.children(j))})
    rot = traj.rotations.copy()
    for j in changed:
        p = skel.parents[j]
        base = skel.rest_local[j] if p < 0 else world[:, p] @ skel.rest_local[j]
        rot[:, j] = rotations.from_matrix(np.linalg.solve(base, world[:, j])[:, :3, :3])
    rot[:, changed] = rotations.make_continuous(rot[:, changed])
    return Trajectories(traj.frames, traj.fps, rot, traj.translations, traj.armature_to_world)


def role_skeleton(skel):
    """(the skeleton of `skel`'s role joints only, each hung from its nearest kept ancestor; the
    indices kept). The joints left out (twist segments, a rig's extra bones) stay at rest on their
    parents in a retargeted pose, so the role joints' bases are the same on both skeletons; the
    legs' IK of the foot repair needs thigh, shin and foot as a parent-child chain."""
    keep = [j for j, n in enumerate(skel.names) if skel.roles.role_of(n) is not None or skel.parents[j] < 0]
    new = {j: i for i, j in enumerate(keep)}

    def kept_parent(j):
        p = skel.parents[j]
        while p >= 0 and p not in new:
            p = skel.parents[p]
        return new[p] if p >= 0 else -1

    parents = np.array([kept_parent(j) for j in keep], dtype=int)
    same = np.array([skel.parents[j] in new or skel.parents[j] < 0 for j in keep])
    return Skeleton(tuple(skel.names[j] for j in keep), parents, skel.rest[keep], skel.lengths[keep],
                    skel.connected[keep] & same, skel.dof[keep], skel.limits[keep], skel.mass[keep], skel.com[keep],
                    skel.inertia[keep], skel.roles, skel.unit_scale), keep


def _columns(traj, keep):
    return Trajectories(traj.frames, traj.fps, traj.rotations[:, keep], traj.translations[:, keep],
                        traj.armature_to_world)


def _to_world(obj, scene):
    from ..armature import armature_to_world
    return armature_to_world(obj, scene)


def foot_measures(skel, traj, planted):
    """The solved feet: the largest slide of a planted point (mm) and the lowest foot point (mm
    above the ground)."""
    points = feet.foot_points(skel, traj.world_frames(skel))
    low = min(float(p[..., 2].min()) for p in points.values()) - GROUND
    return {"planted_slide_mm": round(1000 * feet.planted_slide(skel, traj, planted), 2),
            "lowest_foot_mm": round(1000 * low, 2)}


def held_slide(points, planted):
    """The largest slide (m) over the ground of the point a planted foot stands on: the ball while
    it is down, else the toe tip. `points` from feet.foot_points, `planted` from source_contacts."""
    worst = 0.0
    for side, down in planted.items():
        for i, mask in enumerate((down[:, 0], down[:, 1] & ~down[:, 0]) if down.shape[1] > 1 else (down[:, 0],)):
            for a, b in feet.contact_runs(mask):
                p = points[side][a:b, i, :2]
                worst = max(worst, float(np.linalg.norm(p - p[0], axis=1).max()))
    return worst


def stored(obj):
    """The last retarget summary on `obj`, or None."""
    raw = obj.get(PROPERTY) if obj is not None else None
    return json.loads(raw) if raw else None


def lines(summary):
    """The panel's and the command's lines: feet, ratio, and the mismatch per role."""
    out = [f"'{summary['source']}' -> '{summary['action']}': {summary['roles_mapped']} roles, "
           f"legs x{summary['leg_ratio']:.2f}",
           f"planted feet slide {summary['planted_slide_mm']:.1f} mm, lowest foot {summary['lowest_foot_mm']:+.1f} mm"]
    if summary.get("source_rest_warning"):
        out.append(f"warning: {summary['source_rest_warning']}")
    for role, (mm, deg) in sorted((summary.get("mismatch_per_role") or {}).items()):
        out.append(f"{role}: {mm:.2f} mm, {deg:.2f} deg")
    return out
