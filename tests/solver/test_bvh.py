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
    np.testing.assert_allclose(b.root_positions, [(0, 0, 1), (1, -3, 3)])
    # BVH Z rotation (about the forward axis) is a rotation about Blender's -Y
    np.testing.assert_allclose(rotations.to_matrix(b.rotations[1, 0]),
                               rotations.to_matrix(rotations.axis_rotation(1, -np.pi / 2)), atol=1e-12)
    # channels listed outermost first: Zrotation 0, Xrotation 90 -> about BVH X = Blender X
    np.testing.assert_allclose(rotations.to_matrix(b.rotations[1, 1]),
                               rotations.to_matrix(rotations.axis_rotation(0, np.pi / 2)), atol=1e-12)
    pos = b.positions()
    np.testing.assert_allclose(pos[0, 2], (0.1, 0, 1))


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
