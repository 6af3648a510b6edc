"""The motion QA on hand-made motions whose slide, penetration, pops, lengths and NaN are known."""

import numpy as np
import pytest

from humananim.solver import qa, rotations
from humananim.solver.body_roles import RoleMap

NAMES = ("Hips", "LeftFoot", "LeftToe")
PARENTS = np.array([-1, 0, 1])
FEET = {"L": [1, 2]}
HEADS = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 0.1], [0.1, 0.0, 0.03]])
TAILS = np.array([[0.0, 0.0, 1.7], [0.1, 0.0, 0.03], [0.15, 0.0, 0.0]])


def figure(frames=30, fps=30.0, shift=None):
    """A standing leg; `shift` (F, 3) moves the whole figure per frame."""
    shift = np.zeros((frames, 3)) if shift is None else shift
    heads = HEADS[None] + shift[:, None]
    tails = TAILS[None] + shift[:, None]
    rot = np.zeros((frames, 3, 4))
    rot[..., 0] = 1.0
    return qa.Motion(heads, rot, NAMES, fps, PARENTS, tails)


def sliding(mm_per_frame, frames=30):
    return figure(frames, shift=np.outer(np.arange(frames), [mm_per_frame / 1000, 0.0, 0.0]))


def turning(step_deg, snap_at=None, snap_deg=0.0, frames=30):
    """The foot turning about X at a constant step, with an extra jump arriving at index snap_at."""
    angles = np.radians(step_deg * np.arange(frames) + (snap_deg * (np.arange(frames) >= snap_at)
                                                         if snap_at is not None else 0.0))
    m = figure(frames)
    m.rotations[:, 1] = rotations.axis_rotation(0, angles)
    return m


def test_a_sliding_planted_foot_is_measured_exactly():
    report = qa.measure(sliding(1.0), figure(), FEET, ground=0.0)
    slide = report["measures"]["slide"]
    assert slide["value"] == pytest.approx(29.0)
    assert (slide["bone"], slide["frames"], slide["foot"]) == ("LeftFoot", [1.0, 30.0], "L")
    assert slide["per_foot"] == {"L": pytest.approx(29.0)}
    assert slide["passed"] is False and report["passed"] is False
    assert any("'LeftFoot' at frames 1-30" in w and "29 mm" in w for w in report["warnings"])


def test_a_fast_slide_on_the_inputs_contacts_is_measured():
    # 20 mm a frame is too fast to be found as a contact on the result alone: the input's
    # contact (the foot standing still) is where it is measured
    slide = qa.measure(sliding(20.0), figure(), FEET, ground=0.0)["measures"]["slide"]
    assert slide["value"] == pytest.approx(580.0) and slide["passed"] is False
    retimed = qa.measure(sliding(20.0), figure(), FEET, ground=0.0, aligned=False)["measures"]["slide"]
    assert retimed["value"] == 0.0


def test_slide_limit_allows_the_inputs_own_skating():
    report = qa.measure(sliding(1.0), sliding(1.0), FEET, ground=0.0)
    assert report["measures"]["slide"]["input"] == pytest.approx(29.0)
    assert report["measures"]["slide"]["limit"] == pytest.approx(34.0)
    assert report["measures"]["slide"]["passed"] is True


def test_a_slow_foot_passes_and_a_swinging_foot_is_not_planted():
    assert qa.measure(sliding(0.5), None, FEET, ground=0.0)["measures"]["slide"]["value"] == pytest.approx(14.5)
    assert qa.measure(sliding(0.5), None, FEET, ground=0.0)["measures"]["slide"]["passed"] is True
    # 20 mm a frame is 0.6 m/s: moving, not planted
    assert qa.measure(sliding(20.0), None, FEET, ground=0.0)["measures"]["slide"]["value"] == 0.0


def test_contacts_are_separate_runs():
    shift = np.zeros((40, 3))
    shift[:10, 0] = 0.001 * np.arange(10)  # 9 mm in the first contact
    shift[10:15, 2] = 0.2  # lifted
    shift[10:12, 0] = 0.009
    shift[12:, 0] = 0.5  # moved in the air, put down, then 3 mm
    shift[15:, 0] += 0.001 * np.minimum(np.arange(25), 3)
    slide = qa.measure(figure(40, shift=shift), None, FEET, ground=0.0)["measures"]["slide"]
    assert slide["value"] == pytest.approx(9.0)
    assert slide["frames"] == [1.0, 10.0]


def test_a_toe_dip_below_the_ground_is_measured_in_cm_and_frames():
    m = figure()
    m.tails[9:12, 2, 2] = [-0.01, -0.03, -0.01]  # toe tip at frames 10-12
    report = qa.measure(m, figure(), FEET, ground=0.0)
    pen = report["measures"]["penetration"]
    assert pen["value"] == pytest.approx(3.0)
    assert (pen["bone"], pen["frames"], pen["frames_below"]) == ("LeftToe", [11.0], 3)
    assert pen["first_frames_below"] == [10.0, 11.0, 12.0]
    assert pen["passed"] is False
    assert any("below the ground" in w and "'LeftToe' at frame 11" in w for w in report["warnings"])


def test_the_floor_is_robust_to_a_few_dips_and_sinking_is_measured_against_the_input():
    src = figure()
    src.tails[9, 2, 2] = -0.06  # one dip of the input does not lower the floor
    assert qa.estimate_floor(src, FEET) == pytest.approx(0.0)
    sunk = figure(shift=np.tile([0.0, 0.0, -0.05], (30, 1)))
    pen = qa.measure(sunk, src, FEET)["measures"]["penetration"]
    # frame 10 may be as deep as the input's dip (6 cm + 1 cm), the others 2 cm
    assert pen["value"] == pytest.approx(5.0) and pen["limit"] == pytest.approx(2.0)
    assert pen["frames_below"] == 30 and pen["passed"] is False
    assert pen["frames"] == [1.0] and pen["input"] == pytest.approx(0.0)
    dipped = figure()
    dipped.tails[9, 2, 2] = -0.065
    pen = qa.measure(dipped, src, FEET)["measures"]["penetration"]
    assert pen["passed"] is True and pen["value"] == pytest.approx(6.5) and pen["limit"] == pytest.approx(7.0)


def test_a_snap_is_a_pop_in_velocity_and_acceleration():
    report = qa.measure(turning(2.0, snap_at=15, snap_deg=20.0), turning(2.0), FEET, ground=0.0)
    vel, acc = report["measures"]["pop_velocity"], report["measures"]["pop_acceleration"]
    # allowed: 1.25 x the input's own + 5 deg per frame (at 30 fps)
    assert vel["value"] == pytest.approx(22.0) and vel["input"] == pytest.approx(2.0)
    assert vel["limit"] == pytest.approx(7.5)
    assert (vel["bone"], vel["frames"], vel["passed"]) == ("LeftFoot", [16.0], False)
    assert acc["value"] == pytest.approx(20.0) and acc["input"] == pytest.approx(0.0, abs=1e-9)
    assert acc["limit"] == pytest.approx(5.0) and acc["passed"] is False
    assert acc["bone"] == "LeftFoot" and acc["frames"] in ([15.0], [16.0])  # the step in, or out
    assert any("pops" in w and "'LeftFoot' at frame 16" in w for w in report["warnings"])


def test_a_retimed_motion_a_little_faster_is_no_pop():
    report = qa.measure(turning(12.0), turning(10.0), FEET, ground=0.0)
    assert report["measures"]["pop_velocity"]["passed"] is True  # 12 <= 1.25 x 10 + 5


def test_motion_as_fast_as_the_input_is_no_pop():
    report = qa.measure(turning(10.0), turning(10.0), FEET, ground=0.0)
    assert report["measures"]["pop_velocity"]["value"] == pytest.approx(10.0)
    assert report["measures"]["pop_velocity"]["passed"] is True


def test_pop_limits_follow_the_frame_rate():
    assert qa.thresholds.per_frame(30.0)["pop_velocity_margin_deg"] == pytest.approx(5.0)
    assert qa.thresholds.per_frame(60.0)["pop_velocity_margin_deg"] == pytest.approx(2.5)
    assert qa.thresholds.per_frame(30.0)["pop_acceleration_margin_deg"] == pytest.approx(5.0)
    # without an input the absolute caps hold: 12 deg steps at 30 fps are within 30 deg per frame
    vel = qa.measure(turning(12.0), None, FEET, ground=0.0)["measures"]["pop_velocity"]
    assert vel["value"] == pytest.approx(12.0) and vel["limit"] == pytest.approx(30.0) and vel["passed"]


def test_the_rotation_between_frames_takes_the_short_way():
    q = rotations.axis_rotation(2, np.radians([179.0, -179.0]))[:, None]  # 2 degrees apart
    vel, _ = qa.angular_rates(np.concatenate((q, -q[1:]))[:2])
    assert vel[0, 0] == pytest.approx(2.0)


def test_nan_frames_are_named_and_the_rest_is_measured():
    m = sliding(1.0)
    m.heads[5, 0] = np.nan
    report = qa.measure(m, figure(), FEET, ground=0.0)
    assert report["measures"]["nonfinite"]["value"] == 1
    assert report["measures"]["nonfinite"]["frames"] == [6.0]
    assert report["measures"]["slide"]["value"] == pytest.approx(29.0)
    assert any("NaN" in w and "frame 6" in w for w in report["warnings"])


def test_a_stretched_bone_is_measured():
    m = figure()
    m.heads[7, 2] = m.heads[7, 1] + 1.02 * (m.heads[7, 2] - m.heads[7, 1])  # the toe 2 % further
    bl = qa.measure(m, figure(), FEET, ground=0.0)["measures"]["bone_length"]
    assert bl["value"] == pytest.approx(2.0) and bl["bone"] == "LeftToe" and bl["frames"] == [8.0]
    assert bl["passed"] is False


def test_figure_height_and_source_checksum():
    ok = qa.measure(figure(), None, FEET, ground=0.0, rest_height=1.75)
    assert ok["measures"]["figure_height"]["passed"] and ok["passed"]
    assert qa.measure(figure(), None, FEET, ground=0.0)["measures"]["figure_height"]["value"] == pytest.approx(1.7)
    giant = qa.measure(figure(), None, FEET, ground=0.0, rest_height=176.0)
    assert giant["measures"]["figure_height"]["passed"] is False
    keys = np.arange(12.0)
    same = qa.checksum(keys)
    assert qa.checksum(keys.copy()) == same and qa.checksum(keys + 1e-9) != same
    touched = qa.measure(figure(), None, FEET, ground=0.0, source_checksums=(same, qa.checksum(keys + 1)))
    assert touched["measures"]["source_untouched"]["passed"] is False
    assert "the source motion changed" in touched["warnings"]


def test_feet_from_roles_and_a_report_without_feet():
    roles = RoleMap({"foot.L": ("LeftFoot",), "toe.L": ("LeftToe",), "foot.R": ("RightFoot",)})
    assert qa.feet_from_roles(roles, NAMES + ("RightFoot",)) == {"L": [1, 2], "R": [3]}
    report = qa.measure(figure(), None, {}, ground=0.0)
    assert report["measures"]["slide"]["value"] is None and report["measures"]["slide"]["passed"] is None
    assert report["passed"] is True
    assert qa.summary_line(report).startswith("QA passed")


def test_one_frame_and_empty_results_do_not_fail():
    report = qa.measure(figure(1), figure(1), FEET, ground=0.0)
    assert report["measures"]["pop_velocity"]["value"] == 0.0
    assert report["measures"]["slide"]["value"] == 0.0


def test_a_retimed_result_may_reach_the_inputs_deepest_on_any_frame():
    src = figure()
    src.tails[9, 2, 2] = -0.04  # one 4 cm dip in the input
    short = figure(20)
    short.tails[3, 2, 2] = -0.045  # the dip, now at another frame of a shorter result
    pen = qa.measure(short, src, FEET, ground=0.0)["measures"]["penetration"]
    assert pen["value"] == pytest.approx(4.5) and pen["limit"] == pytest.approx(5.0) and pen["passed"] is True


def test_the_panel_rows_put_failures_first():
    report = qa.measure(sliding(1.0), figure(), FEET, ground=0.0, source_checksums=("a", "a"))
    rows = qa.rows(report)
    assert rows[0][:3] == ("Foot slide", "29 mm (limit 20)", True) and rows[0][3:] == ("LeftFoot", 1.0)
    assert ("Source untouched", "yes", False, None, None) in rows
    assert all(not r[2] for r in rows[1:])


def test_a_joint_that_translates_in_the_input_is_no_bone():
    src = figure()
    src.heads[:, 1:] += np.outer(np.linspace(0, 0.1, 30), [0.0, 0.0, 1.0])[:, None]  # the foot slides up the hips
    bl = qa.measure(src, src, FEET, ground=0.0)["measures"]["bone_length"]
    assert bl["value"] == pytest.approx(0.0) and bl["passed"]
    # without an input the root's children are left out: here the foot, whose parent is the root
    assert qa.measure(src, None, FEET, ground=0.0)["measures"]["bone_length"]["value"] == pytest.approx(0.0)
