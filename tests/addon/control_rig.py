"""A procedural control rig that follows no known naming convention, for the rig-layer tests.

`build_control_rig()` makes, in the current scene, an armature 'Puppet' of a 1.8 m figure facing -Y:
- controls (shown, no deform): `anim_root`; `anim_torso` (moves the hips, the spine and the
  legs' IK chains); FK spine `anim_spine`, `anim_chest`, `anim_neck`, `anim_head`; FK arms `anim_collar_S`,
  `anim_upperarm_S`, `anim_forearm_S`, `anim_hand_S`; IK legs with foot targets `anim_foot_S` and
  knee poles `anim_knee_S` (children of the root); FK toes `anim_toe_S` under the IK feet;
- mechanism (hidden collection): `helper_hips` (the hips' frame, on the torso), the IK leg
  chains `helper_thigh_S` -> `helper_shin_S` (IK to the foot control, pole the knee),
  `helper_foot_S` (copies the foot control's rotation), a flat `helper_bind_root` the deform legs hang from, and `helper_socket_S`
  (on the collar control) the deform arms hang from;
- deform bones (hidden, what a mesh follows): `bind_hips` (Copy Transforms of helper_hips) ->
  `bind_spine` -> `bind_chest` -> `bind_neck` -> `bind_head` (Copy Rotation of the FK spine
  controls), `bind_collar_S` under the chest, `bind_upperarm_S` under the socket, then
  `bind_forearm_S` and `bind_hand_S` (Copy Rotation of the FK arm controls), and legs
  `bind_thigh_S` (under helper_bind_root) -> `bind_shin_S` -> `bind_foot_S` (Copy Transforms of
  the IK chain) -> `bind_toe_S` (Copy Rotation of the toe control).
S is `l` or `r` (no `.L`/`_L` convention). So the deform legs and arms don't hang from the hips.
"""

import bpy
import numpy as np

# (name, head, tail, parent, connected) of the deform skeleton, left side mirrored for the right
_SPINE = [
    ("hips", (0, 0, 1.00), (0, 0, 1.12), None, False),
    ("spine", (0, 0, 1.12), (0, 0, 1.30), "hips", True),
    ("chest", (0, 0, 1.30), (0, 0, 1.48), "spine", True),
    ("neck", (0, 0, 1.48), (0, 0, 1.58), "chest", True),
    ("head", (0, 0, 1.58), (0, 0, 1.80), "neck", True),
]
_LEG = [  # x > 0 is the character's left
    ("thigh", (0.10, 0, 0.98), (0.10, -0.01, 0.54), None, False),
    ("shin", (0.10, -0.01, 0.54), (0.10, 0.02, 0.10), "thigh", True),
    ("foot", (0.10, 0.02, 0.10), (0.10, -0.10, 0.03), "shin", True),
    ("toe", (0.10, -0.10, 0.03), (0.10, -0.17, 0.03), "foot", True),
]
_ARM = [
    ("collar", (0.03, 0, 1.45), (0.18, 0.02, 1.45), None, False),
    ("upperarm", (0.18, 0.02, 1.45), (0.46, 0.04, 1.45), "collar", True),
    ("forearm", (0.46, 0.04, 1.45), (0.72, 0.02, 1.45), "upperarm", True),
    ("hand", (0.72, 0.02, 1.45), (0.82, 0.02, 1.45), "forearm", True),
]


def _mirror(p, side):
    return (p[0] if side == "l" else -p[0], p[1], p[2])


def _bone(eb, name, head, tail, parent=None, connected=False, roll=0.0):
    b = eb.new(name)
    b.head, b.tail, b.roll = head, tail, roll
    if parent is not None:
        b.parent = eb[parent]
        b.use_connect = connected
    return b


def _new_armature(name):
    """An empty armature object, linked, active, in Edit mode: (object, armature, edit bones)."""
    arm = bpy.data.armatures.new(name)
    obj = bpy.data.objects.new(name, arm)
    bpy.context.scene.collection.objects.link(obj)
    bpy.context.view_layer.objects.active = obj
    bpy.ops.object.mode_set(mode="EDIT")
    return obj, arm, arm.edit_bones


def build_control_rig(name="Puppet"):
    """The armature object (see the module docstring), active, in Object mode."""
    obj, arm, eb = _new_armature(name)
    _bone(eb, "anim_root", (0, 0, 0), (0, 0.4, 0))
    _bone(eb, "anim_torso", (0, 0, 1.0), (0, 0.3, 1.0), "anim_root")
    _bone(eb, "helper_bind_root", (0, 0, 0), (0, 0, 0.2))
    _bone(eb, "helper_hips", (0, 0, 1.00), (0, 0, 1.12), "anim_torso")  # the hips' frame on the torso
    for n, h, t, p, c in _SPINE:
        _bone(eb, "bind_" + n, h, t, p and "bind_" + p, c)
        if n != "hips":
            parent = {"spine": "anim_torso", "chest": "anim_spine", "neck": "anim_chest", "head": "anim_neck"}[n]
            _bone(eb, "anim_" + n, h, t, parent)
    for s in ("l", "r"):
        for n, h, t, p, c in _LEG:
            h, t = _mirror(h, s), _mirror(t, s)
            parent = f"bind_{p}_{s}" if p else "helper_bind_root"
            _bone(eb, f"bind_{n}_{s}", h, t, parent, c)
            if n in ("thigh", "shin", "foot"):
                _bone(eb, f"helper_{n}_{s}", h, t, f"helper_{p}_{s}" if p else "anim_torso", c)
            if n == "foot":
                _bone(eb, f"anim_foot_{s}", h, t, "anim_root")
            if n == "toe":
                _bone(eb, f"anim_toe_{s}", h, t, f"anim_foot_{s}")
        knee = _mirror((0.10, -0.6, 0.54), s)
        _bone(eb, f"anim_knee_{s}", knee, (knee[0], knee[1] - 0.1, knee[2]), "anim_root")
        for n, h, t, p, c in _ARM:
            h, t = _mirror(h, s), _mirror(t, s)
            if n == "collar":
                _bone(eb, f"bind_collar_{s}", h, t, "bind_chest")
                _bone(eb, f"anim_collar_{s}", h, t, "anim_chest")
            elif n == "upperarm":
                _bone(eb, f"helper_socket_{s}", h, _mirror((0.18, 0.02, 1.35), s), f"anim_collar_{s}")
                _bone(eb, f"bind_upperarm_{s}", h, t, f"helper_socket_{s}")
                _bone(eb, f"anim_upperarm_{s}", h, t, f"anim_collar_{s}")
            else:
                _bone(eb, f"bind_{n}_{s}", h, t, f"bind_{p}_{s}", c)
                _bone(eb, f"anim_{n}_{s}", h, t, f"anim_{p}_{s}", c)
    bpy.ops.object.mode_set(mode="OBJECT")

    controls, mechanism, deform = (arm.collections.new(n) for n in ("Controls", "Mechanism", "Deform"))
    mechanism.is_visible = deform.is_visible = False
    for b in arm.bones:
        b.use_deform = b.name.startswith("bind_")
        {"anim": controls, "helper": mechanism, "bind": deform}[b.name.split("_")[0]].assign(b)

    pbs = obj.pose.bones

    def con(bone, kind, target, **kw):
        c = pbs[bone].constraints.new(kind)
        c.target, c.subtarget = obj, target
        for k, v in kw.items():
            setattr(c, k, v)
        return c

    con("bind_hips", "COPY_TRANSFORMS", "helper_hips")
    for n in ("spine", "chest", "neck", "head"):
        con("bind_" + n, "COPY_ROTATION", "anim_" + n)
    for s in ("l", "r"):
        con(f"helper_shin_{s}", "IK", f"anim_foot_{s}", chain_count=2, pole_target=obj,
            pole_subtarget=f"anim_knee_{s}", pole_angle=-1.5708)
        con(f"helper_foot_{s}", "COPY_ROTATION", f"anim_foot_{s}")
        for n in ("thigh", "shin", "foot"):
            con(f"bind_{n}_{s}", "COPY_TRANSFORMS", f"helper_{n}_{s}")
        con(f"bind_toe_{s}", "COPY_ROTATION", f"anim_toe_{s}")
        for n in ("collar", "upperarm", "forearm", "hand"):
            con(f"bind_{n}_{s}", "COPY_ROTATION", f"anim_{n}_{s}")
    for pb in pbs:
        pb.rotation_mode = "XYZ"
    return obj


def key_squat(obj, depth=0.3, frames=(1, 20, 40)):
    """A squat keyed on the controls only: the torso goes `depth` metres down (and 5 cm back) and
    up again, the chest leans forward, the IK feet stay planted."""
    pbs = obj.pose.bones
    torso, chest = pbs["anim_torso"], pbs["anim_chest"]
    for f, w in zip(frames, (0.0, 1.0, 0.0)):
        torso.matrix = _translated(torso, (0.0, 0.05 * w, -depth * w))  # armature axes, not the bone's
        torso.keyframe_insert("location", frame=f)
        chest.rotation_euler = (0.25 * w, 0.0, 0.0)
        chest.keyframe_insert("rotation_euler", frame=f)
        bpy.context.view_layer.update()


def _translated(pb, offset):
    from mathutils import Matrix, Vector
    rest = pb.bone.matrix_local
    return Matrix.Translation(Vector(offset)) @ rest


# --- a Mixamo-style rig through Blender's own FBX exporter --------------------------------------
_MIXAMO_TRUNK = [
    ("Hips", (0, 0, 1.00), (0, 0, 1.10), None), ("Spine", (0, 0, 1.10), (0, 0, 1.22), "Hips"),
    ("Spine1", (0, 0, 1.22), (0, 0, 1.34), "Spine"), ("Spine2", (0, 0, 1.34), (0, 0, 1.48), "Spine1"),
    ("Neck", (0, 0, 1.48), (0, 0, 1.58), "Spine2"), ("Head", (0, 0, 1.58), (0, 0, 1.80), "Neck"),
]
_MIXAMO_LIMBS = [
    ("UpLeg", (0.10, 0, 0.98), (0.10, -0.01, 0.54), "Hips"),
    ("Leg", (0.10, -0.01, 0.54), (0.10, 0.02, 0.10), "UpLeg"),
    ("Foot", (0.10, 0.02, 0.10), (0.10, -0.10, 0.03), "Leg"),
    ("ToeBase", (0.10, -0.10, 0.03), (0.10, -0.17, 0.03), "Foot"),
    ("Shoulder", (0.03, 0, 1.45), (0.18, 0.02, 1.45), "Spine2"),
    ("Arm", (0.18, 0.02, 1.45), (0.46, 0.04, 1.45), "Shoulder"),
    ("ForeArm", (0.46, 0.04, 1.45), (0.72, 0.02, 1.45), "Arm"),
    ("Hand", (0.72, 0.02, 1.45), (0.80, 0.02, 1.45), "ForeArm"),
]


def build_mixamo_style(name="Mixamo", fingers=True):
    """A plain FK armature named like a Mixamo download (mixamorig:Hips, mixamorig:LeftUpLeg, ...),
    with a 24-frame motion keyed on its bones (hips bob, legs and arms swing)."""
    obj, arm, eb = _new_armature(name)
    p = "mixamorig:"
    for n, h, t, parent in _MIXAMO_TRUNK:
        _bone(eb, p + n, h, t, parent and p + parent, parent is not None and n != "Hips")
    for side, s in (("Left", "l"), ("Right", "r")):
        for n, h, t, parent in _MIXAMO_LIMBS:
            par = p + (parent if parent in ("Hips", "Spine2") else side + parent)
            _bone(eb, p + side + n, _mirror(h, s), _mirror(t, s), par, parent not in ("Hips", "Spine2"))
        if fingers:
            for k, finger in enumerate(("Thumb", "Index", "Middle", "Ring", "Pinky")):
                y = 0.03 - 0.015 * k
                prev = p + side + "Hand"
                for seg in range(1, 4):
                    x0 = 0.80 + 0.025 * (seg - 1)
                    b = _bone(eb, f"{p}{side}Hand{finger}{seg}", _mirror((x0, y, 1.45), s),
                              _mirror((x0 + 0.025, y, 1.45), s), prev, seg > 1)
                    prev = b.name
    bpy.ops.object.mode_set(mode="OBJECT")
    pbs = obj.pose.bones
    for pb in pbs:
        pb.rotation_mode = "XYZ"
    for f in range(1, 25, 4):
        w = np.sin(2 * np.pi * (f - 1) / 24)
        pbs[p + "Hips"].location = (0.0, 0.0, 0.03 * w)
        pbs[p + "Hips"].keyframe_insert("location", frame=f)
        for side, sign in (("Left", 1.0), ("Right", -1.0)):
            for bone, angle in (("UpLeg", 0.4), ("Leg", 0.3), ("Arm", 0.3), ("ForeArm", 0.2)):
                pbs[p + side + bone].rotation_euler = (sign * angle * w, 0.0, 0.0)
                pbs[p + side + bone].keyframe_insert("rotation_euler", frame=f)
    bpy.context.scene.frame_start, bpy.context.scene.frame_end = 1, 24
    return obj


def export_fbx(obj, path):
    """`obj` and its action to `path` with Blender's own FBX exporter (leaf bones added, as Mixamo's)."""
    bpy.ops.object.select_all(action="DESELECT")
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj
    bpy.ops.export_scene.fbx(filepath=str(path), use_selection=True, object_types={"ARMATURE"},
                             bake_anim=True, bake_anim_use_all_actions=False, bake_anim_use_nla_strips=False,
                             add_leaf_bones=True)  # the scene take: NLA-strip takes export nothing without strips
    return str(path)


# --- a plain FK copy of a rig's physical skeleton (what the rig's results are compared with) -----
def plain_fk_copy(obj, scene, action=None, name="PlainCopy"):
    """An armature of only the deform bones of `obj`, each hung from its body parent (the
    physical skeleton) at the same rest, keyed with the motion `action` (the active one by
    default) shows on `obj`; all of its bones are deform and control. Returns the new object."""
    from mathutils import Matrix
    from humananim.humananim_addon import actions
    from humananim.humananim_addon.armature import skeleton_from_armature
    from humananim.humananim_addon.rig.physical import physical_skeleton, physical_trajectories
    physical = physical_skeleton(obj, scene)
    traj = physical_trajectories(obj, scene, physical, action)
    copy, _, eb = _new_armature(name)
    copy.matrix_world = obj.matrix_world
    for j, bone in enumerate(physical.names):
        rest = np.array(obj.data.bones[bone].matrix_local)
        b = eb.new(bone)
        b.head, b.tail = (0.0, 0.0, 0.0), (0.0, obj.data.bones[bone].length, 0.0)
        b.matrix = Matrix(rest.tolist())
        if physical.parents[j] >= 0:
            b.parent = eb[physical.names[physical.parents[j]]]
            b.use_connect = bool(physical.connected[j])
    bpy.ops.object.mode_set(mode="OBJECT")
    for pb in copy.pose.bones:
        pb.rotation_mode = obj.pose.bones[pb.name].rotation_mode
    skeleton = skeleton_from_armature(copy, scene)
    assert skeleton.names == physical.names or set(skeleton.names) == set(physical.names)
    order = [physical.index(n) for n in skeleton.names]
    from humananim.solver.trajectories import Trajectories
    moved = Trajectories(traj.frames, traj.fps, traj.rotations[:, order], traj.translations[:, order],
                         traj.armature_to_world)
    actions.write_action(copy, skeleton, moved, f"{name}Action")
    return copy


def squat_rigify(rig, depth=0.3):
    """A squat keyed on a generated Rigify rig's torso and (planted) IK foot controls, legs in IK,
    on a new action (the Rigify counterpart of `key_squat`, shared by the Rigify tests)."""
    pbs = rig.pose.bones
    for s in "LR":
        pbs[f"thigh_parent.{s}"]["IK_FK"] = 0.0
    rig.animation_data.action = None
    for pb in pbs:
        pb.matrix_basis.identity()
    for f, w in ((1, 0.0), (15, 1.0), (30, 0.0)):
        pbs["torso"].location = (0.0, 0.0, 0.0)
        bpy.context.view_layer.update()
        # torso moves in armature space: down and a little back
        m = pbs["torso"].matrix.copy()
        m.translation.z -= depth * w
        m.translation.y += 0.05 * w
        pbs["torso"].matrix = m
        pbs["torso"].keyframe_insert("location", frame=f)
        for s in "LR":
            pbs[f"foot_ik.{s}"].keyframe_insert("location", frame=f)
        pbs["chest"].rotation_mode = "XYZ"
        pbs["chest"].rotation_euler = (0.3 * w, 0.0, 0.0)
        pbs["chest"].keyframe_insert("rotation_euler", frame=f)
    return rig.animation_data.action
