#!/usr/bin/env python3
"""Clean Up Capture on corrupted capture: clips of the Bandai Namco corpus
(../shared/data/mocap/bandai-namco-1 beside the repository, read in place, never copied) and the
bundled CMU walks, each corrupted with known faults, cleaned by solver.cleanup, and compared with
the original.

    python benchmarks/cleanup.py              # 50 Bandai Namco clips + the CMU clips: a table
    python benchmarks/cleanup.py --clips 10   # fewer
    python benchmarks/cleanup.py --json       # one JSON object, also benchmarks/results/cleanup.json

Ground truth: each clip read by solver.bvh (unit guessed from the figure's height), with its own
glitches repaired first (raw capture has flips of its own). Each clip is corrupted four ways,
each cleaned with only the repair it calls for (seeded per clip):

- glitches: three single-frame rotation flips of 90-180 deg on random bones, a root position
  spike of 10-30 cm (times a random direction's length / sqrt 3), a held dropout and a zeroed dropout of 2-10 frames each. Per kind: detected
  (an event on that bone covering that frame) and repaired (every joint within 2 deg of the
  original on those frames, the root within 5 mm); elsewhere, the largest change. Per flip and
  dropout also its oracle bound (oracle_fill_deg): the best of several fills from the frames left,
  picked per joint knowing the truth; a gap over 2 deg there can't be repaired to 2 deg by them.
- jitter: 1 deg (per axis, Gaussian) on every joint and 5 mm on the root. The joint angle error
  against the original (RMS and max, deg) and the bone-tail position error (RMS, mm) before and
  after.
- floor and skate: the root lifted 5 cm and drifting 5 cm (a sine of 0.3 Hz) over the ground.
  The floor found against the original's plus 5 cm (mm), the lowest body point (the pelvis and the bones under it) and the lowest foot point
  after (mm, below 0 is through the floor; only feet are repaired), the slide of every planted foot point within its contact (mm; contacts of
  the corrupted clip) before and after.
- ground mesh: the uncorrupted clip put on a bumpy height field (+-1.5 cm): its lowest foot point
  above the ground (mm), the slide of its planted points (mm), and the contacts that the
  flat-floor repair puts on a flat floor that this one puts on the bumps (within 2 mm).
- clean: the uncorrupted clip through glitches and jitter: the change (RMS, deg).
Aims (issue 26): every flip, spike and dropout within 2 deg; planted-foot slide under 2 mm; no
point below the floor; the clean clip within 0.5 deg RMS.
"""

import argparse
import datetime
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT.parent))

from humananim.solver import bvh, rotations, units  # noqa: E402
from humananim.solver.role_detection import detect_roles  # noqa: E402
from humananim.solver.cleanup import Options, clean_up, feet, glitches, ground  # noqa: E402
from humananim.solver.trajectories import Trajectories  # noqa: E402
from machine import numpy_add_us  # noqa: E402  (the contract's machine-speed indicator)

CORPUS = ROOT.parent / "shared" / "data" / "mocap" / "bandai-namco-1"
MIN_FRAMES = 120  # six faults, each with 15 good frames around it
CMU = [ROOT / "humananim_addon" / "data" / "mocap" / f for f in ("cmu_131_01.bvh", "cmu_131_03.bvh")]


def load(path):
    raw = bvh.read(path)
    scale, _ = units.guess_length_scale(bvh.figure_height(raw))
    b = bvh.read(path, scale=scale)
    roles = detect_roles(b.names, b.parents, bvh.rest_heads(b), bvh.rest_tails(b)).roles
    sk = bvh.skeleton(b, roles=roles)
    tr = bvh.trajectories(b, sk)
    q, p, _ = glitches.repair(tr.rotations, tr.translations[:, :1], tr.fps)
    t = tr.translations.copy()
    t[:, :1] = p
    return sk, Trajectories(tr.frames, tr.fps, q, t, np.eye(4))


def deg(a, b):
    return np.degrees(rotations.angle_between(a, b))


def tails(sk, tr):
    w = tr.world_frames(sk)
    return w[..., :3, 3] + w[..., :3, 1] * sk.lengths[:, None]


def _unit_deg(fill, truth):
    return deg(fill / np.linalg.norm(fill, axis=-1, keepdims=True), truth)


def _smoothest_fill(q, a, b, order, context=12):
    """Frames a..b-1 of q (F, J, 4) that make the `order`-th differences over the gap and
    `context` known frames each side least (order 2: least acceleration, 3: least jerk)."""
    lo, hi = max(0, a - context), min(len(q), b + context)
    D = np.eye(hi - lo)
    for _ in range(order):
        D = np.diff(D, axis=0)
    gap = np.zeros(hi - lo, bool)
    gap[a - lo:b - lo] = True
    known = q[lo:hi][~gap].reshape(int((~gap).sum()), -1)
    fill = np.linalg.lstsq(D[:, gap], -D[:, ~gap] @ known, rcond=None)[0]
    return fill.reshape((b - a,) + q.shape[1:])


def oracle_fill_deg(q, a, b):
    """The oracle bound of a gap (frames a..b-1 of every joint's quaternions q (F, J, 4), on one
    hemisphere): per joint the best of several fills from the frames left, chosen KNOWING the
    truth; its largest error over the gap and the joints (deg). The fills: a cubic spline through
    every known frame (it carries the motion's velocity into the gap), the least-acceleration and
    least-jerk fills over 12 known frames each side, a slerp-like blend of the gap's two ends, and
    every stretch of the clip elsewhere warped onto the gap's ends (the clean-up's exemplar fill),
    the best one picked by the truth. Over that bound, none of these fills gets there: the gap's
    motion is neither a smooth continuation of the frames around it nor repeated in the clip."""
    F, J = q.shape[:2]
    n = b - a
    truth = q[a:b]
    bad = np.zeros(F, bool)
    bad[a:b] = True
    w = (np.arange(1, n + 1) / (n + 1))[:, None, None]
    fills = [glitches._spline_fill(q, bad)[a:b], _smoothest_fill(q, a, b, 2), _smoothest_fill(q, a, b, 3),
             (1 - w) * q[a - 1] + w * q[b]]
    best = np.min([_unit_deg(f, truth).max(axis=0) for f in fills], axis=0)  # (J,)
    starts = np.array([s for s in range(1, F - n - 1) if s + n + 1 <= a - 1 or s - 1 >= b + 1])
    if len(starts):
        win = q[starts[:, None] + np.arange(-1, n + 1)]  # (S, n + 2, J, 4)
        win = win * np.sign(np.sum(win[:, :1] * q[a - 1], axis=-1, keepdims=True) + 1e-12)
        w = w[None]
        warped = win[:, 1:-1] + (1 - w) * (q[a - 1] - win[:, :1]) + w * (q[b] - win[:, -1:])
        best = np.minimum(best, _unit_deg(warped, truth[None]).max(axis=1).min(axis=0))
    return float(best.max())


def glitch_case(sk, tr, rng):
    F, J = tr.rotations.shape[:2]
    q, t = tr.rotations.copy(), tr.translations.copy()
    margin = 15  # faults need good frames around them; clips are at least MIN_FRAMES long
    slots = rng.permutation(np.linspace(margin, F - margin - 12, 6).astype(int))  # 6 separate places
    faults = []
    for f in slots[:3]:
        j = int(rng.integers(1, J))
        axis = rng.normal(size=3)
        angle = rng.uniform(90, 180)
        q[f, j] = rotations.multiply(q[f, j], rotations.from_axis_angle(
            np.concatenate(([np.radians(angle)], axis / np.linalg.norm(axis)))))
        faults.append(("flip", j, int(f), int(f)))
    f = int(slots[3])
    t[f, 0] += rng.normal(size=3) / np.sqrt(3) * rng.uniform(0.1, 0.3)
    faults.append(("position spike", 0, f, f))
    for kind, f in (("held dropout", int(slots[4])), ("zero dropout", int(slots[5]))):
        n = int(rng.integers(2, 11))
        if kind == "held dropout":
            q[f:f + n], t[f:f + n] = q[f - 1], t[f - 1]
        else:
            q[f:f + n], t[f:f + n] = [1.0, 0.0, 0.0, 0.0], 0.0
        faults.append((kind, None, f, f + n - 1))
    bad = Trajectories(tr.frames, tr.fps, q, t, tr.armature_to_world)
    out, report = clean_up(sk, bad, Options(jitter=False, floor=False, skate=False))
    events = report["repairs"][0]["events"]
    err = deg(out.rotations, tr.rotations)
    pos = np.linalg.norm(out.translations[:, 0] - tr.translations[:, 0], axis=-1)
    rows, touched = [], np.zeros(F, bool)
    for kind, j, a, b in faults:
        touched[a:b + 1] = True
        name = None if j is None else sk.names[j]
        hit = any(e["frames"][0] <= tr.frames[a] and tr.frames[b] <= e["frames"][1]
                  and (name is None or e["bone"] == name or kind.startswith("zero") or kind.startswith("held"))
                  for e in events)
        worst = float(err[a:b + 1].max())
        ok = worst < 2.0 and float(pos[a:b + 1].max()) < 0.005
        row = {"kind": kind, "detected": bool(hit), "repaired": bool(ok), "max_deg": worst,
               "root_mm": 1000 * float(pos[a:b + 1].max()), "frames": b - a + 1}
        if j is None or kind == "flip":  # what the frames left allow (the flip: that joint only)
            q_true = rotations.make_continuous(tr.rotations)
            row["oracle_deg"] = oracle_fill_deg(q_true if j is None else q_true[:, j:j + 1], a, b + 1)
        rows.append(row)
    elsewhere = float(err[~touched].max()) if (~touched).any() else 0.0
    return rows, elsewhere


def jitter_case(sk, tr, rng):
    F, J = tr.rotations.shape[:2]
    noise = rotations.from_axis_angle(np.concatenate((np.ones((F, J, 1)), np.zeros((F, J, 3))), axis=-1))
    vec = np.radians(1.0) * rng.normal(size=(F, J, 3))
    angle = np.linalg.norm(vec, axis=-1, keepdims=True)
    noise = rotations.from_axis_angle(np.concatenate((angle, vec / np.maximum(angle, 1e-12)), axis=-1))
    q = rotations.multiply(tr.rotations, noise)
    t = tr.translations.copy()
    t[:, 0] += 0.005 * rng.normal(size=(F, 3))
    bad = Trajectories(tr.frames, tr.fps, q, t, tr.armature_to_world)
    out, _ = clean_up(sk, bad, Options(glitches=False, floor=False, skate=False))
    truth = tails(sk, tr)
    res = {}
    for label, m in (("before", bad), ("after", out)):
        e = deg(m.rotations, tr.rotations)
        res[label] = {"rms_deg": float(np.sqrt(np.mean(e ** 2))), "max_deg": float(e.max()),
                      "tail_rms_mm": 1000 * float(np.sqrt(np.mean(np.sum((tails(sk, m) - truth) ** 2, axis=-1))))}
    return res


def slide_mm(sk, tr, planted):
    return 1000 * feet.planted_slide(sk, tr, planted)


def feet_case(sk, tr):
    position, orientation = tr.root_pose(sk)
    points = feet.foot_points(sk, tr.world_frames(sk))
    floor = feet.find_floor(points, feet.find_contacts(points, tr.fps))
    moved = position + [0.0, 0.0, 0.05]
    moved[:, 0] += 0.05 * np.sin(2 * np.pi * 0.3 * tr.times)
    bad = tr.with_root_pose(sk, moved, orientation)
    planted = feet.planted_points(feet.foot_points(sk, bad.world_frames(sk)), tr.fps)
    out, report = clean_up(sk, bad, Options(glitches=False, jitter=False, ground=floor))
    body = [sk.root] + sk.descendants(sk.root)  # not a ground-level root bone above the pelvis
    pts = np.concatenate((out.world_frames(sk)[:, body][..., :3, 3], tails(sk, out)[:, body]), axis=1)
    foot = feet.foot_points(sk, out.world_frames(sk))
    return {"floor_error_mm": 1000 * abs(report["floor_m"] - (floor + 0.05)),
            "lowest_mm": 1000 * float(pts[..., 2].min() - floor),
            "lowest_foot_mm": 1000 * float(min(p[..., 2].min() for p in foot.values()) - floor),
            "slide_before_mm": slide_mm(sk, bad, planted), "slide_after_mm": slide_mm(sk, out, planted),
            "hovering_contacts": report["repairs"][2]["hovering_contacts"],
            "pelvis_lowered_cm": max(report["repairs"][2]["pelvis_lowered_cm"], report["repairs"][3]["pelvis_lowered_cm"])}


def bumps(xy):
    return 0.015 * np.sin(2.0 * xy[..., 0]) * np.cos(1.5 * xy[..., 1])


def ground_case(sk, tr):
    """The clip put on a bumpy height field (+-1.5 cm, 5 cm cells, 3 m waves): its lowest foot
    point above the ground (mm), the slide of its planted points (mm), the contacts that the
    flat-floor repair puts on the floor and this one on the bumps (within 2 mm)."""
    x = np.arange(-15.0, 15.0, 0.05)
    xx, yy = np.meshgrid(x, x)
    field = ground.HeightField(bumps(np.stack((xx, yy), axis=-1)), (x[0], x[0]), 0.05)
    planted = feet.planted_points(feet.foot_points(sk, tr.world_frames(sk)), tr.fps)
    out, _ = clean_up(sk, tr, Options(glitches=False, jitter=False, ground=field))
    flat, _ = clean_up(sk, tr, Options(glitches=False, jitter=False, ground=0.0))
    above = {s: feet.heights_above(p, field).min(axis=1) for s, p in feet.foot_points(sk, out.world_frames(sk)).items()}
    low = {s: p[..., 2].min(axis=1) for s, p in feet.foot_points(sk, flat.world_frames(sk)).items()}
    on_floor = on_bumps = 0
    for side, down in planted.items():
        for a, b in feet.contact_runs(down.any(axis=1)):
            if low[side][a:b].min() < 0.002:
                on_floor += 1
                on_bumps += abs(above[side][a:b].min()) < 0.002
    finite = np.concatenate([h[np.isfinite(h)] for h in above.values()])
    return {"lowest_foot_mm": 1000 * float(finite.min()), "slide_mm": slide_mm(sk, out, planted),
            "contacts_on_floor": on_floor, "contacts_on_bumps": int(on_bumps)}


def clean_case(sk, tr):
    out, _ = clean_up(sk, tr, Options(floor=False, skate=False))
    return float(np.sqrt(np.mean(deg(out.rotations, tr.rotations) ** 2)))


def _by_fps(kinds):
    out = {}
    for k in ("held dropout", "zero dropout"):
        for r in kinds.get(k, []):
            out.setdefault(r["fps"], []).append(r)
    return out


def run_clips(paths, clips, max_frames):
    """Each usable clip through every case: glitch rows by kind, the change elsewhere, jitter, feet,
    ground mesh and clean-clip figures, and the clips skipped (with why)."""
    used = 0
    kinds, jit, fl, gr, clean, elsewhere, skipped = {}, [], [], [], [], [], []
    for i, path in enumerate(paths):
        if used >= clips + len(CMU):
            break
        try:
            sk, tr = load(path)
        except Exception as error:  # a clip the reader or the unit guess refuses
            skipped.append(f"{path.name}: {error}")
            continue
        n = min(len(tr.frames), max_frames)
        tr = Trajectories(tr.frames[:n], tr.fps, tr.rotations[:n], tr.translations[:n], tr.armature_to_world)
        if n < MIN_FRAMES:
            skipped.append(f"{path.name}: {n} frames")
            continue
        used += 1
        rng = np.random.default_rng(i)
        rows, rest = glitch_case(sk, tr, rng)
        for r in rows:
            r["fps"] = round(tr.fps)
            kinds.setdefault(r["kind"], []).append(r)
        elsewhere.append(rest)
        jit.append(jitter_case(sk, tr, rng))
        try:
            fl.append(dict(feet_case(sk, tr), clip=path.name))
            gr.append(ground_case(sk, tr))
        except ValueError as error:  # a rig without a leg chain
            skipped.append(f"{path.name} (feet): {error}")
        clean.append(clean_case(sk, tr))
    return kinds, jit, fl, gr, clean, elsewhere, skipped


def summary(kinds, jit, fl, gr, clean, elsewhere, skipped, seconds):
    """The benchmark's JSON object (without its claims): per-kind glitch counts, medians and worst cases."""
    per_kind = {k: {"injected": len(v), "detected": sum(r["detected"] for r in v),
                    "repaired": sum(r["repaired"] for r in v), "max_deg": max(r["max_deg"] for r in v)}
                for k, v in kinds.items()}
    for k, v in kinds.items():
        bound = [r for r in v if "oracle_deg" in r]
        if bound:  # how many a fill from the frames left could repair at best (the oracle bound)
            per_kind[k]["oracle_within_2deg"] = sum(r["oracle_deg"] < 2.0 for r in bound)
            per_kind[k]["oracle_max_deg"] = max(r["oracle_deg"] for r in bound)
            per_kind[k]["repaired_where_oracle_within_2deg"] = sum(r["repaired"] for r in bound if r["oracle_deg"] < 2.0)
    jitter_after = [j["after"]["rms_deg"] for j in jit]
    return {
        "benchmark": "cleanup", "date": datetime.date.today().isoformat(),
        "machine_speed": {"numpy_add_us": numpy_add_us()},
        "clips": len(clean), "bandai_namco_clips": len(clean) - sum(1 for p in CMU if p.exists()), "skipped": skipped, "seconds": seconds,
        "glitches": per_kind, "glitch_elsewhere_max_deg": max(elsewhere) if elsewhere else None,
        "jitter": {"before_rms_deg": float(np.median([j["before"]["rms_deg"] for j in jit])),
                   "after_rms_deg": float(np.median(jitter_after)),
                   "after_max_deg": float(max(j["after"]["max_deg"] for j in jit)),
                   "before_tail_rms_mm": float(np.median([j["before"]["tail_rms_mm"] for j in jit])),
                   "after_tail_rms_mm": float(np.median([j["after"]["tail_rms_mm"] for j in jit]))},
        "feet": {"floor_error_mm_max": max(f["floor_error_mm"] for f in fl),
                 "lowest_mm_min": min(f["lowest_mm"] for f in fl),
                 "lowest_foot_mm_min": min(f["lowest_foot_mm"] for f in fl),
                 "slide_before_mm_median": float(np.median([f["slide_before_mm"] for f in fl])),
                 "slide_after_mm_median": float(np.median([f["slide_after_mm"] for f in fl])),
                 "slide_after_mm_max": max(f["slide_after_mm"] for f in fl),
                 "slide_after_under_2mm_clips": sum(f["slide_after_mm"] < 2.0 for f in fl), "clips": len(fl),
                 "hovering_contacts": sum(f["hovering_contacts"] for f in fl),
                 "pelvis_lowered_cm_median": float(np.median([f["pelvis_lowered_cm"] for f in fl])),
                 "pelvis_lowered_cm_max": max(f["pelvis_lowered_cm"] for f in fl),
                 "slide_worst_clip": max(fl, key=lambda f: f["slide_after_mm"])["clip"]},
        "ground_mesh": {"lowest_foot_mm_min": min(g["lowest_foot_mm"] for g in gr),
                        "slide_mm_median": float(np.median([g["slide_mm"] for g in gr])),
                        "slide_mm_max": max(g["slide_mm"] for g in gr),
                        "contacts_on_floor": sum(g["contacts_on_floor"] for g in gr),
                        "contacts_on_bumps": sum(g["contacts_on_bumps"] for g in gr)},
        "clean_rms_deg_max": max(clean), "clean_rms_deg_median": float(np.median(clean)),
        "dropout_max_deg_by_fps": {f"{fps:g}": max(r["max_deg"] for r in rs) for fps, rs in _by_fps(kinds).items()},
    }


def _oracle_fraction(kinds):
    bound = [r["oracle_deg"] < 2.0 for v in kinds.values() for r in v if "oracle_deg" in r]
    return sum(bound) / max(len(bound), 1)


def claims(result, kinds):
    """One line per claim, each with its aim and whether it is met."""
    all_rows = [r for v in kinds.values() for r in v]
    repaired = sum(r["repaired"] for r in all_rows) / len(all_rows)
    return [
        {"claim": "injected flips, spikes and dropouts repaired within 2 deg (fraction)", "value": round(repaired, 4),
         "unit": "fraction", "aim": "1.0", "met": repaired == 1.0},
        {"claim": "injected flips, spikes and dropouts within 2 deg by the oracle bound (the best a fill from the "
                  "frames left can do, chosen knowing the truth; fraction of those it bounds)",
         "value": round(_oracle_fraction(kinds), 4), "unit": "fraction", "aim": None, "met": None},
        {"claim": "planted-foot slide after skate repair, worst clip", "value": round(result["feet"]["slide_after_mm_max"], 2),
         "unit": "mm", "aim": "< 2 mm", "met": result["feet"]["slide_after_mm_max"] < 2.0},
        {"claim": "lowest body point after the floor repair, worst clip", "value": round(result["feet"]["lowest_mm_min"], 2),
         "unit": "mm", "aim": ">= 0 (nothing below the floor)", "met": result["feet"]["lowest_mm_min"] >= -0.5},
        {"claim": "planted-foot slide after skate repair, median clip", "value": round(result["feet"]["slide_after_mm_median"], 2),
         "unit": "mm", "aim": "< 2 mm", "met": result["feet"]["slide_after_mm_median"] < 2.0},
        {"claim": "feet on a bumpy ground mesh: lowest foot point above it, worst clip",
         "value": round(result["ground_mesh"]["lowest_foot_mm_min"], 2), "unit": "mm", "aim": ">= 0 (no sinking)",
         "met": result["ground_mesh"]["lowest_foot_mm_min"] >= -0.5},
        {"claim": "feet on a bumpy ground mesh: contacts on it (of those the flat repair puts on a flat floor)",
         "value": round(result["ground_mesh"]["contacts_on_bumps"] / max(result["ground_mesh"]["contacts_on_floor"], 1), 4),
         "unit": "fraction", "aim": "1.0 (no hovering)",
         "met": result["ground_mesh"]["contacts_on_bumps"] == result["ground_mesh"]["contacts_on_floor"]},
        {"claim": "clean clip changed by glitches + jitter, worst clip", "value": round(result["clean_rms_deg_max"], 3),
         "unit": "deg RMS", "aim": "< 0.5 deg RMS", "met": result["clean_rms_deg_max"] < 0.5},
        {"claim": "jitter (1 deg) left after the filter, median clip", "value": round(result["jitter"]["after_rms_deg"], 3),
         "unit": "deg RMS", "aim": None, "met": None},
    ]


def write_json(result):
    text = json.dumps(result, indent=1)
    print(text)
    out = ROOT / "benchmarks" / "results" / "cleanup.json"
    out.parent.mkdir(exist_ok=True)
    out.write_text(text + "\n")


def print_report(result):
    """The same figures as a human-readable table."""
    per_kind, skipped = result["glitches"], result["skipped"]
    print(f"{result['clips']} clips in {result['seconds']} s ({len(skipped)} skipped)")
    print(f"{'fault':16s} {'injected':>8s} {'detected':>8s} {'repaired':>8s} {'max deg':>8s}")
    for k, v in per_kind.items():
        bound = (f"   oracle bound: {v['oracle_within_2deg']} within 2 deg at best (worst {v['oracle_max_deg']:.1f} deg); "
                 f"repaired {v['repaired_where_oracle_within_2deg']} of those") if "oracle_within_2deg" in v else ""
        print(f"{k:16s} {v['injected']:8d} {v['detected']:8d} {v['repaired']:8d} {v['max_deg']:8.2f}{bound}")
    print(f"elsewhere: largest change {result['glitch_elsewhere_max_deg']:.3f} deg")
    j = result["jitter"]
    print(f"jitter: {j['before_rms_deg']:.2f} -> {j['after_rms_deg']:.2f} deg RMS (median), tails "
          f"{j['before_tail_rms_mm']:.1f} -> {j['after_tail_rms_mm']:.1f} mm")
    f = result["feet"]
    print(f"floor: found within {f['floor_error_mm_max']:.1f} mm; lowest point {f['lowest_mm_min']:.1f} mm (feet {f['lowest_foot_mm_min']:.1f} mm); slide "
          f"{f['slide_before_mm_median']:.1f} -> {f['slide_after_mm_median']:.2f} mm median, worst {f['slide_after_mm_max']:.2f} mm, "
          f"{f['slide_after_under_2mm_clips']}/{f['clips']} clips under 2 mm; "
          f"hovering contacts {f['hovering_contacts']}; pelvis lowered {f['pelvis_lowered_cm_median']:.1f} cm median, "
          f"{f['pelvis_lowered_cm_max']:.1f} cm worst")
    g = result["ground_mesh"]
    print(f"bumpy ground: lowest foot {g['lowest_foot_mm_min']:.2f} mm above it; {g['contacts_on_bumps']}/{g['contacts_on_floor']} "
          f"contacts on it; slide {g['slide_mm_median']:.2f} mm median, {g['slide_mm_max']:.2f} mm worst")
    print(f"clean clip: change {result['clean_rms_deg_median']:.3f} deg RMS median, worst {result['clean_rms_deg_max']:.3f}")
    print("dropouts, largest error by frame rate: " + ", ".join(f"{k} fps {v:.1f} deg" for k, v in result["dropout_max_deg_by_fps"].items()))
    for c in result["claims"]:
        print(f"  [{'met' if c['met'] else ('--' if c['met'] is None else 'NOT met')}] {c['claim']}: {c['value']} {c['unit']}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--clips", type=int, default=50, help="Bandai Namco clips (default 50)")
    ap.add_argument("--max-frames", type=int, default=600, help="frames used of each clip (default 600)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    corpus = sorted(CORPUS.glob("*.bvh"))
    spread = max(1, len(corpus) // max(args.clips, 1))
    paths = CMU + corpus[::spread] + [p for i, p in enumerate(corpus) if i % spread]  # evenly over the corpus first
    t0 = time.perf_counter()
    cases = run_clips(paths, args.clips, args.max_frames)
    result = summary(*cases, seconds=round(time.perf_counter() - t0, 1))
    result["claims"] = claims(result, cases[0])
    if args.json:
        write_json(result)
    else:
        print_report(result)


if __name__ == "__main__":
    main()
