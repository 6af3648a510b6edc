import os

import pytest

from humananim.solver.errors import MotionError
from humananim.solver.units import bvh_rest_extent, guess_length_scale

CLIP = os.path.join(os.path.dirname(__file__), "..", "..", "humananim_addon", "data", "mocap", "cmu_131_01.bvh")


@pytest.mark.parametrize("height,scale,unit", [(1.75, 1.0, "m"), (172.0, 0.01, "cm"),
                                               (68.0, 0.0254, "in"), (1800.0, 0.001, "mm")])
def test_common_units_are_recognised(height, scale, unit):
    assert guess_length_scale(height) == (scale, unit)


@pytest.mark.parametrize("height", [31.0, 0.5, 176.0 * 100, 3.0])
def test_a_figure_no_unit_makes_human_is_refused_with_its_height_and_the_scale(height):
    with pytest.raises(MotionError) as error:
        guess_length_scale(height)  # e.g. a BVH in a unit of 0.0564 m, or a 3 m giant
    message = str(error.value)
    assert f"{height:.4g} file units tall" in message and "1-2.3 m" in message
    assert f"--scale {1.7 / height:.4g}" in message


@pytest.mark.parametrize("height", [0.0, float("nan"), float("inf"), -1.0])
def test_no_height_is_refused(height):
    with pytest.raises(MotionError, match="no height"):
        guess_length_scale(height)


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
    assert guess_length_scale(bvh_rest_extent(scaled + "\nMOTION\n"))[1] == "cm"


def _centimetre_tab_copy(text):
    """The clip in cm, its OFFSETs and motion separated by tabs, with Windows line endings."""
    head, motion = text.split("MOTION")
    lines = []
    for line in head.splitlines():
        words = line.split()
        if words and words[0] == "OFFSET":
            line = "\t".join(["\tOFFSET"] + [str(100 * float(x)) for x in words[1:]])
        lines.append(line)
    return "\r\n".join(lines) + "\r\nMOTION" + motion.replace(" ", "\t").replace("\n", "\r\n")


def test_tab_separated_offsets_in_cm_are_read_as_cm():
    with open(CLIP) as f:
        text = f.read()
    metres = bvh_rest_extent(text)
    tabbed = _centimetre_tab_copy(text)
    assert "\tOFFSET\t" in tabbed
    # the root moves by its channels (still in metres here): joint offsets are what scale the figure
    assert guess_length_scale(bvh_rest_extent(tabbed))[1] == "cm"
    assert bvh_rest_extent(tabbed) == pytest.approx(100 * metres, rel=0.02)
