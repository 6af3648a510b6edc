"""Transitions between two actions: foot sliding and acceleration spikes of HumanAnim's three modes
(blend, connect, inertialize) beside a plain NLA crossfade of the same two actions, in one run.

Run with a Python that has the bpy module:  python benchmarks/transitions.py [--json] [--clip FILE]

The two actions are sections of one CMU clip (131_01, 120 fps): frames 1-100 and 61-115, both feet
on the ground at the join. The NLA crossfade is Blender's own: the second section on a track above
the first, overlapping by the blend time (0.25 s) with that Blend In, evaluated by the depsgraph.
Measured on each result, over the transition window only:
  * planted foot slide (mm): the largest distance the ankle, ball or toe tip of a foot that is on
    the ground moves within the window (the solver modes: the joined motion's support, where a
    connection's flying foot is off the ground once it starts its step; the NLA result: support
    detected in it with the solver's contact thresholds);
  * acceleration spike: the largest joint angular acceleration in the window over the 99th
    percentile of the two sections' own (1 = no spike above the clips' own), and the same for the
    root's linear acceleration;
  * ms to compute the transition (solver modes).

The claims set each mode's planted-foot slide and angular spike beside the NLA crossfade's, all
measured in the same run. `--json` prints one object and writes benchmarks/results/transitions.json
(machine.py's contract).
"""

import argparse
import os
import tempfile
import time

os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="humananim-bench-"))

import bpy  # noqa: E402
import numpy as np  # noqa: E402

import humananim  # noqa: E402
from humananim.humananim_addon import action_api, actions  # noqa: E402
from humananim.humananim_addon.armature import armature_to_world, skeleton_from_armature  # noqa: E402
from humananim.humananim_addon.bvh_import import import_bvh  # noqa: E402
from humananim.solver import rotations  # noqa: E402
from humananim.solver.motion_control import support_intervals  # noqa: E402
from humananim.solver.skeleton import decompose  # noqa: E402
from humananim.solver.synthesis import from_trajectories, transition  # noqa: E402
from humananim.solver.synthesis.metrics import planted_slide, spike_ratio  # noqa: E402
from humananim.solver.trajectories import Trajectories  # noqa: E402
from machine import claim, emit, result  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
DEFAULT_CLIP = os.path.join(HERE, "..", "humananim_addon", "data", "mocap", "cmu_131_01.bvh")
A, B, BLEND = (1, 100), (61, 115), 0.25


def measure(sk, tr, window, sources, support=None):
    support = support_intervals(sk, tr) if support is None else support
    slide = planted_slide(sk, tr, support, window, inside=True)
    ang, lin = spike_ratio(sk, tr, window, sources)
    return {"foot_slide_mm": round(1000.0 * max(slide.values(), default=0.0), 3),
            "spike_ratio_angular": round(ang, 3), "spike_ratio_linear": round(lin, 3)}


def nla_crossfade(obj, scene, sk, source, fps):
    """Blender's NLA: section A on one track, section B on the track above starting BLEND s before
    A ends with Blend In over the overlap; the evaluated pose bones' bases as trajectories."""
    overlap = int(round(BLEND * fps))
    ad = obj.animation_data
    slot = ad.action_slot if action_api.SLOTTED else None
    ad.action = None
    t1, s1 = action_api.push_to_nla(obj, source, slot, "A", A[0])
    s1.action_frame_start, s1.action_frame_end = A
    s1.frame_start, s1.frame_end = A[0], A[1]
    start_b = A[1] - overlap + 1
    t2, s2 = action_api.push_to_nla(obj, source, slot, "B", start_b)
    s2.action_frame_start, s2.action_frame_end = B
    s2.frame_end = start_b + (B[1] - B[0])
    s2.frame_start = start_b
    s2.blend_in = overlap - 1
    frames = np.arange(A[0], int(s2.frame_end) + 1)
    n, j = len(frames), sk.joint_count
    names = list(sk.names)
    bases = np.empty((n, j, 4, 4))
    buf = np.empty(len(obj.pose.bones) * 16)
    index = [obj.pose.bones.find(b) for b in names]
    for i, f in enumerate(frames):
        scene.frame_set(int(f))
        obj.pose.bones.foreach_get("matrix_basis", buf)
        bases[i] = buf.reshape(-1, 4, 4).transpose(0, 2, 1)[index]
    t, q = decompose(bases)
    tr = Trajectories(frames.astype(float), fps, rotations.make_continuous(q), t * sk.unit_scale,
                      armature_to_world(obj, scene))
    window = (start_b - A[0], A[1] - A[0])
    return tr, window


def claims(out):
    nla = out["nla_crossfade"]
    found = [claim("NLA crossfade (Blender's own): planted foot slide in the transition", nla["foot_slide_mm"], "mm")]
    for mode in ("blend", "connect", "inertialize"):
        m = out[mode]
        found += [
            claim(f"{mode}: planted foot slide in the transition (NLA crossfade: {nla['foot_slide_mm']:.1f} mm)",
                  m["foot_slide_mm"], "mm"),
            claim(f"{mode}: angular acceleration spike over the NLA crossfade's", m["spike_ratio_angular"]
                  / nla["spike_ratio_angular"] if nla["spike_ratio_angular"] else None, "ratio"),
            claim(f"{mode}: time to compute the transition", m["transition_ms"], "ms wall"),
        ]
    return found


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--clip", default=DEFAULT_CLIP)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    humananim.register()
    try:
        bpy.ops.wm.read_homefile(use_empty=True)
        obj, _, _ = import_bvh(args.clip)
        scene = bpy.context.scene
        source = obj.animation_data.action
        sk = skeleton_from_armature(obj, scene)
        ta = actions.read_action(obj, scene, sk, source, frame_range=A)
        tb = actions.read_action(obj, scene, sk, source, frame_range=B)
        a = from_trajectories("A", sk, ta, BLEND, BLEND)
        b = from_trajectories("B", sk, tb, BLEND, BLEND)
        out = {"clip": os.path.basename(args.clip), "fps": ta.fps, "sections": [list(A), list(B)],
               "blend_s": BLEND}
        for mode in ("blend", "connect", "inertialize"):
            t0 = time.perf_counter()
            r = transition(a, b, mode)
            ms = 1000.0 * (time.perf_counter() - t0)
            m = measure(sk, r.trajectories, r.window, [ta, tb], r.support)
            m["transition_ms"] = round(ms, 1)
            m["window_frames"] = int(r.window[1] - r.window[0] + 1)
            out[mode] = m
        tr, window = nla_crossfade(obj, scene, sk, source, ta.fps)
        out["nla_crossfade"] = {**measure(sk, tr, window, [ta, tb]), "window_frames": window[1] - window[0] + 1}
    finally:
        humananim.unregister()
    if args.json:
        emit(result("transitions", claims(out), **out))
        return
    print(f"{out['clip']} sections {A} and {B}, blend {BLEND} s, {out['fps']:.0f} fps")
    print(f"{'mode':<14}{'foot slide mm':>15}{'spike (angular)':>17}{'spike (root)':>14}{'ms':>8}")
    for mode in ("blend", "connect", "inertialize", "nla_crossfade"):
        m = out[mode]
        print(f"{mode:<14}{m['foot_slide_mm']:>15.2f}{m['spike_ratio_angular']:>17.2f}{m['spike_ratio_linear']:>14.2f}"
              f"{m.get('transition_ms', float('nan')):>8.0f}")


if __name__ == "__main__":
    main()
