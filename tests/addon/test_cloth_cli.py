"""`python -m humananim cloth ...` in fresh processes: a skirt on the CMU walk, a .blend and PC2s."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from conftest import CMU_CLIPS

pytest.importorskip("bpy")
pytestmark = pytest.mark.slow


def run(*args):
    return subprocess.run([sys.executable, "-m", "humananim", *args], capture_output=True, text=True, timeout=600)


def test_cloth_command_writes_a_blend_and_point_caches(tmp_path):
    from humananim.solver.cloth import read_pc2
    out = tmp_path / "skirt.blend"
    r = run("cloth", CMU_CLIPS[0], "--skirt", "--capsule-body", "--frames", "1", "61", "--keep-coarse",
            "--preset", "denim", "--out", str(out), "--json")
    assert r.returncode == 0, r.stderr
    s = json.loads(r.stdout)
    cache = tmp_path / "skirt_cache"
    assert s["command"] == "cloth" and s["wrote"] == [str(out), str(cache / "Skirt.cloth.pc2"),
                                                      str(cache / "Skirt.cloth_coarse.pc2")]
    assert out.exists() and not (tmp_path / "skirt.blend1").exists()
    assert s["particles"] == 66 and s["fine_faces"] == 110 * 16 and s["frames"] == 16 and s["frame_step"] == 4
    assert s["colliders"] == ["MeshBody"] and s["body"] == "Body" and s["preset"] == "denim"
    assert s["max_depth_inside_mm"] < 2.0 and s["max_mean_stretch"] < 0.02
    for key in ("integration_ms", "collision_ms", "smoothing_ms", "total_ms"):
        assert s["timing_ms_per_frame"][key] > 0.0
    fine, start, rate = read_pc2(cache / "Skirt.cloth.pc2")
    assert fine.shape == (61, s["fine_vertices"], 3) and (start, rate) == (1.0, 1.0) and np.isfinite(fine).all()
    # the saved file holds the new object, reading the cache by a path relative to the .blend
    probe = ("import bpy, sys; bpy.ops.wm.open_mainfile(filepath=sys.argv[1]); o = bpy.data.objects['Skirt.cloth'];"
             " m = o.modifiers[0]; print(m.type, m.cache_format, m.filepath, bpy.path.abspath(m.filepath))")
    p = subprocess.run([sys.executable, "-c", probe, str(out)], capture_output=True, text=True, timeout=120)
    kind, fmt, path, absolute = p.stdout.split()[-4:]
    assert (kind, fmt) == ("MESH_CACHE", "PC2") and path.startswith("//")
    assert os.path.samefile(absolute, cache / "Skirt.cloth.pc2")


def test_cloth_command_text_summary_and_pn_only(tmp_path):
    r = run("cloth", CMU_CLIPS[1], "--skirt", "--frames", "1", "21", "--pn-only", "--level", "3",
            "--out", str(tmp_path / "c.blend"))
    assert r.returncode == 0, r.stderr
    assert "cloth: 'Skirt' on" in r.stdout and "ms/frame" in r.stdout and "110 * 36" not in r.stdout
    assert "-> 3960 faces" in r.stdout  # 110 faces x 4 x 3^2


@pytest.mark.parametrize("args,needle", [
    ((), "no garment"),
    (("--skirt", "--body", "Nothing"), "no mesh object named"),
    (("--garment", "Nope"), "no mesh object named"),
    (("--skirt", "--wind", "1,2"), "X,Y,Z"),
    (("--skirt", "--level", "0"), "at least 1"),
])
def test_cloth_command_mistakes_are_one_line(tmp_path, args, needle):
    r = run("cloth", CMU_CLIPS[0], "--frames", "1", "9", "--out", str(tmp_path / "x.blend"), *args)
    assert r.returncode == 2 and needle in r.stderr and "Traceback" not in r.stderr


NO_LEGS = """HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT Spine
  {
    OFFSET 0 10 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    JOINT Head
    {
      OFFSET 0 50 0
      CHANNELS 3 Zrotation Xrotation Yrotation
      End Site
      {
        OFFSET 0 20 0
      }
    }
  }
}
MOTION
Frames: 3
Frame Time: 0.0333333
0 90 0 0 0 0 0 0 0 0 0 0
0 90 1 0 0 0 0 0 0 0 0 0
0 90 2 0 0 0 0 0 0 0 0 0
"""


def test_cloth_on_a_rig_without_legs_exits_2_and_writes_nothing(tmp_path):
    clip = tmp_path / "no_legs.bvh"
    clip.write_text(NO_LEGS)
    out = tmp_path / "out" / "x.blend"
    r = run("cloth", str(clip), "--skirt", "--out", str(out))
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert "thigh" in r.stderr.strip().splitlines()[-1]  # (Blender's importer chatters before it)
    assert not out.exists() and not [p for p in (tmp_path / "out").glob("*") if p.suffix.startswith(".blend")]


def test_cloth_on_an_absurdly_scaled_figure_is_a_clear_error(tmp_path):
    out = tmp_path / "big.blend"
    r = run("cloth", CMU_CLIPS[0], "--skirt", "--scale", "100", "--frames", "1", "9", "--out", str(out))  # (metres)
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
    assert "m tall" in r.stderr and not out.exists()


def test_cloth_from_a_later_frame_fits_the_skirt_at_that_pose(tmp_path):
    """The walk has moved on by frame 241: the skirt is made at that frame's pose, neither inside
    the body nor left behind where the character stood at frame 1."""
    from humananim.solver.cloth import read_pc2
    out = tmp_path / "late.blend"
    r = run("cloth", CMU_CLIPS[0], "--skirt", "--capsule-body", "--frames", "241", "301", "--out", str(out), "--json")
    assert r.returncode == 0, r.stderr
    s = json.loads(r.stdout)
    assert s["frame_range"] == [241, 301] and s["max_depth_inside_mm"] < 2.0 and s["max_mean_stretch"] < 0.02
    fine, start, _ = read_pc2(tmp_path / "late_cache" / "Skirt.cloth.pc2")
    assert start == 241.0
    probe = ("import bpy, sys, numpy as np; bpy.ops.wm.open_mainfile(filepath=sys.argv[1]); s = bpy.context.scene;"
             " s.frame_set(241); a = [o for o in bpy.data.objects if o.type == 'ARMATURE'][0];"
             " print(*np.array(a.matrix_world @ a.pose.bones[0].head))")
    p = subprocess.run([sys.executable, "-c", probe, str(out)], capture_output=True, text=True, timeout=120)
    hips = np.array([float(t) for t in p.stdout.split()[-3:]])
    centre = fine[0].mean(axis=0)
    assert np.linalg.norm((centre - hips)[:2]) < 0.15  # metres: around the hips, not where they were
