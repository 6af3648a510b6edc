"""Clean Up Capture on a given ground (solver/cleanup/ground.py): height fields and meshes
answer the height under points, and the floor repair puts the CMU walk's feet on a bumpy ground:
on it, neither sinking nor hovering, still held where they land."""

from pathlib import Path

import numpy as np
import pytest

from humananim.solver.cleanup import Options, clean_up, feet, ground
from test_cleanup import clip


def bumps(xy):
    return 0.2 + 0.015 * np.sin(2.0 * xy[..., 0]) * np.cos(1.5 * xy[..., 1])


def grid(lo=-6.0, hi=6.0, cell=0.05):
    x = np.arange(lo, hi + cell / 2, cell)
    xx, yy = np.meshgrid(x, x)
    return x, ground.HeightField(bumps(np.stack((xx, yy), axis=-1)), (lo, lo), cell)


def test_height_field_and_mesh_give_the_height_under_points(tmp_path):
    x, field = grid(-1.0, 1.0, 0.01)
    pts = np.random.default_rng(0).uniform(-0.9, 0.9, size=(50, 2))
    assert np.abs(field.height(pts) - bumps(pts)).max() < 1e-3
    assert np.isnan(field.height(np.array([[5.0, 0.0]])))[0]  # off the grid: no ground
    # the same surface as an OBJ written Y up (as Blender's exporter does), two triangles a cell
    xx, yy = np.meshgrid(x, x)
    v = np.stack((xx.ravel(), yy.ravel(), bumps(np.stack((xx, yy), -1)).ravel()), axis=1)
    n = len(x)
    lines = [f"v {a:.6f} {c:.6f} {-b:.6f}" for a, b, c in v]
    for j in range(n - 1):
        for i in range(n - 1):
            k = j * n + i + 1
            lines.append(f"f {k} {k + 1} {k + n + 1} {k + n}")
    path = tmp_path / "ground.obj"
    path.write_text("\n".join(lines))
    mesh = ground.load(path)
    assert np.abs(mesh.height(pts) - bumps(pts)).max() < 1e-3
    assert np.isnan(mesh.height(np.array([[5.0, 0.0]])))[0]
    np.savez(tmp_path / "field.npz", heights=field.heights, cell=0.01, origin=[-1.0, -1.0])
    assert np.abs(ground.load(tmp_path / "field.npz").height(pts) - bumps(pts)).max() < 1e-3


@pytest.mark.parametrize("bad", ["v 0 0 0\n", "nothing here\n"])
def test_a_broken_ground_file_is_refused(tmp_path, bad):
    path = tmp_path / "bad.obj"
    path.write_text(bad)
    with pytest.raises(ValueError):
        ground.load(path)
    with pytest.raises(ValueError):
        ground.load(tmp_path / "bad.png")


WALK = Path(__file__).resolve().parents[3] / "shared" / "data" / "mocap" / "bandai-namco-1" / "dataset-1_walk_normal_001.bvh"


def bandai_walk():
    """A Bandai Namco walk (read in place, never copied), as the benchmark reads it."""
    if not WALK.exists():
        pytest.skip(f"{WALK} is not there")
    from humananim.solver import bvh, units
    from humananim.solver.role_detection import detect_roles
    scale, _ = units.guess_length_scale(bvh.figure_height(bvh.read(WALK)))
    b = bvh.read(WALK, scale=scale)
    sk = bvh.skeleton(b, roles=detect_roles(b.names, b.parents, bvh.rest_heads(b), bvh.rest_tails(b)).roles)
    return sk, bvh.trajectories(b, sk)


@pytest.mark.parametrize("walk", ["bandai", "cmu"])
def test_feet_put_on_a_bumpy_ground(walk):
    sk, tr = bandai_walk() if walk == "bandai" else clip(2)
    _, field = grid()
    out, report = clean_up(sk, tr, Options(glitches=False, jitter=False, ground=field))
    flat_out, flat_report = clean_up(sk, tr, Options(glitches=False, jitter=False, ground=0.0))
    entry = report["repairs"][2]
    assert entry["ground"]["kind"] == "heightfield" and entry["ground_m"] is None
    assert entry["lowest_foot_cm"] > -0.1  # nothing through the ground
    planted = feet.planted_points(feet.foot_points(sk, tr.world_frames(sk)), tr.fps)
    heights = {s: feet.heights_above(p, field).min(axis=1) for s, p in feet.foot_points(sk, out.world_frames(sk)).items()}
    flat = {s: p[..., 2].min(axis=1) for s, p in feet.foot_points(sk, flat_out.world_frames(sk)).items()}
    assert min(h.min() for h in heights.values()) > -0.001
    contacts = 0
    for side, down in planted.items():
        for a, b in feet.contact_runs(down.any(axis=1)):
            # a contact the flat repair puts on a flat floor is on the bumps (CMU 131_01 has
            # contacts several cm above its floor: left where they are, on both grounds)
            if flat[side][a:b].min() < 0.002:
                assert heights[side][a:b].min() == pytest.approx(0.0, abs=0.002)
                contacts += 1
    assert contacts >= (10 if walk == "bandai" else 1)
    # CMU 131_01's toe tips would dip under the ground while planted: the foot is raised instead,
    # so they stay where they landed (feet.hold_feet)
    assert feet.planted_slide(sk, out, planted) < 0.002


STANDING = WALK.parent / "dataset-1_guide_active_001.bvh"


def test_a_standing_figure_on_bumps_is_not_taken_for_a_foot_placed_higher():
    """Standing in place, each foot over its own bump: every contact that the flat repair puts on
    a flat floor is put on the bumps (the feet's own level is measured on the capture's floor)."""
    global WALK
    if not STANDING.exists():
        pytest.skip(f"{STANDING} is not there")
    WALK, walk = STANDING, WALK
    try:
        sk, tr = bandai_walk()
    finally:
        WALK = walk
    _, field = grid()
    out, _ = clean_up(sk, tr, Options(glitches=False, jitter=False, ground=field))
    flat_out, _ = clean_up(sk, tr, Options(glitches=False, jitter=False, ground=0.0))
    planted = feet.planted_points(feet.foot_points(sk, tr.world_frames(sk)), tr.fps)
    heights = {s: feet.heights_above(p, field).min(axis=1) for s, p in feet.foot_points(sk, out.world_frames(sk)).items()}
    flat = {s: p[..., 2].min(axis=1) for s, p in feet.foot_points(sk, flat_out.world_frames(sk)).items()}
    on_floor = [(s, a, b) for s, down in planted.items() for a, b in feet.contact_runs(down.any(axis=1))
                if flat[s][a:b].min() < 0.002]
    assert len(on_floor) >= 4
    for side, a, b in on_floor:
        assert heights[side][a:b].min() == pytest.approx(0.0, abs=0.002), (side, a, b)


@pytest.mark.parametrize("frames", [1, 2, 3, 8])
def test_feet_of_a_clip_shorter_than_the_fade_are_put_on_the_floor(frames):
    """A clip shorter than the fade around a contact (9 frames at 30 fps), e.g. a few frames
    retargeted: every foot ends on the floor, none below it."""
    rng = np.random.default_rng(frames)
    points = {s: np.cumsum(rng.normal(0.0, 1e-4, (frames, 2, 3)), axis=0) + [0.0, 0.0, 0.02]
              for s in ("left", "right")}
    moves = feet.foot_offsets(points, 30.0, floor=0.0)
    for side, p in points.items():
        assert moves[side].shape == (frames, 7)
        lowest = (p[..., 2] + moves[side][:, None, 2]).min(axis=1)
        assert np.all(lowest >= -1e-9) and np.all(lowest <= 1e-3)
