"""The anatomical converter's solve without a pass over world frames (issue 30): when no limb
needs IK (an MVN suit has a sensor on every segment), a sensor bone's local rotation comes from
its target and its parent's world rotation alone. It must give the pose the pass down the
hierarchy gives (the path IK still takes), with all 23 MVN segments and with some missing."""

import numpy as np
import pytest

from humananim.solver import rotations
from humananim.solver.anatomical_converter import AnatomicalConverter, root_of_rotation
from humananim.humananim_addon.devices import mvn
from test_capture_core import _cmu, _readings

PELVIS = ("mvn", mvn.channel(0, "Pelvis"))


def _suit(sk):
    """Every MVN segment on the CMU rig's bone of its role, as a session attaches them."""
    out = {}
    for segment, role in mvn.SEGMENT_ROLES.items():
        bone = sk.roles.bone(role)
        if bone is not None and bone not in out.values():
            out[("mvn", mvn.channel(0, segment))] = bone
    return out


@pytest.fixture(scope="module")
def suit():
    clip, sk, traj = _cmu()
    attach = _suit(sk)
    idx = {k: sk.index(b) for k, b in attach.items()}
    rng = np.random.default_rng(30)
    offsets = {k: rotations.to_matrix(rotations.normalize(rng.normal(size=4))) for k in attach}
    heads = {k: rng.normal(scale=0.03, size=3) for k in attach}
    heads[PELVIS] = np.zeros(3)
    origin = np.array([0.3, -0.1, 0.05])
    conv = AnatomicalConverter(sk, attach, root=PELVIS)
    rest_world = sk.world_frames(np.tile(np.eye(4), (sk.joint_count, 1, 1)))
    conv.calibrate(_readings(sk, rest_world, idx, offsets, heads, origin))
    poses = [sk.world_frames(traj.basis()[f]) for f in (0, 40, 200, 333)]
    return sk, conv, idx, [_readings(sk, w, idx, offsets, heads, origin) for w in poses], poses


def _both_paths(conv, readings, monkeypatch):
    """(solve's pose, the forward pass's pose, whether solve took the forward pass)."""
    calls = []
    forward = conv._by_forward_pass
    monkeypatch.setattr(conv, "_by_forward_pass", lambda *a: calls.append(1) or forward(*a))
    solved = conv.solve(readings)
    monkeypatch.undo()
    heard, rot, _ = conv._targets(readings)
    reference = conv._by_forward_pass(heard, rot, conv.bone_targets(readings), conv._chain_turns(heard, rot))
    return solved, reference, bool(calls)


def test_all_23_segments_give_the_forward_pass_pose_without_it(suit, monkeypatch):
    sk, conv, idx, readings, poses = suit
    assert len(idx) == 21 and not conv._limbs  # L3 and T12 have no body role: 21 of MVN's 23 segments
    for r, target in zip(readings, poses):
        solved, reference, used_forward = _both_paths(conv, r, monkeypatch)
        assert not used_forward
        assert np.abs(solved - reference).max() < 1e-9
        world = sk.world_frames(solved)  # and it is the performer's pose: every sensor bone where it was
        for j in idx.values():
            assert np.allclose(world[j, :3, :3], target[j, :3, :3], atol=1e-9)
        root = idx[PELVIS]
        assert np.allclose(world[root, :3, 3], target[root, :3, 3], atol=1e-9)


@pytest.mark.parametrize("missing", [("LeftHand", "RightHand", "Head"), ("RightForearm", "LeftLowerLeg"),
                                     ("T8", "LeftToe", "RightShoulder")])
def test_missing_segments_give_the_forward_pass_pose_without_it(suit, monkeypatch, missing):
    """Silent segments that are no chain's sensor bone above it (a hand, a shin, the chest...):
    the same pose as the pass down the hierarchy, still without it."""
    sk, conv, idx, readings, _ = suit
    for r in readings:
        r = {k: v for k, v in r.items() if k[1].split("/")[1] not in missing}
        solved, reference, used_forward = _both_paths(conv, r, monkeypatch)
        assert not used_forward
        assert np.abs(solved - reference).max() < 1e-9


@pytest.mark.parametrize("missing", [("Pelvis",), ("L5", "Neck")])
def test_a_silent_segment_above_a_chain_takes_the_forward_pass(suit, monkeypatch, missing):
    """The pelvis, L5 and the neck are the sensor bones above the hips', the chest's and the
    head's chains: the chains' turns need where a first pass puts a silent one, so the pass down
    the hierarchy solves that pose."""
    sk, conv, idx, readings, _ = suit
    r = {k: v for k, v in readings[1].items() if k[1].split("/")[1] not in missing}
    solved, reference, used_forward = _both_paths(conv, r, monkeypatch)
    assert used_forward and np.abs(solved - reference).max() < 1e-9


def _about(axes, angles):
    return rotations.to_matrix(rotations.from_axis_angle(np.column_stack((angles, axes))))


def test_a_chain_share_is_the_turn_about_its_axis_by_a_fraction_of_its_angle():
    """root_of_rotation against rotations built from axis and angle, from no turn to a half turn
    (small and near-half turns each checked on their own), and the n-th power of the root is the turn."""
    rng = np.random.default_rng(30)
    axes = rng.normal(size=(40, 3))
    axes /= np.linalg.norm(axes, axis=1)[:, None]
    angles = np.concatenate((rng.uniform(0, np.pi, 30), [0.0, 1e-9, 1e-4, np.radians(153.9), np.radians(154.2),
                                                          np.pi - 1e-4, np.pi - 1e-9, np.pi, np.pi, np.pi]))
    n = rng.integers(2, 5, 40)
    turn = _about(axes, angles)
    for below in (angles < np.radians(154), angles >= np.radians(154)):  # small and near-half turns apart
        root = root_of_rotation(turn[below], n[below])
        power = root.copy()
        for k in range(len(root)):
            for _ in range(n[below][k] - 1):
                power[k] = power[k] @ root[k]
        assert np.abs(power - turn[below]).max() < 1e-9
        exact = angles[below] < np.pi - 1e-6  # at a half turn either axis' root is a root
        expected = _about(axes[below][exact], (angles / n)[below][exact])
        assert np.abs(root[exact] - expected).max() < 1e-9
