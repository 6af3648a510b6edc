"""Hands in Blender (Huang 1996 ch. 4): grasp the selected object, release it, follow its
animation, hold another character's bone, remove self-collisions. Each writes a NEW action (the
source action is only read); a grasped object gets a Child Of constraint to the hand with a keyed
influence (1 while held, 0 from the release frame). On a control rig (a generated Rigify rig) the
solved role bones are keyed through the controls that carry them, with the IK/FK switch set to FK."""

import re
from dataclasses import dataclass, field, replace

import bpy
import numpy as np
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty, StringProperty

from ..solver import rotations
from ..solver.body_roles import sided
from ..solver.errors import HumanAnimError, MotionError
from ..solver.hands import grasp as grasp_solver
from ..solver.hands import manipulation, self_collision
from ..solver.hands.checks import grasp_measures
from ..solver.hands.primitives import fit_primitive, kind
from ..solver.trajectories import Trajectories
from . import action_api, actions
from .armature import armature_to_world, skeleton_from_armature
from .properties import settings_registration

CONSTRAINT = "HumanAnim Grasp"
TYPE_ITEMS = (("AUTO", "Automatic", "From the object's primitive and the hand's size (the thesis's table)"),
              ("LATERAL", "Lateral", "Thumb against the side of the index (a card)"),
              ("PINCH", "Pinch", "Thumb and index tips"),
              ("TRIPOD", "Tripod", "Thumb, index and middle tips (a small ball)"),
              ("WRAP", "Wrap", "The whole hand around it"),
              ("DISK", "Disk", "Fingers spread over a flat round object (a lid)"))


class HumanAnimHands(bpy.types.PropertyGroup):
    side: EnumProperty(name="Hand", items=(("AUTO", "Nearest", "The hand nearer the object"),
                                           ("L", "Left", ""), ("R", "Right", "")))
    grasp_type: EnumProperty(name="Type", items=TYPE_ITEMS)
    pattern: PointerProperty(name="Pattern", type=bpy.types.Action,
                             description="A hand pose from the pose library the fingers close toward "
                                         "(its first frame); empty: the built-in pattern of the type")
    duration: FloatProperty(name="Reach", default=1.0, min=0.1, soft_max=5.0, unit="TIME_ABSOLUTE",
                            description="Seconds the arm takes to reach the object")
    close_duration: FloatProperty(name="Close", default=0.5, min=0.05, soft_max=3.0, unit="TIME_ABSOLUTE",
                                  description="Seconds the fingers take to close")
    start_frame: IntProperty(name="Start", default=1, description="Frame the reach starts")
    release_frame: IntProperty(name="Release", default=0,
                               description="Frame the object is let go (0: held to the end)")
    with_spine: BoolProperty(name="Use Spine", description="The spine bends to help the reach")
    other: PointerProperty(name="Other Character", type=bpy.types.Object,
                           description="The armature whose bone is held")
    other_bone: StringProperty(name="Bone", description="The other character's bone to hold (hand, arm, shoulder)")
    frame_start: IntProperty(name="From", default=1, description="First frame to follow or correct")
    frame_end: IntProperty(name="To", default=100, description="Last frame to follow or correct")


register, unregister = settings_registration((HumanAnimHands,), bpy.types.Scene, "humananim_hands", HumanAnimHands)


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
    from ..solver.errors import RigError
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


def object_shape(target, scene):
    """The grasp primitive of a mesh object (its evaluated mesh, world, metres)."""
    if target is None or target.type != "MESH":
        raise HumanAnimError("select a mesh object to grasp")
    depsgraph = bpy.context.evaluated_depsgraph_get()
    ev = target.evaluated_get(depsgraph)
    mesh = ev.to_mesh()
    try:
        mesh.calc_loop_triangles()
        n = len(mesh.vertices)
        if n < 4 or len(mesh.loop_triangles) < 4:
            raise HumanAnimError(f"'{target.name}' has too few faces to grasp")
        co = np.empty(n * 3)
        mesh.vertices.foreach_get("co", co)
        tri = np.empty(len(mesh.loop_triangles) * 3, dtype=np.int32)
        mesh.loop_triangles.foreach_get("vertices", tri)
    finally:
        ev.to_mesh_clear()
    m = np.array(target.matrix_world)
    verts = co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]
    return fit_primitive(verts * scene.unit_settings.scale_length, tri.reshape(-1, 3))


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
    depsgraph = bpy.context.evaluated_depsgraph_get()
    ev = skin.evaluated_get(depsgraph)
    mesh = ev.to_mesh()
    try:
        n = len(mesh.vertices)
        co = np.empty(n * 3)
        mesh.vertices.foreach_get("co", co)
    finally:
        ev.to_mesh_clear()
    owner = np.full(n, -1)
    for v in skin.data.vertices:  # the strongest group of each vertex
        if v.groups:
            g = max(v.groups, key=lambda e: e.weight)
            j = index.get(g.group)
            owner[v.index] = -1 if j is None else j
    m = np.array(skin.matrix_world)
    verts = (co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]) * scene.unit_settings.scale_length
    from ..solver.hands.sensors import default_hand_sensors, sensors_from_mesh
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


# --- control rigs (a generated Rigify rig) ---------------------------------------------------
# Its DEF- bones copy ORG- bones that copy the FK or IK controls, an IK/FK switch property driving
# the constraints' influence: keys on the DEF- bones do nothing. The solver still works on the
# role bones; each bone it moves is mapped to the control that carries it rigidly (found by
# following the constraints upstream, checked by turning the control and watching the bone),
# and the solved poses are written to those controls through armature space.
_CON_PATH = re.compile(r'^pose\.bones\["((?:[^"\\]|\\.)*)"\]\.constraints\[')
_PROP_PATH = re.compile(r'^pose\.bones\["((?:[^"\\]|\\.)*)"\]\["((?:[^"\\]|\\.)*)"\]$')
_PROBE_ANGLE = 0.3  # radians the probe turns a candidate control


@dataclass
class ControlRig:
    frozen: tuple  # driven chain joints that are no role bone and no control: the solver keeps them
    controls: dict = field(default_factory=dict)  # joint -> (control bone, control rest in joint rest)
    switches: dict = field(default_factory=dict)  # (bone, property) -> value keyed so the controls drive
    fixed: dict = field(default_factory=dict)  # every switch value the mapping relied on
    stretched: tuple = ()  # connected arm and finger joints: the FK controls keep their lengths
    actual: np.ndarray = None  # the last pose given to `rigid`, as read

    def rigid(self, basis):
        """Local bases (..., J, 4, 4) without the stretch a constraint-driven pose can carry (Rigify's
        IK stretch): the FK controls rebuild connected bones at their rest lengths."""
        self.actual = np.array(basis, dtype=float)  # what Blender shows: the controls' parents are read from it
        basis = self.actual.copy()
        basis[..., list(self.stretched), :3, 3] = 0.0
        return basis

    def solver_skeleton(self, skeleton):
        """The skeleton the solver moves: frozen joints lose their DOFs."""
        if not self.frozen:
            return skeleton
        dof = skeleton.dof.copy()
        dof[list(self.frozen)] = False
        return replace(skeleton, dof=dof)


def _driven(pb):
    return any(not c.mute and c.influence > 0 for c in pb.constraints)


def _is_control(obj, name):
    """A bone the animator keys: no constraints, some free rotation, shown in a visible collection."""
    bone, pb = obj.data.bones[name], obj.pose.bones[name]
    if bone.hide or any(not c.mute for c in pb.constraints) or all(pb.lock_rotation):
        return False
    collections = list(getattr(bone, "collections", ()))
    return not collections or any(c.is_visible for c in collections)


def _followed(obj, pb):
    """The bones a pose bone's constraints take their targets from."""
    out = []
    for c in pb.constraints:
        if c.mute:
            continue
        pairs = [(getattr(c, "target", None), getattr(c, "subtarget", ""))]
        pairs += [(t.target, t.subtarget) for t in getattr(c, "targets", ())]  # Armature constraint
        out += [n for t, n in pairs if t == obj and n in obj.pose.bones]
    return out


def _upstream(obj, name, depth=8):
    """{bone: steps} of the bones `name` follows (constraint targets and parents, recursively)."""
    seen, queue = {name: 0}, [name]
    while queue:
        x = queue.pop(0)
        if seen[x] >= depth:
            continue
        pb = obj.pose.bones[x]
        for y in _followed(obj, pb) + ([pb.parent.name] if pb.parent else []):
            if y not in seen:
                seen[y] = seen[x] + 1
                queue.append(y)
    return seen


def _switch_drivers(obj):
    """(constrained bone, switch) pairs in the order of the object's drivers: the custom
    properties of pose bones that drive the influence of a bone's constraints (Rigify's IK_FK on
    the limb's parent bone)."""
    ad = obj.animation_data
    out = []
    for d in (ad.drivers if ad else ()):
        m = _CON_PATH.match(d.data_path)
        if not m:
            continue
        bone = bpy.utils.unescape_identifier(m.group(1))
        for v in d.driver.variables:
            if v.type != "SINGLE_PROP" or v.targets[0].id != obj:
                continue
            p = _PROP_PATH.match(v.targets[0].data_path or "")
            if not p:
                continue
            key = (bpy.utils.unescape_identifier(p.group(1)), bpy.utils.unescape_identifier(p.group(2)))
            if key[0] in obj.pose.bones and isinstance(obj.pose.bones[key[0]].get(key[1]), float):
                out.append((bone, key))
    return out


def _switches(drivers, bones):
    """The switches (from `_switch_drivers`) of the constraints of `bones`, each once."""
    return list(dict.fromkeys(key for bone, key in drivers if bone in bones))


def _rest_m(obj, name, scale):
    m = np.array(obj.data.bones[name].matrix_local, dtype=float)
    m[:3, :3] = rotations.to_matrix(rotations.from_matrix(m[:3, :3]))
    m[:3, 3] *= scale
    return m


def _same_rest(a, b, length):
    cos = (np.trace(a[:3, :3].T @ b[:3, :3]) - 1.0) / 2.0
    return np.arccos(np.clip(cos, -1.0, 1.0)) < np.radians(1.0) and np.linalg.norm(a[:3, 3] - b[:3, 3]) < 0.01 * length


def control_rig(obj, skeleton, sides=("L", "R"), with_spine=False):
    """None for a plain FK rig (no arm, spine or finger bone the solver moves follows a constraint);
    else the ControlRig whose joints still need their controls (`map_controls`)."""
    from ..solver.body_roles import FINGERS
    from ..solver.hands.ik import chain_joints
    joints = []
    for s in sides:
        if skeleton.role_index(sided("hand", s)) is None:
            continue
        joints += chain_joints(skeleton, s, with_spine)
        joints += [skeleton.index(n) for f in FINGERS for n in skeleton.roles.chain(sided(f, s))]
    pbs = obj.pose.bones
    if not any(_driven(pbs[skeleton.names[j]]) for j in joints):
        return None
    pelvis = skeleton.role_index("pelvis")
    body = set()  # the pelvis and what moves it (a control rig's torso): the reach never moves them
    if pelvis is not None:
        body = set(skeleton.ancestors(pelvis)) | {pelvis}
        body |= {skeleton.index(n) for n in _upstream(obj, skeleton.names[pelvis]) if skeleton.find(n) is not None}
    frozen = []
    for j in dict.fromkeys(joints):
        name = skeleton.names[j]
        role = skeleton.roles.role_of(name)
        if j in body or (role is None and not _is_control(obj, name)):
            frozen.append(j)  # the pelvis's ancestors, twist segments, ORG-/MCH- bones of the spine
    stretched = tuple(j for j in dict.fromkeys(joints) if skeleton.connected[j] and j not in body)
    return ControlRig(tuple(frozen), stretched=stretched)


def _carries(obj, bone, control):
    """True when turning `control` turns `bone` with it: the bone's head and tail stay put in the
    control's frame and the bone moves."""
    from mathutils import Matrix, Vector
    pbs, view_layer = obj.pose.bones, bpy.context.view_layer
    b, c = pbs[bone], pbs[control]

    def where():
        inv = np.linalg.inv(np.array(c.matrix))
        pts = np.array([tuple(b.head) + (1.0,), tuple(b.tail) + (1.0,)])
        return pts[:, :3], (pts @ inv.T)[:, :3]

    view_layer.update()
    p0, r0 = where()
    keep = c.matrix_basis.copy()
    c.matrix_basis = keep @ Matrix.Rotation(_PROBE_ANGLE, 4, Vector((1.0, 0.0, 0.6)).normalized())
    view_layer.update()
    p1, r1 = where()
    c.matrix_basis = keep
    length = obj.data.bones[bone].length
    return np.abs(r1 - r0).max() < 1e-3 * length and np.linalg.norm(p1 - p0, axis=1).max() > 0.02 * length


def map_controls(obj, skeleton, crig, joints):
    """Each of `joints` (parents first) gets the control carrying it: a control itself, else the
    nearest control upstream whose rest frame matches the bone's (not shorter: tweak controls
    sit on top of the chain) and that turns it, with the switch values that make it drive.
    Raises HumanAnimError for a driven joint no control carries."""
    pbs = obj.pose.bones
    scale = skeleton.unit_scale
    drivers = _switch_drivers(obj)
    saved = {k: pbs[k[0]][k[1]] for k in _switches(drivers, set(pbs.keys()))}
    missing = []
    try:
        for k, v in crig.fixed.items():
            pbs[k[0]][k[1]] = v
        for j in joints:
            if j in crig.controls or j in crig.frozen:
                continue
            name = skeleton.names[j]
            if _is_control(obj, name):
                crig.controls[j] = (name, np.eye(4))
                continue
            found = _find_control(obj, name, crig, scale, saved, drivers)
            if found is None:
                missing.append(name)
            else:
                crig.controls[j] = found
    finally:
        for (b, p), v in saved.items():
            pbs[b][p] = v
        bpy.context.view_layer.update()
    if missing:
        raise HumanAnimError(
            f"the bones {', '.join(missing[:4])}{' ...' if len(missing) > 4 else ''} follow other bones through "
            "constraints and no control of the rig turns them (a control rig whose controls can't be found): keys "
            "on them would be ignored; grasp with the metarig, or map the hand roles to the FK controls")


def _find_control(obj, name, crig, scale, current, drivers):
    import itertools
    pbs = obj.pose.bones
    up = _upstream(obj, name)
    rest = _rest_m(obj, name, scale)
    length = obj.data.bones[name].length
    candidates = sorted((d, i, c) for i, (c, d) in enumerate(up.items())
                        if d > 0 and _is_control(obj, c) and obj.data.bones[c].length >= 0.9 * length
                        and _same_rest(rest, _rest_m(obj, c, scale), length * scale))
    free = [k for k in _switches(drivers, set(up)) if k not in crig.fixed]
    # switch settings, the fewest changes first (the current one first): only what must change is keyed
    options = [tuple(dict.fromkeys((float(current[k]), 1.0, 0.0))) for k in free]
    combos = sorted(itertools.product(*options), key=lambda vs: sum(v != float(current[k]) for k, v in zip(free, vs)))
    for _, _, c in candidates:
        for values in combos:
            for k, v in zip(free, values):
                pbs[k[0]][k[1]] = v
            if _carries(obj, name, c):
                crig.fixed.update(zip(free, values))
                crig.switches.update((k, v) for k, v in zip(free, values) if v != float(current[k]))
                return c, np.linalg.solve(rest, _rest_m(obj, c, scale))
    return None


def control_targets(skeleton, crig, base, out):
    """Armature-space frames (metres) of every mapped control over the frames: where the solved
    pose puts the bone it carries, times the control's rest frame in the bone's. Also each
    known bone's old and new frames {bone: (old (F,4,4), new (F,4,4))}."""
    old, new = skeleton.world_frames(base), skeleton.world_frames(out)
    targets, known = {}, {}
    for j, (c, offset) in sorted(crig.controls.items()):
        targets[c] = new[:, j] @ offset
        known[c] = (old[:, skeleton.index(c)], targets[c])
        known[skeleton.names[j]] = (old[:, j], new[:, j])
    return targets, known, old


def control_bases(obj, skeleton, targets, known, old):
    """{control: (F, 4, 4) pose-bone basis (armature units)}: each control's parent is carried
    rigidly by its nearest ancestor whose new frame is known (checked afterwards by Blender's
    own evaluation, `correct_controls`)."""
    bases = {}
    for c in sorted(targets, key=skeleton.index):
        pb = obj.pose.bones[c]
        j = skeleton.index(c)
        if pb.parent is None:
            parent = np.eye(4)[None]
        else:
            p = skeleton.index(pb.parent.name)
            parent = old[:, p]
            x = pb.parent
            while x is not None:
                if x.name in known:
                    was, now = known[x.name]
                    parent = now @ np.linalg.solve(was, old[:, p])
                    break
                x = x.parent
        basis = np.linalg.solve(parent @ skeleton.rest_local[j], targets[c])
        basis[..., :3, 3] /= skeleton.unit_scale
        bases[c] = basis
    return bases


def control_errors(obj, scene, skeleton, frames, targets, sample):
    """Largest position (m) and angle (rad) between Blender's evaluated controls and their
    targets, on the frames at `sample` (indices)."""
    pos, ang = 0.0, 0.0
    keep = scene.frame_current
    for k in sample:
        scene.frame_set(int(frames[k]))
        for c, t in targets.items():
            m = np.array(obj.pose.bones[c].matrix, dtype=float)
            m[:3, :3] /= np.linalg.norm(m[:3, :3], axis=0)
            m[:3, 3] *= skeleton.unit_scale
            pos = max(pos, float(np.linalg.norm(m[:3, 3] - t[k, :3, 3])))
            cos = (np.trace(m[:3, :3].T @ t[k, :3, :3]) - 1.0) / 2.0
            ang = max(ang, float(np.arccos(np.clip(cos, -1.0, 1.0))))
    scene.frame_set(keep)
    return pos, ang


def correct_controls(obj, scene, skeleton, frames, targets, bases):
    """Blender's evaluation frame by frame: each control's basis from its evaluated parent, again
    until no control changes (a parent that follows constraints non-rigidly, e.g. a spine bone
    copying half of the chest)."""
    from mathutils import Matrix
    pbs = obj.pose.bones
    view_layer = bpy.context.view_layer
    keep = scene.frame_current
    order = sorted(targets, key=skeleton.index)
    rest_local = {c: skeleton.rest_local[skeleton.index(c)].copy() for c in order}
    for c in order:
        rest_local[c][:3, 3] /= skeleton.unit_scale
    for k, f in enumerate(frames):
        scene.frame_set(int(f))
        for _ in range(len(order) + 1):
            change = 0.0
            for c in order:
                pb = pbs[c]
                parent = np.array(pb.parent.matrix) if pb.parent else np.eye(4)
                t = targets[c][k].copy()
                t[:3, 3] /= skeleton.unit_scale
                b = np.linalg.solve(parent @ rest_local[c], t)
                b[:3, :3] /= np.linalg.norm(b[:3, :3], axis=0)
                change = max(change, float(np.abs(b - bases[c][k]).max()))
                bases[c][k] = b
                pb.matrix_basis = Matrix(b.tolist())
            if change < 1e-7:
                break
            view_layer.update()
    scene.frame_set(keep)
    return bases


def _new_action_keys(obj, source, name, copy_source):
    """A writer into a NEW action for the control rig: a copy of the source (so every other
    control keeps its keys), or a fresh one."""
    if source is not None and copy_source:
        action = source.copy()
        action.name = name
        return action_api.ChannelWriter(action, obj, existing=True)
    return action_api.ChannelWriter(bpy.data.actions.new(name), obj)


def write_controls(obj, scene, crig, frames, bases, name, keys=None):
    """Keys the controls' bases and the IK/FK switches (CONSTANT, the value before the range kept
    on the frame before) into a new action (`keys`, reused when correcting)."""
    output = getattr(getattr(scene, "humananim", None), "output", "ACTION")
    ad = obj.animation_data
    source = ad.action if ad else None
    first = keys is None
    if first:
        keys = _new_action_keys(obj, source, name, copy_source=output != "NLA")
    for c, b in bases.items():
        pb = obj.pose.bones[c]
        path = actions.bone_path(c)
        q = rotations.make_continuous(rotations.from_matrix(b[:, :3, :3]))
        prop, values = actions.rotation_channels(q, pb.rotation_mode)
        for i in range(values.shape[1]):
            keys.replace_keys(f"{path}.{prop}", i, c, frames, values[:, i])
        loc = b[:, :3, 3]
        keyed = keys.has(f"{path}.location", 0)  # the source's location keys are replaced too
        if not obj.data.bones[c].use_connect and (keyed or not np.allclose(loc, 0.0, atol=1e-7)):
            for i in range(3):
                keys.replace_keys(f"{path}.location", i, c, frames, loc[:, i])
    if first:
        for (bone, prop), value in crig.switches.items():
            path = f'{actions.bone_path(bone)}["{bpy.utils.escape_identifier(prop)}"]'
            before = _value_before(obj, source, path, frames[0] - 1, obj.pose.bones[bone][prop])
            fc = keys.replace_keys(path, 0, bone, frames, np.full(len(frames), float(value)), "CONSTANT")
            if abs(before - value) > 1e-9 and not any(abs(k.co[0] - (frames[0] - 1)) < 0.5 for k in fc.keyframe_points):
                kp = fc.keyframe_points.insert(float(frames[0] - 1), float(before), options={"FAST"})
                kp.interpolation = "CONSTANT"
                fc.update()
        if source is not None:
            source.use_fake_user = True
        if output == "NLA":
            action_api.push_to_nla(obj, keys.action, keys.slot, f"HumanAnim: {name}", frames[0])
        else:
            action_api.assign_action(obj, keys.action, keys.slot)
    return keys


def _value_before(obj, source, path, frame, current):
    for fc in (action_api.fcurves_of(source, obj) if source is not None else ()):
        if fc.data_path == path:
            return float(fc.evaluate(frame))
    return float(current)


def write_result(obj, scene, skeleton, crig, frames, base, out, name):
    """The new action: the role bones' keys on a plain rig; on a control rig, the controls'."""
    if crig is None:
        return _write(obj, scene, skeleton, frames, out, name)
    moved = [j for j in range(skeleton.joint_count)
             if j not in crig.frozen and np.abs(out[:, j] - base[:, j]).max() > 1e-9]
    map_controls(obj, skeleton, crig, moved)
    crig.controls = {j: v for j, v in crig.controls.items() if j in moved}
    actual = base if crig.actual is None else np.broadcast_to(crig.actual, base.shape)
    targets, known, old = control_targets(skeleton, crig, actual, out)
    bases = control_bases(obj, skeleton, targets, known, old)
    keys = write_controls(obj, scene, crig, frames, bases, name)
    sample = sorted({0, len(frames) // 2, len(frames) - 1})
    pos, ang = control_errors(obj, scene, skeleton, frames, targets, sample)
    if pos > 2e-4 or ang > 1e-3:  # a parent not carried rigidly: Blender's evaluation, frame by frame
        bases = correct_controls(obj, scene, skeleton, frames, targets, bases)
        write_controls(obj, scene, crig, frames, bases, name, keys)
    return keys.action
