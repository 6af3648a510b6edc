"""The corpus runs shared by the slow corpus test and benchmarks/quality.py: every batch command
on a clip, in this process (`python -m humananim`'s own main), each result's motion QA.

The Bandai Namco corpus (CC BY-NC 4.0: tests and benchmarks only, never copied into the repo or
the extension) is read where the developers' guide puts it: ../shared/data/mocap/bandai-namco-1
beside the repository."""

import contextlib
import io
import json
import os
import re
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
CORPUS = REPO.parent / "shared" / "data" / "mocap" / "bandai-namco-1"
BUNDLED = [REPO / "humananim_addon" / "data" / "mocap" / f for f in ("cmu_131_01.bvh", "cmu_131_03.bvh")]
SECONDS = 3.0  # of each clip the dynamics commands work on (from its second 0.5)


def corpus_clips():
    return sorted(CORPUS.glob("*.bvh")) if CORPUS.is_dir() else []


def motion_type(path):
    """'walk', 'run', 'dance-short', ... from dataset-1_<type>_<style>_001.bvh; 'cmu' for CMU."""
    m = re.match(r"dataset-1_([^_]+)_", Path(path).name)
    return m.group(1) if m else "cmu"


def sample(per_type=1):
    """`per_type` corpus clips of every motion type (the first styles in name order, so the
    sample is the same on every run), and the bundled CMU clips."""
    chosen, seen = [], {}
    for clip in corpus_clips():
        kind = motion_type(clip)
        if seen.get(kind, 0) < per_type:
            chosen.append(clip)
            seen[kind] = seen.get(kind, 0) + 1
    return chosen + [c for c in BUNDLED if c.exists()]


def clip_frames(path):
    """(frame count, fps) from a BVH header."""
    from humananim.solver import bvh
    with open(path) as f:
        clip = bvh.parse(f.read())
    return clip.frame_count, clip.fps


def window(path):
    """The frames the dynamics commands run on: SECONDS of the clip from its second 0.5 (the
    whole clip when shorter)."""
    frames, fps = clip_frames(path)
    start = min(1 + int(round(0.5 * fps)), max(1, frames - 3))
    end = min(frames, start + int(round(SECONDS * fps)))
    return start, end


# command -> arguments after the clip, formatted with the clip's {name}, {start}-{end} window,
# {mid} and {mid2} (5 % of the clip later) and {clip} (its path)
COMMANDS = {
    "info": [],
    "simulate": ["--frames", "{start}", "{end}"],
    "control": ["--frames", "{start}", "{end}", "--load-left", "3", "--load-right", "3"],
    "filter": ["--denoise-hz", "8"],
    "compress": [],
    "warp": ["--map", "{mid}:{mid2}"],
    "blend": ["--with", "{clip}"],
    "synthesize": ["--queue", "{name}@{start}-{mid}", "--queue", "{name}@{mid2}-{end}:connect"],
    "walk": ["--line", "3"],
}


def arguments(command, path, out_dir):
    start, end = window(path)
    frames, _ = clip_frames(path)
    mid = (start + end) // 2
    # the warp moves the middle 5 % of its distance to the clip's start later: a mild retiming
    values = {"name": Path(path).stem, "start": start, "end": end, "mid": mid,
              "mid2": min(end - 1, mid + max(1, (mid - 1) // 20)), "clip": str(path)}
    args = [command, str(path)] + [a.format(**values) for a in COMMANDS[command]]
    if command != "info":
        args += ["--out", str(Path(out_dir) / f"{command}-{Path(path).stem}.blend")]
    return args + ["--json"]


def run(command, path, out_dir):
    """(exit status, summary dict or None, stderr text, seconds) of one command on one clip."""
    from humananim.humananim_addon import cli
    out, err = io.StringIO(), io.StringIO()
    t0 = time.perf_counter()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = cli.main(arguments(command, path, out_dir))
        except SystemExit as stop:
            code = stop.code
    seconds = time.perf_counter() - t0
    try:
        summary = json.loads(out.getvalue()) if code == 0 else None
    except ValueError:
        summary = None
    for produced in Path(out_dir).glob(f"{command}-*"):
        os.remove(produced)
    return code, summary, err.getvalue(), seconds
