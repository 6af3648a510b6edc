"""The motion QA's thresholds: the one place they are defined (docs/qa.md explains each).

Rates are given per second and turned into per-frame values at the clip's own frame rate, so a
limit means the same motion at 24, 30 or 120 fps; reports give them per frame."""

# Planted contacts: a foot point is planted on a frame when it is within CONTACT_HEIGHT_M of its
# own lowest level in the clip and moves slower than CONTACT_SPEED_M_S over the ground, for at
# least CONTACT_MIN_SECONDS in a row.
CONTACT_HEIGHT_M = 0.02
CONTACT_SPEED_M_S = 0.2
CONTACT_MIN_SECONDS = 0.1

# A planted point may drift this far over the ground within one contact, or no more than the
# input's own worst drift plus SLIDE_MARGIN_MM (capture skates a little).
SLIDE_MM = 20.0
SLIDE_MARGIN_MM = 5.0

# Any body point (bone heads and tails) may go this far below the ground, or the input's own
# deepest plus PENETRATION_MARGIN_CM; frames deeper than PENETRATION_FRAME_CM are counted.
PENETRATION_CM = 2.0
PENETRATION_MARGIN_CM = 1.0
PENETRATION_FRAME_CM = 0.5
# Without a given ground, the floor is this percentile of the input's lowest foot point per frame
# (a few toe dips do not move it).
FLOOR_PERCENTILE = 10.0

# Pops: a joint's angular velocity (rotation between frames) and acceleration (change of that
# rotation between frames) may reach POP_RATIO times the input's own largest for that joint plus
# these margins (a retimed clip may be a little faster); with no input motion (a generated walk)
# they may not exceed the absolute caps.
POP_RATIO = 1.25
POP_VELOCITY_MARGIN_DEG_S = 150.0  # 5 deg per frame at 30 fps
POP_ACCELERATION_MARGIN_DEG_S2 = 4500.0  # 5 deg per frame per frame at 30 fps
POP_VELOCITY_CAP_DEG_S = 900.0  # 30 deg per frame at 30 fps
POP_ACCELERATION_CAP_DEG_S2 = 13500.0  # 15 deg per frame per frame at 30 fps

# Bones keep their lengths (head to parent head, against the input or the first frame).
BONE_LENGTH_PCT = 1.0
BONE_MIN_LENGTH_M = 0.01  # shorter bones are left out (zero-length helpers)

# The figure's height (rest pose, ground to the highest point) is a human's.
FIGURE_HEIGHT_M = (1.0, 2.3)


def per_frame(fps):
    """The rate limits at `fps`: deg per frame and deg per frame per frame."""
    return {"pop_velocity_margin_deg": POP_VELOCITY_MARGIN_DEG_S / fps,
            "pop_acceleration_margin_deg": POP_ACCELERATION_MARGIN_DEG_S2 / fps ** 2,
            "pop_velocity_cap_deg": POP_VELOCITY_CAP_DEG_S / fps,
            "pop_acceleration_cap_deg": POP_ACCELERATION_CAP_DEG_S2 / fps ** 2}


def as_dict(fps=30.0):
    """Every threshold, for reports and docs."""
    return {"slide_mm": SLIDE_MM, "slide_margin_mm": SLIDE_MARGIN_MM,
            "penetration_cm": PENETRATION_CM, "penetration_margin_cm": PENETRATION_MARGIN_CM,
            "bone_length_pct": BONE_LENGTH_PCT, "pop_ratio": POP_RATIO, "figure_height_m": list(FIGURE_HEIGHT_M),
            "contact_height_m": CONTACT_HEIGHT_M, "contact_speed_m_s": CONTACT_SPEED_M_S,
            **{k: round(v, 4) for k, v in per_frame(fps).items()}}
