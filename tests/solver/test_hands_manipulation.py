"""Object manipulation (sec. 4.4) and two characters (sec. 4.5): the arm follows a keyframed
hammer and racket keeping the grip (hand-to-object transform within 1 mm and 0.5 degrees on
every frame); one character holds the other's hand and keeps the hold while the other moves."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from hands_cases import SPOTS, frame, metarig
from humananim.solver.hands import grasp as G
from humananim.solver.hands import manipulation as M
from humananim.solver.hands.grasp import rigid_inv
from humananim.solver.hands.primitives import Box, Cylinder


@pytest.fixture(scope="module")
def rig():
    return metarig()


def keyframed(start, keys, frames):
    """Object frames interpolated between keys (position offset, rotation vector) like Blender's
    default Bezier keys: smoothstep in time between successive keys."""
    out = []
    n = len(keys) - 1
    for t in range(frames):
        u = t / (frames - 1) * n
        k = min(int(u), n - 1)
        x = u - k
        s = x * x * (3 - 2 * x)
        p = (1 - s) * np.asarray(keys[k][0]) + s * np.asarray(keys[k + 1][0])
        r = Rotation.from_rotvec(keys[k][1]) * Rotation.from_rotvec(
            s * (Rotation.from_rotvec(keys[k][1]).inv() * Rotation.from_rotvec(keys[k + 1][1])).as_rotvec())
        f = start.copy()
        f[:3, :3] = r.as_matrix() @ start[:3, :3]
        f[:3, 3] = start[:3, 3] + p
        out.append(f)
    return np.array(out)


# a hammer (handle held, head swung down twice) and a racket (a forehand swing)
HAMMER = [((0, 0, 0), (0, 0, 0)), ((0, 0.05, 0.12), (-0.6, 0, 0)), ((0, -0.03, -0.05), (0.35, 0, 0)),
          ((0, 0.05, 0.12), (-0.6, 0, 0)), ((0, -0.03, -0.05), (0.35, 0, 0))]
RACKET = [((0, 0, 0), (0, 0, 0)), ((-0.12, 0.1, 0.05), (0, 0, 0.6)), ((0.1, -0.12, 0.1), (0.2, 0, -0.7)),
          ((0.15, -0.05, 0.15), (0.3, 0.2, -0.9))]


@pytest.mark.parametrize("keys", [HAMMER, RACKET], ids=["hammer", "racket"])
def test_arm_follows_a_keyframed_tool(rig, keys):
    sk, basis, a2w = rig
    handle = Cylinder(frame(SPOTS[0]), 0.016, 0.14)
    g = G.grasp(sk, basis, a2w, handle, gtype="WRAP")
    h = g.hands[0]
    objects = keyframed(handle.frame, keys, 60)
    frames, report = M.follow(sk, np.repeat(g.basis[-1][None], len(objects), 0), a2w, objects, {h.side: h.grip})
    hand = sk.role_index(f"hand.{h.side}")
    for t in range(len(objects)):  # measured independently of the report
        rel = rigid_inv(sk.world_frames(frames[t], a2w)[hand]) @ objects[t]
        assert np.linalg.norm(rel[:3, 3] - h.grip[:3, 3]) < 0.001
        ang = np.linalg.norm(Rotation.from_matrix(rel[:3, :3] @ h.grip[:3, :3].T).as_rotvec())
        assert np.degrees(ang) < 0.5
    assert report.max_position_error < 0.001 and np.degrees(report.max_rotation_error) < 0.5
    # the arm really moved (the fingers keep the grasp's pose)
    assert np.ptp(frames[:, sk.role_index(f"forearm.{h.side}"), :3, :3], axis=0).max() > 0.1


def test_two_characters_hold_and_follow(rig):
    sk, basis, a2w = rig
    other_a2w = frame([-0.98, -0.37, 0.0], Rotation.from_rotvec([0, 0, np.pi]).as_matrix())
    ua = sk.role_index("upper_arm.R")
    other = []
    for t in range(40):  # the other character (active) raises and swings its right arm
        b = basis.copy()
        b[ua, :3, :3] = basis[ua, :3, :3] @ Rotation.from_rotvec(
            [0.3 * np.sin(np.pi * t / 39), 0, 0.15 * np.sin(2 * np.pi * t / 39)]).as_matrix()
        other.append(b)
    other = np.array(other)
    frames, g, report = M.hold(sk, basis, a2w, sk, other, other_a2w, "hand.R", side="R")
    assert g.gtype in ("WRAP", "PINCH") and g.hands[0].fingers_touching
    assert len(frames) == g.frame_count + len(other) - 1
    hand = sk.role_index("hand.R")
    target = sk.index("hand.R")
    grip = rigid_inv(g.world[hand]) @ sk.world_frames(other[0], other_a2w)[target]
    for t in range(len(other)):
        rel = rigid_inv(sk.world_frames(frames[g.frame_count - 1 + t], a2w)[hand]) \
            @ sk.world_frames(other[t], other_a2w)[target]
        assert np.linalg.norm(rel[:3, 3] - grip[:3, 3]) < 0.001
    assert report.max_position_error < 0.001


def test_bone_primitives(rig):
    sk, basis, a2w = rig
    w = sk.world_frames(basis, a2w)
    assert type(M.bone_primitive(sk, w, sk.role_index("forearm.R"))).__name__ == "Cylinder"
    assert type(M.bone_primitive(sk, w, sk.role_index("chest"))).__name__ == "Frustum"
    assert type(M.bone_primitive(sk, w, sk.role_index("head"))).__name__ == "Sphere"
    # the limb's cylinder contains its bone
    fa = sk.role_index("forearm.R")
    cyl = M.bone_primitive(sk, w, fa)
    mid = w[fa][:3, :3] @ [0, 0.5 * sk.lengths[fa], 0] + w[fa][:3, 3]
    assert cyl.distance(mid) < 0


def test_follow_rejects_mismatched_lengths(rig):
    sk, basis, a2w = rig
    from humananim.solver.errors import HumanAnimError
    with pytest.raises(HumanAnimError):
        M.follow(sk, np.repeat(basis[None], 3, 0), a2w, np.repeat(np.eye(4)[None], 4, 0), {"R": np.eye(4)})
