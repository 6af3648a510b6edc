"""Planted feet through a blend's transition (solver/sequence/planted_feet.py): a transition that
carries the body 12 cm sideways drags the planted feet; held, they stay where they landed, above
the floor, and the frames away from the transition are left as they were."""

import numpy as np

from humananim.solver.cleanup import feet
from humananim.solver.sequence import planted_feet
from test_cleanup import clip


def dragged(first, last, shift=0.12):
    """The CMU walk with its body carried `shift` m along X, eased in over frames first..last (as
    blending into a copy of itself placed beside it does), and the transition mask."""
    sk, tr = clip(2)
    position, orientation = tr.root_pose(sk)
    u = np.clip((np.arange(tr.frame_count) - first) / (last - first), 0.0, 1.0)
    position = position.copy()
    position[:, 0] += shift * u * u * (3.0 - 2.0 * u)
    return sk, tr, tr.with_root_pose(sk, position, orientation), (u > 0.0) & (u < 1.0)


def worst_slide(sk, traj, planted, transition):
    """The farthest a planted point gets from where it is at the transition's start (or where it
    lands, later) over the contacts that overlap the transition."""
    first = int(np.argmax(transition))
    points = feet.foot_points(sk, traj.world_frames(sk))
    worst = 0.0
    for side, down in planted.items():
        for i in range(down.shape[1]):
            for a, b in feet.contact_runs(down[:, i]):
                if transition[a:b].any():
                    p = points[side][max(a, first):b, i, :2]
                    worst = max(worst, float(np.linalg.norm(p - p[0], axis=1).max()))
    return worst


def test_planted_feet_are_held_through_a_transition():
    sk, tr, moved, transition = dragged(200, 260)
    planted = feet.planted_points(feet.foot_points(sk, moved.world_frames(sk)), moved.fps)
    before = worst_slide(sk, moved, planted, transition)
    held, report = planted_feet.hold_planted_feet(sk, moved, transition)
    after = worst_slide(sk, held, planted, transition)
    assert before > 0.03 and after < 0.1 * before and after < 0.005, (before, after)
    assert any(report["held"].values())
    # through the transition, on or above the floor the result's contacts stand on
    floor = report["floor_m"]
    low = min(p[transition, :, 2].min() for p in feet.foot_points(sk, held.world_frames(sk)).values())
    assert low > floor - 0.005
    # away from the transition and the contacts held through it, the motion is as it was
    held_frames = [f for runs in report["held"].values() for f in runs]
    first = min(f[0] for f in held_frames) - moved.frames[0]
    last = max(f[1] for f in held_frames) - moved.frames[0]
    ramp = int(round(feet.RAMP_SECONDS * moved.fps)) + 2
    away = np.ones(moved.frame_count, bool)
    away[int(first) - ramp:int(last) + ramp + 1] = False
    assert np.allclose(held.rotations[away], moved.rotations[away], atol=1e-9)
    assert np.isfinite(held.rotations).all() and np.isfinite(held.translations).all()


def test_nothing_changes_without_a_transition_or_feet():
    sk, tr, moved, transition = dragged(200, 260)
    same, report = planted_feet.hold_planted_feet(sk, moved, np.zeros(moved.frame_count, bool))
    assert same is moved and not any(report["held"].values())
