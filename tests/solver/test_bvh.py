"""The bpy-free BVH reader on CMU 131_01 and on a tiny hand-written file."""

from pathlib import Path

import numpy as np
import pytest

from humananim.solver import bvh, rotations

CMU = Path(__file__).resolve().parents[2] / "humananim_addon" / "data" / "mocap" / "cmu_131_01.bvh"

TINY = """HIERARCHY
ROOT Hips
{
  OFFSET 0 1 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT Spine
  {
    OFFSET 0 0.5 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 0 0.3 0
    }
  }
  JOINT Leg
  {
    OFFSET 0.1 0 0
    CHANNELS 3 Xrotation Yrotation Zrotation
    End Site
    {
      OFFSET 0 -0.9 0
    }
  }
}
MOTION
Frames: 2
Frame Time: 0.04
0 0 0 0 0 0 0 0 0 0 0 0
1 2 3 90 0 0 0 90 0 30 0 0
"""


def test_tiny_file_axes_and_channel_order():
    b = bvh.parse(TINY)
    assert b.names == ("Hips", "Spine", "Leg") and list(b.parents) == [-1, 0, 0]
    assert b.fps == pytest.approx(25.0) and b.frame_count == 2
    # Blender (x, y, z) = BVH (x, -z, y)
    np.testing.assert_allclose(b.offsets[1], (0, 0, 0.5))
    # position channels place the root where they say, its OFFSET aside (Blender's importer does so)
    np.testing.assert_allclose(b.root_positions, [(0, 0, 0), (1, -3, 2)])
    # BVH Z rotation (about the forward axis) is a rotation about Blender's -Y
    np.testing.assert_allclose(rotations.to_matrix(b.rotations[1, 0]),
                               rotations.to_matrix(rotations.axis_rotation(1, -np.pi / 2)), atol=1e-12)
    # channels listed outermost first: Zrotation 0, Xrotation 90 -> about BVH X = Blender X
    np.testing.assert_allclose(rotations.to_matrix(b.rotations[1, 1]),
                               rotations.to_matrix(rotations.axis_rotation(0, np.pi / 2)), atol=1e-12)
    pos = b.positions()
    np.testing.assert_allclose(pos[0, 2], (0.1, 0, 0))


@pytest.fixture(scope="module")
def cmu():
    if not CMU.exists():
        pytest.skip("CMU clip not available")
    return bvh.read(CMU)


def test_cmu_header(cmu):
    assert cmu.frame_count == 995
    assert cmu.fps == pytest.approx(120.0, rel=1e-4)
    assert len(cmu.names) == 31 and cmu.names[0] == "Hips"
    assert cmu.names[cmu.parents[cmu.names.index("LeftKnee")]] == "LeftHip"
    assert sum(len(c) for c in cmu.channels) == 96


def test_cmu_skeleton_reproduces_bvh_positions(cmu):
    """Blender-style rest frames and pose bases give back the BVH's own joint positions."""
    sk = bvh.skeleton(cmu)
    tr = bvh.trajectories(cmu, sk)
    heads = tr.world_frames(sk)[..., :3, 3]
    np.testing.assert_allclose(heads, cmu.positions(), atol=1e-9)
    # Z up: the head is above the feet, head joint 1.1-1.9 m above the toes
    top = heads[0, sk.index("Head"), 2] - heads[0, sk.index("LeftToe"), 2]
    assert 1.1 < top < 1.9
    assert sk.roles.missing() == []
    assert sk.total_mass == pytest.approx(70.0)


# --- any whitespace, line endings and channel layouts ------------------------------------------

def _same(a, b):
    assert a.names == b.names and list(a.parents) == list(b.parents)
    np.testing.assert_allclose(a.values, b.values)
    np.testing.assert_allclose(a.positions(), b.positions(), atol=1e-12)


@pytest.mark.parametrize("variant", [
    lambda t: t.replace(" ", "\t"),  # tabs between every word
    lambda t: t.replace("\n", "\r\n"),  # Windows
    lambda t: t.replace("\n", "\r"),  # old Mac
    lambda t: t.replace("\n", "  \n\n"),  # trailing blanks and empty lines
    lambda t: t.replace("Frames:", "FRAMES:").replace("MOTION", "motion").replace("End Site", "end site"),
    lambda t: t.split("Frame Time: 0.04\n")[0] + "Frame Time: 0.04\n" + " ".join(
        t.split("Frame Time: 0.04\n")[1].split()),  # every value on one line
    lambda t: t.replace("ROOT Hips", "ROOT Hips {").replace("ROOT Hips {\n{", "ROOT Hips {"),  # brace on the line
])
def test_any_whitespace_and_line_endings_read_the_same(variant):
    _same(bvh.parse(variant(TINY)), bvh.parse(TINY))


def test_joint_names_with_spaces_are_joined_as_blender_does():
    b = bvh.parse(TINY.replace("JOINT Spine", "JOINT Upper Spine"))
    assert b.names == ("Hips", "Upper_Spine", "Leg")


def test_position_channels_on_every_joint_place_it():
    six = TINY.replace("CHANNELS 3 Zrotation Xrotation Yrotation",
                       "CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation")
    six = six.replace("0 0 0 0 0 0 0 0 0 0 0 0\n", "0 0 0 0 0 0 0 0.5 0 0 0 0 0 0 0\n")
    six = six.replace("1 2 3 90 0 0 0 90 0 30 0 0\n", "1 2 3 90 0 0 0 0.7 0 0 90 0 30 0 0\n")
    b = bvh.parse(six)
    pos = b.positions()
    np.testing.assert_allclose(pos[0, 1], (0, 0, 0.5))  # the Spine's channels, not its OFFSET
    np.testing.assert_allclose(b.joint_offsets[1, 1], (0, 0, 0.7))
    sk = bvh.skeleton(b)
    heads = bvh.trajectories(b, sk).world_frames(sk)[..., :3, 3]
    np.testing.assert_allclose(heads, pos, atol=1e-9)


def test_the_canonical_text_reads_back_the_same():
    b = bvh.parse(TINY.replace(" ", "\t"))
    again = bvh.parse(bvh.write(b))
    _same(again, b)
    np.testing.assert_allclose(again.file_offsets, b.file_offsets)
    assert again.frame_time == b.frame_time


def test_figure_height_of_the_posed_figure():
    # hips 1 m up from frame 0's channels (0) ... the tiny figure stands from -0.9 (leg tip) to 0.8
    standing = TINY.replace("Frames: 2", "Frames: 1").replace("1 2 3 90 0 0 0 90 0 30 0 0\n", "")
    assert bvh.figure_height(bvh.parse(standing)) == pytest.approx(1.7)
    assert bvh.figure_height(bvh.parse(standing, scale=0.01)) == pytest.approx(1.7)  # in file units


# --- broken files: one clear message each --------------------------------------------------------

@pytest.mark.parametrize("text,match", [
    ("", "does not start with HIERARCHY"),
    ("garbage\x00\x01 ~~~", "does not start with HIERARCHY"),
    ("HIERARCHY\nROOT Hips\n{\n  OFFSET 0 1 0\n", "no MOTION section"),
    (TINY.replace("Frames: 2", "Frames: 3"), r"promises 3 frames of 12 values, the file holds 2 complete"),
    (TINY[:-10], r"promises 2 frames .* holds 1 complete"),
    (TINY.replace("1 2 3 90", "1 2 nan 90"), r"NaN or infinite .*frame 2, joint 'Hips'"),
    (TINY.replace("0 90 0 30", "0 90 1e400 30"), r"NaN or infinite .*frame 2, joint 'Spine'"),
    (TINY.replace("1 2 3 90", "1 2 x3 90"), r"frame 2: 'x3' is not a number"),
    (TINY.replace("OFFSET 0 0.5 0", "OFFSET 0 0.5"), r"line 8: OFFSET: expected 3 numbers"),
    (TINY.replace("OFFSET 0 0.5 0", "OFFSET 0 abc 0"), r"line 8: OFFSET: .* not 3 number"),
    (TINY.replace("OFFSET 0 0.5 0", "OFFSET 0 inf 0"), r"line 8: OFFSET: .* not finite"),
    (TINY.replace("CHANNELS 3 Zrotation", "CHANNELS 4 Zrotation"), r"line 9: expected 4 channels"),
    (TINY.replace("CHANNELS 3 Zrotation", "CHANNELS 3 Wrotation"), r"line 9: expected 3 channels"),
    (TINY.replace("Frame Time: 0.04", "Frame Time: 0"), "positive time"),
    (TINY.replace("Frames: 2", "Frames: -1"), "whole number of frames"),
    (TINY.replace("Frames: 2", "Frames: 0"), "whole number of frames"),
    (TINY.replace("Frame Time: 0.04", "Time: 0.04"), "expected 'Frames: N' and 'Frame Time: T'"),
    ("HIERARCHY\nMOTION\nFrames: 1\nFrame Time: 0.1\n\n", "no joints"),
    (TINY.replace("}\nMOTION", "MOTION"), "not closed"),
    (TINY.replace("MOTION", "}\n}\nMOTION"), "closes nothing"),
])
def test_broken_files_are_one_clear_error(text, match):
    from humananim.solver.errors import MotionError
    with pytest.raises(MotionError, match=match):
        bvh.parse(text)


def test_a_missing_file_is_a_motion_error(tmp_path):
    from humananim.solver.errors import MotionError
    with pytest.raises(MotionError, match="cannot read"):
        bvh.read(tmp_path / "nope.bvh")
