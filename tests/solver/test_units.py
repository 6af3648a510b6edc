import os

import pytest

from humananim.solver.units import bvh_rest_extent, guess_length_scale

CLIP = os.path.join(os.path.dirname(__file__), "..", "..", "humananim_addon", "data", "mocap", "cmu_131_01.bvh")


@pytest.mark.parametrize("height,scale,unit", [(1.75, 1.0, "m"), (172.0, 0.01, "cm"),
                                               (68.0, 0.0254, "in"), (1800.0, 0.001, "mm")])
def test_common_units_are_recognised(height, scale, unit):
    assert guess_length_scale(height) == (scale, unit)


def test_unknown_unit_is_scaled_to_a_human_height():
    scale, unit = guess_length_scale(31.0)  # e.g. a BVH in a unit of 0.0564 m
    assert 31.0 * scale == pytest.approx(1.7)
    assert "unknown" in unit


def test_cmu_clip_extent_is_in_metres():
    with open(CLIP) as f:
        extent = bvh_rest_extent(f.read())
    assert 1.2 < extent < 2.0  # joint centres: ankle to skull joint, not skin height
    assert guess_length_scale(extent)[1] == "m"


def test_centimetre_copy_is_recognised():
    with open(CLIP) as f:
        text = f.read().split("MOTION")[0]
    scaled = "\n".join(
        f"OFFSET {' '.join(str(100 * float(x)) for x in line.split()[1:])}" if line.strip().startswith("OFFSET")
        else line for line in text.splitlines())
    assert guess_length_scale(bvh_rest_extent(scaled + "MOTION\n"))[1] == "cm"
