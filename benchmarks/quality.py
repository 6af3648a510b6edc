#!/usr/bin/env python3
"""Motion quality on motion nobody here tuned for: every batch command on the Bandai Namco corpus
(../shared/data/mocap/bandai-namco-1 beside the repository; CC BY-NC 4.0, read in place, never
copied) and the bundled CMU clips, each result held to the motion QA's thresholds (solver/qa).

    python benchmarks/quality.py                 # every clip, every command: a table
    python benchmarks/quality.py --per-type 1    # one clip of every motion type
    python benchmarks/quality.py --json          # one JSON object, also benchmarks/results/quality.json
    python benchmarks/quality.py --json --commands simulate,compress   # updates those rows of it

Per command: clips run, clips passed (exit 0 and every QA measure within its threshold), clips
refused (exit 2, with the reason), and the worst planted-foot slide (mm), depth below the ground
(cm) and pop (joint angular velocity, deg per frame): each the clip furthest past (or closest
to) its own limit, with that limit (the input's own plus the margin); median wall time per clip. The commands' arguments are in tests/corpus/corpus_runs.py (the slow corpus
test runs the same code on a sample). Which failures come from which solver method is in
docs/qa.md."""

import argparse
import datetime
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests" / "corpus"))
os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="humananim-user-"))

import corpus_runs  # noqa: E402
from machine import numpy_add_us  # noqa: E402  (the contract's machine-speed indicator)


def worst(rows, measure):
    """The clip furthest past (or closest to) its limit on `measure`: its value, limit and where."""
    values = [(r["qa"]["measures"][measure]["value"] - r["qa"]["measures"][measure]["limit"], r) for r in rows
              if r.get("qa") and r["qa"].get("measures", {}).get(measure, {}).get("value") is not None]
    if not values:
        return None
    _, row = max(values, key=lambda v: v[0])
    value = row["qa"]["measures"][measure]["value"]
    m = row["qa"]["measures"][measure]
    return {"value": value, "clip": row["clip"], "bone": m.get("bone"), "frames": m.get("frames"),
            "limit": m.get("limit"), "input": m.get("input")}


def summarise(command, rows):
    ran = [r for r in rows if r["exit"] == 0]
    return {"command": command, "clips": len(rows), "ran": len(ran),
            "passed": sum(1 for r in ran if r["qa"].get("passed") is not False),
            "refused": sorted({r["error"] for r in rows if r["exit"] != 0})[:5],
            "failed": [{"clip": r["clip"], "warnings": r["qa"]["warnings"]} for r in ran
                       if r["qa"].get("passed") is False],
            "worst_slide_mm": worst(ran, "slide"), "worst_penetration_cm": worst(ran, "penetration"),
            "worst_pop_deg_per_frame": worst(ran, "pop_velocity"),
            "median_seconds": round(statistics.median([r["seconds"] for r in rows]), 2) if rows else None}


def merged(table, clips):
    """`table` with the rows of benchmarks/results/quality.json for the commands not run now, when
    that file holds the same number of clips (a run of some --commands updates their rows and keeps
    the others', each row with its date); in the order of corpus_runs.COMMANDS."""
    path = ROOT / "benchmarks" / "results" / "quality.json"
    try:
        before = json.loads(path.read_text())
    except (OSError, ValueError):
        return table
    if before.get("clips") != clips:
        return table
    ran = {t["command"] for t in table}
    rows = table + [t for t in before.get("commands", []) if t.get("command") not in ran]
    order = list(corpus_runs.COMMANDS)
    return sorted(rows, key=lambda t: order.index(t["command"]) if t["command"] in order else len(order))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--per-type", type=int, help="clips of each motion type (default: all)")
    parser.add_argument("--commands", default=",".join(corpus_runs.COMMANDS), help="comma-separated commands")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    clips = corpus_runs.sample(args.per_type) if args.per_type else \
        corpus_runs.corpus_clips() + [c for c in corpus_runs.BUNDLED if c.exists()]
    if not corpus_runs.CORPUS.is_dir():
        print(f"note: the corpus is not at {corpus_runs.CORPUS}: the bundled CMU clips only", file=sys.stderr)
    import bpy  # noqa: F401
    import humananim
    humananim.register()
    out_dir = tempfile.mkdtemp(prefix="humananim-quality-")
    rows = {c: [] for c in args.commands.split(",")}
    speed = numpy_add_us()
    try:
        for clip in clips:
            for command in rows:
                code, summary, err, seconds = corpus_runs.run(command, clip, out_dir)
                error = err.strip().splitlines()[-1] if code != 0 and err.strip() else ""
                rows[command].append({"clip": clip.name, "type": corpus_runs.motion_type(clip), "exit": code,
                                      "qa": (summary or {}).get("qa"), "error": error, "seconds": seconds})
                print(f"{command:10s} {clip.name:45s} exit {code} "
                      f"{'' if not summary else 'QA passed' if summary['qa'].get('passed') is not False else 'QA FAILED'} "
                      f"{seconds:.1f} s {error}", file=sys.stderr, flush=True)
    finally:
        humananim.unregister()
    table = [dict(summarise(c, r), date=datetime.date.today().isoformat()) for c, r in rows.items()]
    if args.json:
        table = merged(table, len(clips))
    result = {"benchmark": "quality", "date": datetime.date.today().isoformat(),
              "machine_speed": {"numpy_add_us": round(speed, 3)},
              "clips": len(clips), "corpus": str(corpus_runs.CORPUS) if corpus_runs.CORPUS.is_dir() else None,
              "claims": [{"claim": f"{t['command']}: results within every QA threshold", "value": t["passed"],
                          "unit": f"of {t['clips']} clips", "aim": f"{t['clips']} of {t['clips']}",
                          "met": t["passed"] == t["clips"]} for t in table],
              "commands": table}
    if args.json:
        print(json.dumps(result, indent=1))
        (ROOT / "benchmarks" / "results").mkdir(exist_ok=True)
        (ROOT / "benchmarks" / "results" / "quality.json").write_text(json.dumps(result, indent=1) + "\n")
        return
    print(f"{'command':11s} {'clips':>5s} {'passed':>6s} {'refused':>7s} {'worst slide (limit)':>20s} "
          f"{'worst below (limit)':>20s} {'worst pop (limit)':>26s} {'median s':>8s}")
    for t in table:
        def cell(w, fmt):
            return "-" if w is None else fmt.format(**w)
        print(f"{t['command']:11s} {t['clips']:5d} {t['passed']:6d} {t['clips'] - t['ran']:7d} "
              f"{cell(t['worst_slide_mm'], '{value:.0f} mm ({limit:.0f})'):>20s} "
              f"{cell(t['worst_penetration_cm'], '{value:.1f} cm ({limit:.1f})'):>20s} "
              f"{cell(t['worst_pop_deg_per_frame'], '{value:.1f} deg/frame ({limit:.1f})'):>26s} "
              f"{t['median_seconds']:8.1f}")


if __name__ == "__main__":
    main()


