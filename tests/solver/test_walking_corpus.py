"""Walk Along Path on real skeletons and against real walks (issue 23): Bandai Namco's skeleton
(every bone along X in its rest pose, a root joint above the hips, six channels a joint) walks from
a standing frame of its clip; the cycle law holds at every speed; the pelvis sways as the corpus's
captured walks do at the same speed, measured by the same function (clip.measure_gait)."""

import glob
from dataclasses import replace

import numpy as np
import pytest

from humananim.solver.trajectories import Trajectories
from humananim.solver.walking import Path, clip, metrics, model, walk
from humananim.solver.walking.body import stands
from corpus_clips import CORPUS, load
from walking_cases import rig

FPS = 30.0
CORPUS_WALKS = ("walk_normal_001", "bow_active_001", "run_active_001")


def _walk(sk, speed=1.3, length=4.0, reference=None):
    return walk(sk, Path.from_points([[0, 0, 0], [length, 0, 0]]), speed=speed, fps=FPS, reference=reference)


def _knees_bend_forward(r):
    """Each knee lies ahead of its hip-ankle line along the walk (+X) whenever it bends."""
    w = metrics.world(r)
    sk = r.skeleton
    for s in "LR":
        h, k, a = (w[:, sk.role_index(f"{part}.{s}"), :3, 3] for part in ("thigh", "shin", "foot"))
        n = (a - h) / np.linalg.norm(a - h, axis=1)[:, None]
        off = (k - h) - np.einsum("fi,fi->f", k - h, n)[:, None] * n
        bent = np.linalg.norm(off, axis=1) > 0.02
        assert bent.any() and (off[bent, 0] > 0).all()


@pytest.mark.parametrize("name", CORPUS_WALKS)
def test_a_rig_whose_rest_pose_lies_along_x_walks_from_its_clip(name):
    sk, tr = load(name)
    assert not stands(sk)  # Bandai's rest pose: the legs along +X and -X
    with pytest.raises(Exception, match="does not stand"):
        _walk(sk)
    r = _walk(sk, reference=tr)
    assert r.reached.all() and metrics.foot_slip(r) < 0.002
    assert np.isfinite(r.trajectories.rotations).all()
    _knees_bend_forward(r)
    report = metrics.qa_report(r)
    for measure in ("slide", "penetration", "pop_velocity", "bone_length", "nonfinite"):
        assert report["measures"][measure]["passed"] is not False, (measure, report["measures"][measure])
    # the walk is written on the rig's own rest pose: its standing frames are the clip's standing pose
    hips = metrics.hip_centre(r)
    assert abs(hips[0, 2] - r.body.ht) < 0.1


def test_any_rest_pose_gives_the_same_walk():
    """The metarig laid on its back in the rest pose (every bone turned 90 deg about X), with a
    one-frame motion standing it up, walks exactly as the standing metarig does."""
    sk = rig("metarig")
    turn = np.eye(4)
    turn[1:3, 1:3] = [[0.0, -1.0], [1.0, 0.0]]
    lying = replace(sk, rest=turn @ sk.rest)
    assert not stands(lying)
    basis = np.broadcast_to(np.eye(4), (1, sk.joint_count, 4, 4)).copy()
    basis[0, sk.root] = np.linalg.inv(lying.rest[sk.root]) @ sk.rest[sk.root]
    rot = np.array([[np.r_[1.0, 0, 0, 0]] * sk.joint_count])
    from humananim.solver import rotations
    rot[0, sk.root] = rotations.from_matrix(basis[0, sk.root, :3, :3])
    standing = Trajectories(np.array([1.0]), FPS, rot, basis[..., :3, 3], np.eye(4))
    a, b = _walk(sk, length=3.0), _walk(lying, length=3.0, reference=standing)
    wa, wb = metrics.world(a), metrics.world(b)
    assert np.abs(wa[..., :3, 3] - wb[..., :3, 3]).max() < 1e-6


@pytest.mark.parametrize("name", ["cmu", "metarig", "bandai"])
def test_the_cycle_follows_eq_2_5_at_every_speed(name):
    sk, ref = load("walk_normal_001") if name == "bandai" else (rig(name), None)
    for v in (0.6, 1.0, 1.4, 1.8):
        r = _walk(sk, speed=v, length=9.0, reference=ref)
        ht = r.body.ht
        for c in metrics.cycles(r):  # each steady cycle against its own relative velocity
            assert abs(c["rlc"] / c["rlc_model"] - 1) < 0.05, (v, c)
        # and the cycles at the asked speed against eq. 2-5 at that speed, measured as a capture is
        g = clip.measure_gait(sk, r.trajectories, min_speed=0.9 * v)
        steady = [c["length_m"] for c in g["per_cycle"] if abs(c["speed_m_s"] / v - 1) < 0.05]
        assert steady, (name, v)
        law = model.relative_cycle_length(v / ht) * ht
        assert abs(np.mean(steady) / law - 1) < 0.05, (name, v, np.mean(steady), law)


def _corpus_cycles():
    cycles = []
    for f in sorted(glob.glob(str(CORPUS / "dataset-1_walk_*_00[12].bvh"))):
        sk, tr = clip.load_bvh(f)
        cycles += clip.measure_gait(sk, tr)["per_cycle"]
    return cycles


def test_the_captured_walks_are_measured():
    """The measure finds the cycles of a captured walk; eq. 2-5 holds for it within 10 % (5.6 %
    with the rig's own Ht)."""
    sk, tr = load("walk_normal_001")
    g = clip.measure_gait(sk, tr)
    assert g["cycles"] >= 6 and 1.1 < g["speed_m_s"] < 1.4
    ht = _walk(sk, reference=tr).body.ht
    law = model.relative_cycle_length(g["speed_m_s"] / ht) * ht
    assert abs(g["length_m"] / law - 1) < 0.1
    assert 0.03 < g["pelvis_lateral_m"] < 0.09 and 0.2 < g["double_support_share"] < 0.5


def test_the_pelvis_sways_as_the_captured_walks_do():
    """Pelvis sway within 25 % of the median of the corpus's walking cycles at the same speed
    (+-0.15 m/s), on Bandai Namco's skeleton, both measured by clip.measure_gait."""
    if not CORPUS.is_dir():
        pytest.skip(f"the Bandai Namco corpus is not at {CORPUS}")
    cycles = _corpus_cycles()
    sk, tr = load("walk_normal_001")
    for v in (0.7, 1.0, 1.3):
        near = [c["pelvis_lateral_m"] for c in cycles if abs(c["speed_m_s"] - v) < 0.15]
        assert len(near) >= 20
        r = _walk(sk, speed=v, length=8.0, reference=tr)
        g = clip.measure_gait(sk, r.trajectories, min_speed=0.8 * v)
        mine = [c["pelvis_lateral_m"] for c in g["per_cycle"] if abs(c["speed_m_s"] / v - 1) < 0.1]
        assert mine
        assert 0.75 < np.mean(mine) / np.median(near) < 1.25, (v, np.mean(mine), np.median(near))
