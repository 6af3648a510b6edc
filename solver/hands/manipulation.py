"""Object manipulation and two-character interaction (Huang 1996 sec. 4.4 and 4.5).

Manipulation: once grasped, the object moves actively (keyframes or any animation) and the arm
follows it passively: on every frame the hand's goal is the object's frame composed with the grip
(the object in the hand's frame at the end of the grasp), solved by IK warm-started from the
previous frame, with the self-collision response in the null space.

Two characters: one reaches and holds the other's hand, arm or shoulder (the bone is bounded by a
cylinder for a limb, a frustum for the thorax, a sphere for the head, then grasped as an object);
then one is active (its own animation) and the other follows by IK to keep the hold: the held
bone's frame plays the object's part.
"""

from dataclasses import dataclass

import numpy as np

from ..body_roles import sided
from ..errors import HumanAnimError
from . import ik
from .body import body_sensors, body_volumes, shoulder_width
from .grasp import grasp, rigid_inv
from .primitives import Cylinder, Frustum, Sphere
from .self_collision import correct_frame


@dataclass
class FollowReport:
    max_position_error: float  # metres, hand-to-object transform vs the grip
    max_rotation_error: float  # radians
    frames: int


def follow(skeleton, frames, armature_to_world, object_frames, grips, avoid_body=True, max_steps=60):
    """The arm(s) follow a moving object. `frames` (F, J, 4, 4) is the motion to correct (the
    grasp's last pose repeated, or the character's own animation); `object_frames` (F, 4, 4)
    world; `grips` {side: object frame in the hand bone's frame}. Returns (frames, report)."""
    frames = np.array(frames, float)
    object_frames = np.asarray(object_frames, float)
    if len(frames) != len(object_frames):
        raise HumanAnimError("the object's frames and the character's frames differ in number")
    rest_world = skeleton.world_frames(frames[0], armature_to_world)
    volumes = [v for v in body_volumes(skeleton, rest_world) if v.name in ("trunk", "head")] if avoid_body else []
    sensors = body_sensors(skeleton, rest_world)
    chains = {s: ik.Chain.arm(skeleton, s) for s in grips}
    out = frames.copy()
    perr = rerr = 0.0
    for t in range(len(frames)):
        cur = frames[t].copy()
        for s, grip in grips.items():
            hand = skeleton.role_index(sided("hand", s))
            goal = object_frames[t] @ rigid_inv(np.asarray(grip, float))
            if t > 0:  # warm start: the previous frame's arm
                cur = chains[s].apply(chains[s].angles(out[t - 1]), cur)
            cur, _, _, _ = correct_frame(skeleton, cur, armature_to_world, s, goal[:3, 3], goal[:3, :3], volumes,
                                         max_steps=max_steps, sensors=sensors)
            w = skeleton.world_frames(cur, armature_to_world)
            rel = rigid_inv(w[hand]) @ object_frames[t]
            perr = max(perr, float(np.linalg.norm(rel[:3, 3] - grip[:3, 3])))
            rerr = max(rerr, float(np.linalg.norm(ik.rot_log(rel[:3, :3] @ np.asarray(grip)[:3, :3].T))))
        out[t] = cur
    return out, FollowReport(perr, rerr, len(frames))


def bone_primitive(skeleton, world, joint):
    """The bounding volume of a body part: a cylinder on a limb or hand bone, a frustum on the
    thorax, a sphere on the head (sec. 4.5)."""
    w = shoulder_width(skeleton, world)
    f = world[joint]
    length = skeleton.lengths[joint]
    role = skeleton.roles.role_of(skeleton.names[joint]) or ""
    frame = np.eye(4)
    # local Z of the primitive along the bone (its Y), centred mid-bone
    frame[:3, :3] = f[:3, :3] @ np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])
    frame[:3, 3] = f[:3, :3] @ [0, 0.5 * length, 0] + f[:3, 3]
    if role == "head":
        return Sphere(frame[:3, 3], 0.27 * w)
    if role in ("chest", "spine", "pelvis"):
        return Frustum(frame, 0.3 * w, 0.38 * w, 0.5 * length)
    radius = {"upper_arm": 0.12, "forearm": 0.09, "hand": 0.07, "clavicle": 0.12}.get(role.split(".")[0], 0.1) * w
    return Cylinder(frame, radius, 0.5 * length)


def hold(holder, holder_basis, holder_a2w, other, other_frames, other_a2w, bone, side="AUTO", reach_frames=24,
         close_frames=12, fps=24.0):
    """Step 1: the holder reaches and grasps the other character's bone at the other's first
    frame. Step 2: the other moves (its frames, active), the holder follows by IK keeping the
    hold. Returns (holder frames: the grasp then the follow, grasp result, follow report)."""
    j = other.index(bone) if isinstance(bone, str) else int(bone)
    other_world = [other.world_frames(b, other_a2w) for b in other_frames]
    shape = bone_primitive(other, other_world[0], j)
    g = grasp(holder, holder_basis, holder_a2w, shape, side=side, reach_frames=reach_frames,
              close_frames=close_frames, fps=fps, two_hands=False)
    h = g.hands[0]
    hand = holder.role_index(sided("hand", h.side))
    # the grip on the bone itself (the primitive is fixed to it)
    grip = rigid_inv(g.world[hand]) @ other_world[0][j]
    follow_frames = np.repeat(g.basis[-1][None], len(other_frames), axis=0)
    bone_frames = np.array([w[j] for w in other_world])
    out, report = follow(holder, follow_frames, holder_a2w, bone_frames, {h.side: grip})
    return np.concatenate((g.basis, out[1:])), g, report
