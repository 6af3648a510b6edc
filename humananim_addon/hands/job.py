"""Hands in Blender (Huang 1996 ch. 4): grasp the selected object, release it, follow its
animation, hold another character's bone, remove self-collisions. Each writes a NEW action (the
source action is only read); a grasped object gets a Child Of constraint to the hand with a keyed
influence (1 while held, 0 from the release frame). On a control rig (a generated Rigify rig) the
solved role bones are keyed through the controls that carry them, with the IK/FK switch set to FK."""

import bpy
import numpy as np

from ...solver import rotations
from ...solver.body_roles import sided
from ...solver.errors import HumanAnimError, MotionError
from ...solver.hands import grasp as grasp_solver
from ...solver.hands import manipulation, self_collision
from ...solver.hands.checks import grasp_measures
from ...solver.hands.primitives import fit_primitive, kind
from ...solver.trajectories import Trajectories
from .. import actions
from ..armature import armature_to_world, skeleton_from_armature
from ..rig.controls import control_rig_for
from ..rig.posing import key_through_controls

CONSTRAINT = "HumanAnim Grasp"


# --- reading Blender -----------------------------------------------------------------------
def solver_view(obj, skeleton, sides=("L", "R"), with_spine=False):
    """(control rig or None, the skeleton the solver works on) for the rig's `skeleton`: on a
    control rig the solver keeps the bones it must not move still (see ControlRig). A rig whose arm
    or finger role bones follow other bones through constraints and have no control that moves
    them is refused (control_rig): keys on the role bones would be ignored."""
    crig = control_rig(obj, skeleton, sides, with_spine)
    return crig, (crig.solver_skeleton(skeleton) if crig else skeleton)


def rig_pose(obj, scene, skeleton, crig, frames):
    """pose_frames, made rigid on a control rig (its stretch removed, see ControlRig.rigid)."""
    base = pose_frames(obj, scene, skeleton, frames)
    return base if crig is None else crig.rigid(base)


def hand_skeleton(obj, scene):
    """The armature's Skeleton. Grasping needs no masses: a skin the mass model cannot use (open,
    hands only) falls back to the body tables for this run instead of failing."""
    from ...solver.errors import RigError
    try:
        return skeleton_from_armature(obj, scene)
    except RigError as error:
        settings = getattr(obj.data, "humananim", None)
        if settings is None or "mesh" not in str(error) or settings.mass_source == "ANTHROPOMETRIC":
            raise
        keep = settings.mass_source
        settings.mass_source = "ANTHROPOMETRIC"
        try:
            return skeleton_from_armature(obj, scene)
        finally:
            settings.mass_source = keep


def pose_frames(obj, scene, skeleton, frames):
    """Local bases (F, J, 4, 4) in metres: from the active action, or the current pose."""
    frames = [int(f) for f in frames]
    ad = obj.animation_data
    if ad is not None and ad.action is not None:
        try:
            tr = actions.read_action(obj, scene, skeleton, frame_range=(frames[0], frames[-1]))
            basis = tr.basis()
            have = {int(round(f)): k for k, f in enumerate(tr.frames)}
            first, last = tr.frames[0], tr.frames[-1]
            return np.array([basis[have[min(max(f, int(first)), int(last))]] for f in frames])
        except MotionError:
            pass
    if actions.needs_evaluation(obj):  # constraints place the bones: the evaluated pose
        return np.repeat(evaluated_basis(obj, skeleton)[None], len(frames), axis=0)
    m = np.array([np.array(pb.matrix_basis) for pb in (obj.pose.bones[n] for n in skeleton.names)])
    m[:, :3, 3] *= skeleton.unit_scale
    return np.repeat(m[None], len(frames), axis=0)


def evaluated_basis(obj, skeleton):
    """Local bases (J, 4, 4), metres, of the pose Blender shows now, for a rigid FK skeleton."""
    bpy.context.view_layer.update()
    m = np.array([np.array(obj.pose.bones[n].matrix, dtype=float) for n in skeleton.names])
    return actions.rigid_basis(m, skeleton)


def evaluated_mesh(obj, scene):
    """The vertices (V, 3), world, metres, and triangles (T, 3) of an object's evaluated mesh."""
    ev = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
    mesh = ev.to_mesh()
    try:
        mesh.calc_loop_triangles()
        co = np.empty(len(mesh.vertices) * 3)
        mesh.vertices.foreach_get("co", co)
        tri = np.empty(len(mesh.loop_triangles) * 3, dtype=np.int32)
        mesh.loop_triangles.foreach_get("vertices", tri)
    finally:
        ev.to_mesh_clear()
    m = np.array(obj.matrix_world)
    verts = co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]
    return verts * scene.unit_settings.scale_length, tri.reshape(-1, 3)


def object_shape(target, scene):
    """The grasp primitive of a mesh object (its evaluated mesh, world, metres)."""
    if target is None or target.type != "MESH":
        raise HumanAnimError("select a mesh object to grasp")
    verts, tri = evaluated_mesh(target, scene)
    if len(verts) < 4 or len(tri) < 4:
        raise HumanAnimError(f"'{target.name}' has too few faces to grasp")
    return fit_primitive(verts, tri)


def skin_of(obj):
    """The mesh deformed by the armature (an Armature modifier on it), or None."""
    for o in bpy.data.objects:
        if o.type == "MESH" and any(m.type == "ARMATURE" and m.object == obj for m in o.modifiers):
            return o
    return None


def hand_sensors_from_skin(obj, scene, skeleton, world):
    """Sensors sized from the skin's vertices around each finger bone and the palm (sec. 4.3.1);
    {} when the armature has no skin (the bones size them)."""
    skin = skin_of(obj)
    if skin is None:
        return {}
    index = {g.index: skeleton.find(g.name) for g in skin.vertex_groups}
    verts, _ = evaluated_mesh(skin, scene)
    owner = np.full(len(verts), -1)
    for v in skin.data.vertices:  # the strongest group of each vertex
        if v.groups:
            g = max(v.groups, key=lambda e: e.weight)
            j = index.get(g.group)
            owner[v.index] = -1 if j is None else j
    from ...solver.hands.sensors import default_hand_sensors, sensors_from_mesh
    return {s: sensors_from_mesh(skeleton, default_hand_sensors(skeleton, s), world, verts, owner)
            for s in ("L", "R") if skeleton.role_index(sided("hand", s)) is not None}


def _trajectories(frames, fps, basis, a2w):
    trans = basis[:, :, :3, 3].copy()
    quats = rotations.make_continuous(rotations.from_matrix(basis[:, :, :3, :3]))
    return Trajectories(np.asarray(frames, float), fps, quats, trans, a2w)


def _write(obj, scene, skeleton, frames, basis, name):
    output = getattr(getattr(scene, "humananim", None), "output", "ACTION")
    source = obj.animation_data.action if obj.animation_data else None
    return actions.write_action(obj, skeleton, _trajectories(frames, actions.scene_fps(scene), basis,
                                                              armature_to_world(obj, scene)),
                                name, output=output, source=source)


# --- grasp ----------------------------------------------------------------------------------
def run_grasp(obj, scene, target, props=None, solved=None):
    """Job: reach, close, write the new action and the keyed Child Of. Yields progress; returns
    the summary dict. `solved`, a dict, receives the solve (skeleton, result, shape, armature to
    world, grasped frame) to check what Blender shows against it."""
    props = props or scene.humananim_hands
    skeleton = hand_skeleton(obj, scene)
    sides = ("L", "R") if props.side == "AUTO" else (props.side,)
    rig_skeleton = skeleton
    crig, skeleton = solver_view(obj, skeleton, sides, props.with_spine)
    shape = object_shape(target, scene)
    fps = actions.scene_fps(scene)
    reach = max(1, int(round(props.duration * fps)))
    close = max(1, int(round(props.close_duration * fps)))
    start = props.start_frame
    yield 0.1
    basis0 = rig_pose(obj, scene, skeleton, crig, [start])[0]
    pattern = None
    if props.pattern is not None:
        pattern = pose_frames_of_action(obj, scene, skeleton, props.pattern)
    a2w = armature_to_world(obj, scene)
    gtype = None if props.grasp_type == "AUTO" else props.grasp_type
    keep = scene.frame_current
    scene.frame_set(start)  # the skin at the start pose
    skin_sensors = hand_sensors_from_skin(obj, scene, skeleton, skeleton.world_frames(basis0, a2w))
    scene.frame_set(keep)
    result = grasp_solver.grasp(skeleton, basis0, a2w, shape, side=props.side, gtype=gtype, reach_frames=reach,
                                close_frames=close, fps=fps, pattern=pattern, with_spine=props.with_spine,
                                hand_sensors=skin_sensors)
    yield 0.7
    end = start + result.frame_count - 1
    release = props.release_frame if props.release_frame > end else 0
    last = max(end, release)
    frames = np.arange(start, last + 1)
    base = rig_pose(obj, scene, skeleton, crig, frames)
    moved = _moved_joints(skeleton, result)
    if crig is not None:  # the twist segments the solver kept still stay as they were at the start
        moved = np.union1d(moved, np.array(crig.frozen, dtype=int))
    out = base.copy()
    for k in range(len(frames)):
        src = result.basis[min(k, result.frame_count - 1)]
        out[k, moved] = src[moved]
    action = write_result(obj, scene, rig_skeleton, crig, frames, base, out, f"{target.name}.grasp")
    yield 0.9
    hand_bone = skeleton.names[skeleton.role_index(sided("hand", result.hands[0].side))]
    attach(obj, scene, target, hand_bone, end, release)
    m = grasp_measures(skeleton, result, shape, a2w)
    if solved is not None:
        solved.update(skeleton=skeleton, result=result, shape=shape, armature_to_world=a2w,
                      grasped_frame=int(end))
    return {"action": action.name, "object": target.name, "type": result.gtype, "primitive": kind(shape),
            "hands": [h.side for h in result.hands], "fingers_touching": {h.side: list(h.fingers_touching)
                                                                           for h in result.hands},
            "frames": [int(start), int(last)], "grasped_frame": int(end), "release_frame": int(release),
            "max_penetration_mm": round(1000 * m["max_penetration_m"], 3),
            "max_finger_gap_mm": round(1000 * m["max_finger_gap_m"], 3),
            "reach_error_mm": round(1000 * m["reach_error_m"], 3), "hand_bone": hand_bone,
            "sensors_from": "skin" if skin_sensors else "bones",
            "controls": sorted(c for c, _ in crig.controls.values()) if crig else [],
            "switches": {f"{b}:{p}": v for (b, p), v in crig.switches.items()} if crig else {}}


def pose_frames_of_action(obj, scene, skeleton, action):
    tr = actions.read_action(obj, scene, skeleton, action=action)
    return tr.basis()[0]


def _moved_joints(skeleton, result):
    diff = np.abs(result.basis - result.basis[:1]).max(axis=(0, 2, 3))
    return np.flatnonzero(diff > 1e-9)


def attach(obj, scene, target, bone, frame, release=0):
    """A Child Of constraint from the object to the hand bone, its influence keyed 0 before the
    grasp frame, 1 from it, 0 again from the release frame; the inverse keeps the object where
    it is at the grasp frame."""
    con = target.constraints.get(CONSTRAINT) or target.constraints.new("CHILD_OF")
    con.name = CONSTRAINT
    con.target, con.subtarget = obj, bone
    keep = scene.frame_current
    scene.frame_set(int(frame))
    bpy.context.view_layer.update()
    hand = obj.matrix_world @ obj.pose.bones[bone].matrix
    con.inverse_matrix = hand.inverted()
    scene.frame_set(keep)
    path = f'constraints["{CONSTRAINT}"].influence'
    con.influence = 0.0
    target.keyframe_insert(path, frame=frame - 1)
    con.influence = 1.0
    target.keyframe_insert(path, frame=frame)
    if release:
        set_release(target, release)
    return con


def set_release(target, frame):
    con = target.constraints.get(CONSTRAINT)
    if con is None:
        raise HumanAnimError(f"'{target.name}' is not held (no '{CONSTRAINT}' constraint)")
    path = f'constraints["{CONSTRAINT}"].influence'
    con.influence = 1.0
    target.keyframe_insert(path, frame=frame - 1)
    con.influence = 0.0
    target.keyframe_insert(path, frame=frame)
    return con


# --- follow an object / hold another character ---------------------------------------------
def object_world_frames(target, scene, frames):
    """The object's own animated frames (metres), the grasp constraint muted while sampling."""
    con = target.constraints.get(CONSTRAINT)
    muted = con.mute if con else None
    keep = scene.frame_current
    out = []
    try:
        if con:
            con.mute = True
        for f in frames:
            scene.frame_set(int(f))
            m = np.array(target.matrix_world)
            m[:3, :3] /= np.linalg.norm(m[:3, :3], axis=0)
            m[:3, 3] *= scene.unit_settings.scale_length
            out.append(m)
    finally:
        if con:
            con.mute = muted
        scene.frame_set(keep)
    return np.array(out)


def run_follow(obj, scene, target, props=None):
    """Job: the hand holding `target` follows the object's own animation over the frame range."""
    props = props or scene.humananim_hands
    con = target.constraints.get(CONSTRAINT)
    if con is None or con.target != obj:
        raise HumanAnimError(f"'{target.name}' is not held by '{obj.name}': grasp it first")
    skeleton = hand_skeleton(obj, scene)
    frames = np.arange(props.frame_start, props.frame_end + 1)
    if len(frames) < 2:
        raise MotionError("the frame range is empty")
    side = skeleton.roles.role_of(con.subtarget).split(".")[-1]
    rig_skeleton = skeleton
    crig, skeleton = solver_view(obj, skeleton, (side,))
    a2w = armature_to_world(obj, scene)
    base = rig_pose(obj, scene, skeleton, crig, frames)
    yield 0.2
    objects = object_world_frames(target, scene, frames)
    hand = skeleton.role_index(sided("hand", side))
    w0 = skeleton.world_frames(base[0], a2w)
    grip = grasp_solver.rigid_inv(w0[hand]) @ objects[0]
    out, report = manipulation.follow(skeleton, base, a2w, objects, {side: grip})
    yield 0.9
    action = write_result(obj, scene, rig_skeleton, crig, frames, base, out, f"{target.name}.follow")
    con.influence = 0.0  # the object leads now: the arm follows it
    target.keyframe_insert(f'constraints["{CONSTRAINT}"].influence', frame=int(frames[0]))
    return {"action": action.name, "object": target.name, "frames": [int(frames[0]), int(frames[-1])],
            "max_grip_error_mm": round(1000 * report.max_position_error, 3),
            "max_grip_error_deg": round(float(np.degrees(report.max_rotation_error)), 3)}


def run_hold(obj, scene, props=None):
    """Job: the active character reaches and holds the other's bone, then follows its motion."""
    props = props or scene.humananim_hands
    other = props.other
    if other is None or other.type != "ARMATURE" or other == obj:
        raise HumanAnimError("choose another armature to hold")
    if props.other_bone not in other.pose.bones:
        raise HumanAnimError(f"'{other.name}' has no bone '{props.other_bone}'")
    skeleton = hand_skeleton(obj, scene)
    sides = ("L", "R") if props.side == "AUTO" else (props.side,)
    rig_skeleton = skeleton
    crig, skeleton = solver_view(obj, skeleton, sides)
    other_sk = hand_skeleton(other, scene)
    fps = actions.scene_fps(scene)
    reach = max(1, int(round(props.duration * fps)))
    close = max(1, int(round(props.close_duration * fps)))
    start = props.start_frame
    grasp_end = start + reach + close
    frames_other = np.arange(grasp_end, max(props.frame_end, grasp_end + 1) + 1)
    other_basis = pose_frames(other, scene, other_sk, frames_other)
    yield 0.2
    basis0 = rig_pose(obj, scene, skeleton, crig, [start])[0]
    out, g, report = manipulation.hold(skeleton, basis0, armature_to_world(obj, scene), other_sk, other_basis,
                                       armature_to_world(other, scene), props.other_bone,
                                       side=props.side, reach_frames=reach, close_frames=close, fps=fps)
    yield 0.9
    frames = np.arange(start, start + len(out))
    base = np.repeat(basis0[None], len(out), axis=0)  # the solver starts every frame from it
    action = write_result(obj, scene, rig_skeleton, crig, frames, base, out, f"{obj.name}.hold.{other.name}")
    return {"action": action.name, "held": f"{other.name}:{props.other_bone}", "type": g.gtype,
            "frames": [int(frames[0]), int(frames[-1])],
            "max_grip_error_mm": round(1000 * report.max_position_error, 3)}


def run_self_collisions(obj, scene, props=None):
    """Job: the arms kept out of the trunk and head, and the legs out of each other and the trunk,
    over the frame range (table 4-1)."""
    props = props or scene.humananim_hands
    skeleton = hand_skeleton(obj, scene)
    frames = np.arange(props.frame_start, props.frame_end + 1)
    sides = tuple(s for s in ("L", "R") if skeleton.role_index(sided("hand", s)) is not None)
    rig_skeleton = skeleton
    crig, skeleton = solver_view(obj, skeleton, sides, props.with_spine)
    base = rig_pose(obj, scene, skeleton, crig, frames)
    yield 0.2
    out, rep = self_collision.remove_self_collisions(skeleton, base, armature_to_world(obj, scene), sides=sides,
                                                     with_spine=props.with_spine)
    yield 0.9
    action = write_result(obj, scene, rig_skeleton, crig, frames, base, out, f"{obj.name}.no_self_collision")
    return {"action": action.name, "frames": [int(frames[0]), int(frames[-1])],
            "frames_corrected": rep.frames_corrected, "leg_frames_corrected": rep.leg_frames_corrected,
            "max_depth_before_mm": round(1000 * rep.max_depth_before, 2),
            "max_depth_after_mm": round(1000 * rep.max_depth_after, 2),
            "max_hand_error_mm": round(1000 * rep.max_goal_error, 2),
            "max_foot_error_mm": round(1000 * rep.max_foot_error, 2)}


# --- control rigs (a generated Rigify rig: the rig layer, rig/controls.py and rig/posing.py) -----
_CONTROL_ADVICE = "grasp with the metarig, or map the hand roles to the FK controls"


def control_rig(obj, skeleton, sides=("L", "R"), with_spine=False):
    """None for a plain FK rig (no arm, spine or finger bone the solver moves follows a constraint);
    else the ControlRig whose joints still need their controls (rig.controls.map_controls)."""
    from ...solver.body_roles import FINGERS
    from ...solver.hands.ik import chain_joints
    joints = []
    for s in sides:
        if skeleton.role_index(sided("hand", s)) is None:
            continue
        joints += chain_joints(skeleton, s, with_spine)
        joints += [skeleton.index(n) for f in FINGERS for n in skeleton.roles.chain(sided(f, s))]
    return control_rig_for(obj, skeleton, joints)


def write_result(obj, scene, skeleton, crig, frames, base, out, name):
    """The new action: the role bones' keys on a plain rig; on a control rig, the controls'."""
    if crig is None:
        return _write(obj, scene, skeleton, frames, out, name)
    return key_through_controls(obj, scene, skeleton, crig, frames, base, out, name, _CONTROL_ADVICE)
