"""Clean Up Capture's floor and its feet (solver/cleanup/feet.py), on hand-made feet and on
Bandai Namco clips (read in place, never copied): no point of a foot below the floor (its
ankle, a toe without a role, a toe-end bone), a contact judged by its height in the capture (a
ground's dip under it is not something else to stand on), and a held toe tip that does not
leave its contact hovering."""

import numpy as np
import pytest

from humananim.solver.cleanup import Options, clean_up, feet, ground
from test_cleanup_ground import WALK

CALL = WALK.parent / "dataset-1_call_normal_001.bvh"  # standing, both feet down the whole take
FEMININE = WALK.parent / "dataset-1_walk_feminine_002.bvh"  # its right toe tip went 0.9 mm under


def bandai(path):
    if not path.exists():
        pytest.skip(f"{path} is not there")
    from humananim.solver import bvh, units
    from humananim.solver.role_detection import detect_roles
    scale, _ = units.guess_length_scale(bvh.figure_height(bvh.read(path)))
    b = bvh.read(path, scale=scale)
    sk = bvh.skeleton(b, roles=detect_roles(b.names, b.parents, bvh.rest_heads(b), bvh.rest_tails(b)).roles)
    return sk, bvh.trajectories(b, sk)


def standing_foot(frames=60, height=0.01):
    """One foot standing still over frames 10..49 (its ball `height` above Z = 0), lifted 5 cm
    before and after: its foot points (F, 1, 3) and its contact (F, 1)."""
    p = np.zeros((frames, 1, 3))
    p[..., 2] = height
    on = np.zeros((frames, 1), bool)
    on[10:50] = True
    p[~on[:, 0], :, 2] += 0.05
    return p, on


def test_every_sole_point_kept_above_the_floor():
    """A point of the foot that is not a foot point (a toe-end bone 4 mm under the ball): the
    contact's lowest point is that one, put on the floor; without it, it would stay under."""
    p, on = standing_foot()
    sole = np.concatenate((p, p - [0.0, 0.0, 0.004]), axis=1)
    without = feet.foot_offsets({"L": p}, 30.0, floor=0.0, skate=False, planted={"L": on})["L"]
    assert (sole[..., 2] + without[:, 2:3]).min() == pytest.approx(-0.004)
    d = feet.foot_offsets({"L": p}, 30.0, floor=0.0, skate=False, planted={"L": on}, sole={"L": sole})["L"]
    lowest = (sole[..., 2] + d[:, 2:3]).min(axis=1)
    assert lowest.min() > -1e-9
    np.testing.assert_allclose(lowest[10:50], 0.0, atol=1e-9)  # on the floor, not above it


def test_a_contact_is_judged_by_its_height_in_the_capture():
    """2.5 cm above the capture's floor (a foot on the floor, a little high) but 3.9 cm above the
    ground under it once the body follows the ground: put on the ground. 5 cm above the
    capture's floor (on a step) but 2 cm above the ground: left where it is."""
    for captured, now, moved in ((0.025, 0.039, -0.039), (0.05, 0.02, 0.0)):
        p, on = standing_foot(height=now)
        seen = {"L": np.where(on[:, 0], captured, captured + 0.05)}
        d = feet.foot_offsets({"L": p}, 30.0, floor=0.0, skate=False, planted={"L": on}, captured=seen)["L"]
        np.testing.assert_allclose(d[10:50, 2], moved, atol=1e-9)


def test_a_toe_end_bone_is_kept_above_the_floor_by_the_toe_turn():
    """The toe's turn is cut back where a toe-end point past the tip would go under the floor."""
    F = 5
    head = np.zeros((F, 3))
    tips = np.array([[0.05, 0.0, 0.0], [0.07, 0.0, -0.001]])[None].repeat(F, axis=0)  # tip, toe end
    head[:, 2] = 0.02
    omega = np.zeros((F, 3))
    omega[:, 1] = np.radians(np.linspace(5, 40, F))  # about Y: turns +X down
    only_tip = feet._keep_tip_up(omega, tips[:, 0], head, 0.0)
    both = feet._keep_tip_up(omega, tips, head, 0.0)
    assert (np.linalg.norm(both, axis=1) <= np.linalg.norm(only_tip, axis=1) + 1e-12).all()
    for share, points in ((both, tips), (only_tip, tips[:, :1])):
        for f in range(F):
            turn = feet._axis_rotation(feet._unit(omega[f:f + 1]), np.linalg.norm(share[f:f + 1], axis=1))[0]
            assert (head[f, 2] + (points[f] @ turn.T)[:, 2]).min() >= -1e-4
    assert (np.linalg.norm(both, axis=1) < np.linalg.norm(only_tip, axis=1) - 1e-3).any()


def body_points(sk, tr):
    body = [sk.root] + sk.descendants(sk.root)
    w = tr.world_frames(sk)[:, body]
    return np.concatenate((w[..., :3, 3], w[..., :3, 3] + w[..., :3, 1] * sk.lengths[body][None, :, None]), axis=1)


def test_no_body_point_below_the_floor_after_floor_and_skate():
    """The benchmark's floor case on its worst clip: the root lifted 5 cm and drifting, cleaned
    on the clip's own floor; no point of the pelvis or a bone under it ends below the floor (the
    toe tip here is a point of the foot whatever role its toe was given)."""
    sk, tr = bandai(FEMININE)
    points = feet.foot_points(sk, tr.world_frames(sk))
    floor = feet.find_floor(points, feet.find_contacts(points, tr.fps))
    position, orientation = tr.root_pose(sk)
    moved = position + [0.0, 0.0, 0.05]
    moved[:, 0] += 0.05 * np.sin(2 * np.pi * 0.3 * tr.times)
    bad = tr.with_root_pose(sk, moved, orientation)
    assert body_points(sk, bad)[..., 2].min() - floor > 0.04
    out, report = clean_up(sk, bad, Options(glitches=False, jitter=False, ground=floor))
    assert body_points(sk, out)[..., 2].min() - floor > -1e-6
    assert report["repairs"][2]["lowest_foot_cm"] > -1e-4


@pytest.mark.parametrize("surface", ["flat", "bumps"])
def test_holding_the_toe_tip_does_not_leave_a_contact_hovering(surface):
    """Standing the whole take: the toe tip held where it landed keeps its pitch at landing, which
    would raise the foot 2 mm off the floor where the captured toe bent; the foot is lowered by
    as much, so each contact's lowest point stays on the ground after the skate repair."""
    sk, tr = bandai(CALL)
    x = np.arange(-6.0, 6.0, 0.05)
    xx, yy = np.meshgrid(x, x)
    field = ground.HeightField(0.015 * np.sin(2.0 * xx) * np.cos(1.5 * yy), (x[0], x[0]), 0.05)
    g = 0.0 if surface == "flat" else field
    out, report = clean_up(sk, tr, Options(glitches=False, jitter=False, ground=g))
    planted = feet.planted_points(feet.foot_points(sk, tr.world_frames(sk)), tr.fps)
    world = out.world_frames(sk)
    sole = feet.sole_points(sk, world)
    contacts = 0
    for side, p in feet.foot_points(sk, world).items():
        low = feet.lowest_above(p, sole[side], g)
        assert low.min() > -1e-4
        for a, b in feet.contact_runs(planted[side].any(axis=1)):
            assert low[a:b].min() == pytest.approx(0.0, abs=1e-4), (side, a, b)
            contacts += 1
    assert contacts >= 2 and report["repairs"][3]["pelvis_lowered_cm"] <= 100 * feet.MAX_PELVIS_DROP
