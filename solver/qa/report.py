"""Warnings and a short text of a QA report, naming frames and bones."""

WHAT = {
    "nonfinite": "NaN or infinite values",
    "slide": "planted foot slides",
    "penetration": "below the ground",
    "pop_velocity": "joint rotation pops (angular velocity beyond the input's own)",
    "pop_acceleration": "joint rotation pops (angular acceleration beyond the input's own)",
    "bone_length": "bone lengths change",
    "figure_height": "figure height outside a human's",
    "source_untouched": "the source motion changed",
}


def _frames(frames):
    if not frames:
        return ""
    if len(frames) == 2 and frames[0] != frames[1]:
        return f" at frames {frames[0]:g}-{frames[1]:g}"
    return " at frame" + ("s " if len(frames) > 1 else " ") + ", ".join(f"{f:g}" for f in frames)


def describe(name, m):
    """One line for a measure: value, unit, limit, bone and frames."""
    if name == "source_untouched":
        return "source motion untouched" if m["passed"] else WHAT[name]
    if m["value"] is None:
        return f"{name}: not measured" + (f" ({m['note']})" if m.get("note") else "")
    limit = m["limit"]
    limit = f"{limit[0]:g}-{limit[1]:g}" if isinstance(limit, list) else f"{limit:g}"
    where = (f" '{m['bone']}'" if m.get("bone") else "") + _frames(m.get("frames", []))
    extra = ""
    if name == "penetration" and m.get("frames_below"):
        extra = f", {m['frames_below']} frames below"
    if name.startswith("pop") and m.get("input") is not None:
        extra = f" (the input's own: {m['input']:g})"
    what = WHAT[name] if not m["passed"] else name
    if name.startswith("pop") and m.get("input") is None:
        what = what.replace("the input's own", "a human's")
    return f"{what}: {m['value']:g} {m['unit']} (limit {limit}){where}{extra}"


def warnings(report):
    """One line per measure beyond its threshold, naming the bone and the frames."""
    return [describe(name, m) for name, m in report["measures"].items() if m["passed"] is False]


def summary_line(report):
    """The QA in one line for command summaries and operator reports."""
    ms = report["measures"]
    parts = []
    for name, label in (("slide", "slide"), ("penetration", "below ground"), ("pop_velocity", "pop"),
                        ("pop_acceleration", "pop accel")):
        m = ms[name]
        if m["value"] is not None:
            parts.append(f"{label} {m['value']:.1f} {m['unit']}")
    state = "passed" if report["passed"] else f"{len(report['warnings'])} WARNING(S)"
    return f"QA {state}: " + ", ".join(parts)


def text(report):
    """The summary line and one indented line per warning."""
    return "\n".join([summary_line(report)] + [f"  WARNING: {w}" for w in report["warnings"]])


LABELS = {"nonfinite": "NaN / inf", "slide": "Foot slide", "penetration": "Below ground",
          "pop_velocity": "Pop (velocity)", "pop_acceleration": "Pop (acceleration)", "bone_length": "Bone length",
          "figure_height": "Figure height", "source_untouched": "Source untouched"}


def rows(report):
    """The QA panel's rows: (label, text, failed, bone or None, first frame or None) per measure
    that was measured, the failed ones first."""
    out = []
    for name, m in report.get("measures", {}).items():
        if name == "source_untouched":
            if m["passed"] is not None:
                out.append((LABELS[name], "yes" if m["passed"] else "NO: the source changed", not m["passed"], None,
                            None))
            continue
        if m["value"] is None:
            continue
        limit = m["limit"]
        limit = f"{limit[0]:g}-{limit[1]:g}" if isinstance(limit, list) else f"{limit:g}"
        frames = m.get("frames") or []
        out.append((LABELS[name], f"{m['value']:.3g} {m['unit']} (limit {limit})", m["passed"] is False,
                    m.get("bone"), frames[0] if frames else None))
    return sorted(out, key=lambda r: not r[2])
