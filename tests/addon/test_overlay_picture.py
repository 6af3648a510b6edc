"""The dynamic-control still (overlay.render_picture): frame labels never overlap whatever the
character's travel, pushes get a snapshot of their own, loads, pushes and garments are drawn."""

import os

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from humananim.humananim_addon.motion_control import overlay  # noqa: E402
from humananim.humananim_addon.motion_control.job import OverlayData  # noqa: E402

SIZE = 0.1  # label text size (m)


def label_intervals(travel, texts, size=SIZE):
    shift = overlay.strip_shift(travel, [overlay.label_width(t, size) for t in texts])
    centres = np.asarray(travel, float) + shift
    widths = np.array([overlay.label_width(t, size) for t in texts])
    return sorted(zip(centres - widths / 2, centres + widths / 2)), centres


@pytest.mark.parametrize("travel", [
    [0.0, 0.05, 0.1, 0.12, 0.2],  # standing nearly still
    [0.0, 2.5, 5.0, 7.5, 10.0],  # walking steadily
    [0.0, 0.1, 0.3, 6.0, 12.0],  # standing, then walking away
    [0.0, 3.0, 1.0, 3.2, 0.5],  # back and forth
    [0.0, -2.0, -4.0, -6.0, -8.0],  # travelling against the picture's axis
])
def test_frame_labels_never_overlap(travel):
    texts = [f"frame {f}" for f in (1, 120, 240, 1200, 12000)]
    intervals, centres = label_intervals(travel, texts)
    for (_, right), (left, _) in zip(intervals, intervals[1:]):
        assert left > right, f"labels overlap for travel {travel}: {intervals}"
    assert np.min(np.diff(np.sort(centres))) >= overlay.SPACING - 1e-9  # the bodies stand apart too


def test_steady_travel_is_drawn_where_it_happened():
    assert not overlay.strip_shift([0.0, 2.5, 5.0, 7.5, 10.0], [0.5] * 5).any()


def synthetic(frames=60, travel=0.0):
    """A stick 'body' of two bones walking `travel` metres along x."""
    f = np.arange(1, frames + 1, dtype=float)
    x = np.linspace(0.0, travel, frames)
    pelvis = np.column_stack((x, np.zeros(frames), np.full(frames, 1.0)))
    bones = np.stack([np.stack((pelvis, pelvis + [0, 0, 0.6]), axis=1),  # trunk
                      np.stack((pelvis + [0.1, 0, 0.5], pelvis + [0.1, 0, 0.1]), axis=1)], axis=1)  # arm
    return OverlayData(frames=f, ghost=bones.copy(), bones=bones, control=np.zeros((frames, 2), np.int8),
                       stress=np.zeros((frames, 2)), zmp=np.column_stack((x, np.zeros(frames))),
                       polygons=[np.array([[x[i] - 0.1, -0.1], [x[i] + 0.1, -0.1], [x[i] + 0.1, 0.1]])
                                 for i in range(frames)],
                       ground=0.0, falling=np.zeros(frames, bool), forward=np.array([1.0, 0.0]))


def test_snapshot_frames_include_each_push():
    data = synthetic()
    frames = overlay.snapshot_frames(data, 5, include=[33.0])
    assert 33.0 in frames and frames[0] == 1.0 and frames[-1] == 60.0 and len(frames) == 5


def test_picture_draws_loads_pushes_and_garments(tmp_path, empty_scene):
    data = synthetic(travel=0.3)
    bpy.ops.mesh.primitive_cylinder_add(radius=0.25, depth=0.4, location=(0.0, 0.0, 1.0))
    skirt = bpy.context.active_object
    made = []
    real_tube, real_garments = overlay.tube_object, overlay._garments_drawn

    def tube(scene, name, segments, colour, radius):
        made.append((name, colour))
        return real_tube(scene, name, segments, colour, radius)

    def garments(scene, pairs, frame, offset):
        out = real_garments(scene, pairs, frame, offset)
        made.extend((o.name, tuple(o.color)) for o in out)
        return out

    overlay.tube_object, overlay._garments_drawn = tube, garments
    try:
        path = str(tmp_path / "still.png")
        push = overlay.Push(bone=0, frame=30.0, point=np.array([0.2, 0.0, 0.4]), direction=np.array([-1.0, 0, 0]),
                            text="15 N s")
        frames = overlay.render_picture(data, path, overlay.snapshot_frames(data, 4, include=[30.0]),
                                        resolution=(320, 140), loads=[overlay.Load(bone=1, kg=5.0, frame=20.0)],
                                        pushes=[push], garments=[(bpy.context.scene, skirt)])
    finally:
        overlay.tube_object, overlay._garments_drawn = real_tube, real_garments
    assert os.path.getsize(path) > 1000 and 30.0 in frames
    loads = [n for n, c in made if c == overlay.LOAD and n.startswith("weight")]
    assert len(loads) == sum(f >= 20.0 for f in frames)  # from the frame it is picked up
    assert [n for n, c in made if c == overlay.PUSH] == ["push0.30"]
    assert len([n for n, c in made if n.startswith("HumanAnim garment")]) == len(frames)
    assert "HumanAnim Picture" not in bpy.data.scenes  # the temporary scene is gone
