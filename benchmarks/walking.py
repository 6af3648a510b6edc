#!/usr/bin/env python3
"""Speed and realism of the procedural walk (solver/walking, Boulic's model).

    python3 benchmarks/walking.py          # a table
    python3 benchmarks/walking.py --json   # one JSON object, also benchmarks/results/walking.json

Speed: wall milliseconds per generated second of walk (median of 3 runs) for the Rigify metarig's
skeleton (159 bones) and the CMU skeleton (31 bones) along a 10 m S curve at 1.3 m/s, at 24 and
120 fps.

Realism, in the same run: the CMU clip 131_01 ("start, walk, stop", 120 Hz) is measured by the
contact detector (motion_control.contacts, thresholds raised for the clip's floor) for its
walking cycles (cycles faster than 0.6 m/s): cycle length and duration, double-support share,
pelvis vertical and lateral oscillation (peak to peak). The generated walk of the same skeleton at
the clip's measured speed is measured by the same code (solver/walking/clip.gait) and set beside
it, with eq. 2-5's cycle length for the clip's own relative velocity.

Against Bandai Namco's corpus (../shared/data/mocap/bandai-namco-1 beside the repository, when it
is there): every `walk_*` clip measured by clip.measure_gait (Zeni's gait events, no floor
threshold), the median of its cycles within 0.15 m/s of 1.0 and 1.3 m/s; the generated walk on
Bandai's skeleton (from walk_normal_001's standing frame) at those speeds, measured by the same
function: pelvis sway and double support over the corpus's, and the cycle length's error against
eq. 2-5 at the asked speed.

`--json` prints one object and writes benchmarks/results/walking.json (machine.py's contract):
the speed figures, the generated walk's cycle length, duration and double-support share over
the clip's, measured side by side, and the corpus ratios.
"""

import argparse
import statistics
import sys
import time
from pathlib import Path as FilePath

import numpy as np

ROOT = FilePath(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests" / "solver"))

from humananim.solver.walking import Path, clip, metrics, model, walk  # noqa: E402
from machine import claim, emit, result  # noqa: E402

CMU = ROOT / "humananim_addon" / "data" / "mocap" / "cmu_131_01.bvh"
CORPUS = ROOT.parent / "shared" / "data" / "mocap" / "bandai-namco-1"


def s_curve(length=10.0, amplitude=1.0, n=200):
    x = np.linspace(0.0, length, n)
    return np.column_stack((x, amplitude * np.sin(2 * np.pi * x / length), np.zeros(n)))


def speed(sk, fps, repeats=3):
    path = Path.from_points(s_curve())
    times, walked = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        walked = walk(sk, path, speed=1.3, fps=fps)
        times.append(time.perf_counter() - t0)
    seconds = float(walked.times[-1] - walked.times[0])
    return 1000 * statistics.median(times) / seconds, seconds


def comparison(sk, tr):
    ref = clip.gait(sk, tr, min_speed=0.6)
    if ref["cycles"] == 0:
        raise SystemExit("no walking cycle found in the clip")
    v = ref["speed_m_s"]
    r = walk(sk, Path.from_points([[0, 0, 0], [12, 0, 0]]), speed=v, fps=tr.fps)
    gen = clip.gait(r.body.skeleton, r.trajectories, min_speed=0.6 * v)
    gen["exact_double_support_share"] = metrics.double_support_share(r)  # from the walk's own supports
    ht = r.body.ht
    return ref, gen, ht, v


def corpus(speeds=(1.0, 1.3)):
    """{speed: (sway ratio, double-support ratio, cycle-law error)} of the generated walk against
    the corpus's walking cycles at the same speed; {} without the corpus."""
    walks = sorted(CORPUS.glob("dataset-1_walk_*_00[12].bvh"))
    if not walks:
        return {}
    cycles = []
    for f in walks:
        sk, tr = clip.load_bvh(str(f))
        cycles += clip.measure_gait(sk, tr)["per_cycle"]
    sk, tr = clip.load_bvh(str(CORPUS / "dataset-1_walk_normal_001.bvh"))
    out = {}
    for v in speeds:
        near = [c for c in cycles if abs(c["speed_m_s"] - v) < 0.15]
        r = walk(sk, Path.from_points([[0, 0, 0], [8, 0, 0]]), speed=v, fps=30.0, reference=tr)
        g = [c for c in clip.measure_gait(sk, r.trajectories, min_speed=0.8 * v)["per_cycle"]
             if abs(c["speed_m_s"] / v - 1) < 0.1]
        mean = {k: float(np.mean([c[k] for c in g])) for k in ("pelvis_lateral_m", "double_support_share", "length_m")}
        ref = {k: float(np.median([c[k] for c in near])) for k in ("pelvis_lateral_m", "double_support_share")}
        law = float(model.relative_cycle_length(v / r.body.ht) * r.body.ht)
        out[v] = (mean["pelvis_lateral_m"] / ref["pelvis_lateral_m"],
                  mean["double_support_share"] / ref["double_support_share"], abs(mean["length_m"] / law - 1))
    return out


def claims(out):
    found = [claim(f"{'Rigify metarig (159 bones)' if name == 'metarig' else 'CMU skeleton (31 bones)'} "
                   f"at {fps} fps: time per generated second of walk", out[f"{name}_{fps}fps_ms_per_walk_second"],
                   "ms wall") for name in ("metarig", "cmu") for fps in (24, 120)]
    at = f"at the clip's speed ({out['speed_m_s']:.2f} m/s)"
    found += [
        claim(f"generated walk {at}: cycle length over CMU 131_01's",
              out["generated_cycle_length_m"] / out["cmu_cycle_length_m"], "ratio"),
        claim(f"generated walk {at}: cycle duration over CMU 131_01's",
              out["generated_cycle_duration_s"] / out["cmu_cycle_duration_s"], "ratio"),
        claim(f"generated walk {at}: double-support share (CMU 131_01: {out['cmu_double_support_share']:.2f})",
              out["generated_double_support_share"], "share"),
        claim(f"generated walk {at}: pelvis vertical oscillation over CMU 131_01's",
              out["generated_pelvis_vertical_m"] / out["cmu_pelvis_vertical_m"], "ratio"),
    ]
    for v, (sway, ds, law) in out.get("corpus", {}).items():
        found += [
            claim(f"Bandai skeleton at {v} m/s: pelvis sway over the corpus's walks'", sway, "ratio",
                  "within 25 %", abs(sway - 1) <= 0.25),
            claim(f"Bandai skeleton at {v} m/s: double support (Zeni's events) over the corpus's walks'", ds,
                  "ratio", "within 25 %", abs(ds - 1) <= 0.25),
            claim(f"Bandai skeleton at {v} m/s: cycle length's error against eq. 2-5", law, "share",
                  "within 5 %", law <= 0.05),
        ]
    return found


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args(argv)
    from walking_cases import rig
    cmu_sk, cmu_tr = clip.load_bvh(str(CMU))
    out = {}
    for name, sk in (("metarig", rig("metarig")), ("cmu", cmu_sk)):
        for fps in (24, 120):
            ms, seconds = speed(sk, fps)
            out[f"{name}_{fps}fps_ms_per_walk_second"] = ms
    ref, gen, ht, v = comparison(cmu_sk, cmu_tr)
    rv = ref["length_m"] / (ref["duration_s"] * ht)
    out.update({
        "cmu_walk_cycles": ref["cycles"], "speed_m_s": v, "thigh_height_m": ht,
        "cmu_cycle_length_m": ref["length_m"], "generated_cycle_length_m": gen["length_m"],
        "eq_2_5_cycle_length_m": float(model.relative_cycle_length(rv) * ht),
        "cmu_cycle_duration_s": ref["duration_s"], "generated_cycle_duration_s": gen["duration_s"],
        "cmu_double_support_share": ref["double_support_share"],
        "generated_double_support_share": gen["double_support_share"],
        "generated_double_support_share_exact": gen["exact_double_support_share"],
        "eq_2_6_double_support_share": float(2 * model.walk_durations(gen["duration_s"])[2] / gen["duration_s"]),
        "cmu_pelvis_vertical_m": ref["pelvis_vertical_m"], "generated_pelvis_vertical_m": gen["pelvis_vertical_m"],
        "cmu_pelvis_lateral_m": ref["pelvis_lateral_m"], "generated_pelvis_lateral_m": gen["pelvis_lateral_m"],
    })
    out["corpus"] = corpus()
    if args.json:
        emit(result("walking", claims(out), **{k: (round(v, 4) if isinstance(v, float) else v)
                                               for k, v in out.items()}))
        return
    print("ms per generated second of walk (10 m S curve at 1.3 m/s):")
    for name in ("metarig", "cmu"):
        print(f"  {name:8s} 24 fps {out[f'{name}_24fps_ms_per_walk_second']:7.1f}   "
              f"120 fps {out[f'{name}_120fps_ms_per_walk_second']:7.1f}")
    print(f"CMU 131_01 walking cycles ({ref['cycles']}) against the generated walk at {v:.2f} m/s "
          f"(Ht {ht:.3f} m):")
    print(f"  {'':28s} {'CMU 131_01':>11s} {'generated':>11s} {'model':>9s}")
    print(f"  {'cycle length (m)':28s} {ref['length_m']:11.3f} {gen['length_m']:11.3f} "
          f"{out['eq_2_5_cycle_length_m']:9.3f}")
    print(f"  {'cycle duration (s)':28s} {ref['duration_s']:11.3f} {gen['duration_s']:11.3f}")
    print(f"  {'double-support share':28s} {ref['double_support_share']:11.3f} "
          f"{gen['double_support_share']:11.3f} {out['eq_2_6_double_support_share']:9.3f}")
    print(f"  {'  (exact, from the supports)':28s} {'':11s} {gen['exact_double_support_share']:11.3f}")
    print(f"  {'pelvis vertical p-p (m)':28s} {ref['pelvis_vertical_m']:11.3f} {gen['pelvis_vertical_m']:11.3f}")
    print(f"  {'pelvis lateral p-p (m)':28s} {ref['pelvis_lateral_m']:11.3f} {gen['pelvis_lateral_m']:11.3f}")
    for v, (sway, ds, law) in out["corpus"].items():
        print(f"Bandai skeleton at {v} m/s against the corpus's walks: sway {sway:.2f}x, double support "
              f"{ds:.2f}x (Zeni), cycle {100 * law:.1f} % off eq. 2-5")


if __name__ == "__main__":
    main()
