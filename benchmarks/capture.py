#!/usr/bin/env python3
"""Latency and CPU share of a live capture session: this tree's device code side by side with
the device code of commit 7a9849e (before issue 30), in one run, plus the Xsens MVN stream.

    PYTHONPATH=<worktree parent> /work/main/.venv/bpy50/bin/python benchmarks/capture.py [--seconds 6] [--rounds 8] [--json]

The earlier device code is loaded with `git show 7a9849e:humananim_addon/devices/<file>` into a
temporary package (humananim.humananim_addon.devices_baseline), nothing of it is copied into
the repository. Three configurations run back to back in each of `--rounds` rounds (every other
round in reverse order), `--seconds` each:

- 'baseline': the earlier drivers, simulators and session;
- 'new': this tree's drivers, simulators and session, the same devices;
- 'new+mvn': the same plus an Xsens MVN stream (one actor, 23 segments at 60 Hz, on UDP),
  its segments attached to the rig through body roles.

Devices: a Flock of Birds (2 birds, group mode, POSITION/QUATERNION at 120 Hz) and a CyberGlove
(22 sensors at 120 Hz), their simulators (and the MVN sender) in a separate process on
pseudo-terminals, logging when each record leaves them: a serial tick when its bytes are
written to the line, an MVN sample when its datagrams are sent (after the simulator built
them: its encoding stands in for the device's, not for our code). This process runs the
session as Blender does: the drivers read the ports through pyserial in their reader threads,
the pump thread drains them, and the display step (capture.LIVE.step, what the modal operator
calls on each timer event) runs at 60 Hz on the CMU clip's armature, after a calibration in the
rest pose. The display step is this tree's for every configuration (only the device code
differs).

The display's clock runs a little slow (one MVN sample period per round: 0.3 % at 6 s), as a
timer and a device's crystal never agree: within every round the display steps meet the
devices' ticks at every phase, so a round's p99 is that of a performer's session, not of one
phase drawn at random (with a fixed phase per round, a p99 moved by up to a sample period from
round to round).

Measured per configuration: latency from a record leaving its simulator to the pose being
applied, for every record applied (median and 99th percentile; it includes waiting for the next
display step: a display step shows a sample up to one sample period after it arrived); the
transport part alone (leaving the simulator to decoded in the reader thread); the display
step's own time; the CPU share of this process (reader threads, pump and display steps) over
the run, process CPU seconds / wall seconds (1.0 = one core). Records are matched to the ticks
that sent them by content (the simulators' motion is a known function of the tick).

Claims, each the median over the rounds of that round's ratio (a round runs its configurations
back to back, so a change of the host's load hits both sides of a ratio): the new code's
latency (median, p99), CPU share and transport over the baseline's, aim no worse (ratio <= 1.10,
the runs' noise). With MVN added: its latency p99 in ms; the same above its sampling floor
(0.99 of its 16.7 ms sample period, which any p99 holds whatever the code: a 60 Hz stream shown
by a 60 Hz display waits up to a frame) over today's Flock + CyberGlove p99 above theirs (0.99
of 8.3 ms), aim no worse (<= 1.10): what the code adds to the wait, MVN's path against today's;
and the Flock + CyberGlove p99 with MVN in the session over today's without it (the display
step solving 23 more segments).
"""

import argparse
import contextlib
import importlib
import importlib.util
import json
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import threading
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from machine import claim, emit, result  # noqa: E402

RATE = 120.0
MVN_RATE = 60.0
DISPLAY = 60.0
SWEEP = 1.0 / min(RATE, MVN_RATE)
CONFIGS = ("baseline", "new", "new+mvn")
BASELINE_COMMIT = "7a9849e"
BASELINE_PACKAGE = "humananim.humananim_addon.devices_baseline"
HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)

LOADER = r"""
import importlib.util, sys
def register(directory, name=%(name)r):
    import humananim.humananim_addon
    spec = importlib.util.spec_from_file_location(name, directory + "/__init__.py",
                                                  submodule_search_locations=[directory])
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module
"""

SIM_SCRIPT = LOADER + r"""
import json, sys, importlib, time
config, baseline_dir, mvn_port = sys.argv[1], sys.argv[2], int(sys.argv[3])

def stamped(sim):
    # a streamed tick is logged when its bytes are written to the line, after the simulator
    # encoded them (each simulator's encoding is its own, not the device code's)
    tick, send, written = sim.tick, sim.send, []
    def send_stamped(data):
        written.append(time.perf_counter())
        send(data)
    def tick_stamped(now):
        written.clear()
        tick(now)
        if written and sim.sent:
            sim.sent[-1] = (sim.sent[-1][0], written[0])
    sim.send, sim.tick = send_stamped, tick_stamped
    return sim.start()

if config == "baseline":
    register(baseline_dir)
    fob = importlib.import_module(%(name)r + ".fob")
    cg = importlib.import_module(%(name)r + ".cyberglove")
    f = stamped(fob.FlockSimulator(birds=(1, 2), rate=%(rate)r))
    g = stamped(cg.CyberGloveSimulator(sensors=22, rate=%(rate)r))
else:
    from humananim.humananim_addon.devices import sim_fob, sim_glove, sim_mvn
    f = stamped(sim_fob.FlockSimulator(birds=(1, 2), rate=%(rate)r))
    g = stamped(sim_glove.CyberGloveSimulator(sensors=22, rate=%(rate)r))
m = sim_mvn.MVNSender(port=mvn_port, actors=(0,), rate=%(mvn_rate)r).start() if config == "new+mvn" else None
print(json.dumps({"fob": f.port, "glove": g.port}), flush=True)
sys.stdin.readline()
if m is not None:
    m.stop()
log = {"fob": f.sent, "glove": g.sent, "dropped_bytes": f.dropped_bytes + g.dropped_bytes,
       "mvn": [[a, c, t, s] for (a, c), (t, s) in m.sent.items()] if m is not None else []}
f.stop(); g.stop()
print(json.dumps(log), flush=True)
"""


def load_baseline():
    """Today's device code (commit 7a9849e) as a package beside this tree's, for the comparison."""
    directory = tempfile.mkdtemp(prefix="humananim-devices-baseline-")
    files = subprocess.run(["git", "-C", REPO, "ls-tree", "--name-only", BASELINE_COMMIT, "humananim_addon/devices/"],
                           capture_output=True, text=True, check=True).stdout.split()
    for path in files:
        text = subprocess.run(["git", "-C", REPO, "show", f"{BASELINE_COMMIT}:{path}"], capture_output=True,
                              text=True, check=True).stdout
        with open(os.path.join(directory, os.path.basename(path)), "w") as f:
            f.write(text)
    namespace = {}
    exec(LOADER % {"name": BASELINE_PACKAGE}, namespace)
    namespace["register"](directory)
    return directory


def _thread_cpu(thread):
    try:
        return time.clock_gettime(time.pthread_getcpuclockid(thread.ident))
    except (AttributeError, OSError):
        return 0.0


def _clip():
    return os.path.join(REPO, "humananim_addon", "data", "mocap", "cmu_131_01.bvh")


def _free_udp_port():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def run_config(config, seconds, baseline_dir):
    import bpy
    from humananim.humananim_addon.capture import job as capture
    from humananim.humananim_addon.bvh_import import import_bvh

    mvn_port = _free_udp_port()
    sim = subprocess.Popen([sys.executable, "-c", SIM_SCRIPT % {"rate": RATE, "mvn_rate": MVN_RATE,
                                                               "name": BASELINE_PACKAGE},
                            config, baseline_dir, str(mvn_port)],
                           stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=dict(os.environ))
    ports = json.loads(sim.stdout.readline())
    patched = {}
    if config == "baseline":  # the earlier drivers and session behind this tree's display step
        base_fob = importlib.import_module(BASELINE_PACKAGE + ".fob")
        base_glove = importlib.import_module(BASELINE_PACKAGE + ".cyberglove")
        base_session = importlib.import_module(BASELINE_PACKAGE + ".session")

        def build_device(item):
            if item.kind == "FLOCK":
                return base_fob.FlockOfBirds(item.name, item.port, item.baud, birds=(1, 2), record=item.record,
                                             settle=0.3), None
            return base_glove.CyberGlove(item.name, item.port, item.baud, sensors=22, hand="R"), None
        patched = {"build_device": capture.build_device, "Session": capture.Session}
        capture.build_device, capture.Session = build_device, base_session.Session
    try:
        bpy.ops.wm.read_homefile(use_empty=True)
        obj, _, _ = import_bvh(_clip())
        bpy.context.view_layer.objects.active = obj
        scene = bpy.context.scene
        capture.add_device(scene, "FLOCK", name="fob", port=ports["fob"], birds="1,2", bones="Hips, LeftWrist",
                           record="POSITION/QUATERNION")
        capture.add_device(scene, "CYBERGLOVE", name="glove", port=ports["glove"], sensors="22", hand="R")
        if config == "new+mvn":
            capture.add_device(scene, "MVN", name="mvn", mvn_port=mvn_port)
        live = capture.connect(obj, scene)
        end = time.perf_counter() + 15
        while not set(live.attach) <= set(live.session.pose_readings()) and time.perf_counter() < end:
            live.session.pump()
            time.sleep(0.01)
        live.calibrate()
        applied, steps, last_seq = [], [], {}
        threads = [t for t in threading.enumerate() if t.name.startswith("humananim-capture")]
        thread_cpu0 = sum(_thread_cpu(t) for t in threads)
        main0 = time.thread_time()
        cpu0, wall0 = time.process_time(), time.perf_counter()
        next_t = wall0
        # the display's clock drifts one sample period of the slowest device per round against
        # the devices' clocks (a timer and a device's crystal never agree): every round meets
        # every phase of the ticks against the steps, as a performer does, not one fixed phase
        frame = 1.0 / DISPLAY + SWEEP / (seconds * DISPLAY)
        while time.perf_counter() - wall0 < seconds:
            t = time.perf_counter()
            live.step(bpy.context)
            done = time.perf_counter()
            steps.append(done - t)
            for key, s in live.last_applied.items():
                if s.seq != last_seq.get(key):
                    applied.append((key, s, done))
                    last_seq[key] = s.seq
            next_t += frame
            time.sleep(max(0.0, next_t - time.perf_counter()))
        cpu, wall = time.process_time() - cpu0, time.perf_counter() - wall0
        main_cpu = time.thread_time() - main0
        thread_cpu = sum(_thread_cpu(t) for t in threads) - thread_cpu0
        status = live.status()
        capture.disconnect()
    finally:
        for k, v in patched.items():
            setattr(capture, k, v)
        sim.stdin.write("\n")
        sim.stdin.flush()
        log = json.loads(sim.stdout.readline())
        sim.wait(10)
    latency = _latencies(applied, log)
    steps = np.array(steps) * 1000
    out = {"config": config, "seconds": round(wall, 2), "cpu_share": round(cpu / wall, 4),
           "cpu_share_readers_and_pump": round(thread_cpu / wall, 4), "cpu_share_display_steps": round(main_cpu / wall, 4),
           "step_median_ms": round(float(np.median(steps)), 3), "step_p99_ms": round(float(np.percentile(steps, 99)), 3),
           "dropped_samples": int(sum(d["dropped"] for d in status)), "line_dropped_bytes": int(log["dropped_bytes"])}
    for kind, values in latency.items():
        v = np.array(values) * 1000
        out[f"{kind}_records_applied"] = int(len(v))
        out[f"{kind}_latency_median_ms"] = round(float(np.median(v)), 3) if len(v) else None
        out[f"{kind}_latency_p99_ms"] = round(float(np.percentile(v, 99)), 3) if len(v) else None
    return out


def _fob_tick(position, bird, near):
    """The simulator tick whose bird position is this one (within one 14-bit step)."""
    from humananim.humananim_addon.devices.sim_fob import default_motion
    res = 36 * 0.0254 * 4 / 32768 + 1e-9
    for t in sorted(range(max(0, near - 400), near + 400), key=lambda t: abs(t - near)):
        if np.all(np.abs(default_motion(bird, t / RATE)[0] - position) <= res):
            return t
    return None


def _glove_tick(raw, near):
    from humananim.humananim_addon.devices.sim_glove import default_glove_motion
    for t in sorted(range(max(0, near - 400), near + 400), key=lambda t: abs(t - near)):
        if np.array_equal(default_glove_motion(t / RATE, 22).astype(float), raw):
            return t
    return None


def _latencies(applied, log):
    """Seconds from a record leaving its simulator to the display step that applied it, for the
    devices of the baseline (Flock + glove, 'devices') and for MVN."""
    sent = {"fob": dict(log["fob"]), "glove": dict(log["glove"])}
    mvn_sent = {(a, c): s for a, c, _, s in log["mvn"]}
    near = {"fob": 0, "glove": 0}
    out = {"devices": [], "mvn": [], "devices_transport": [], "mvn_transport": []}
    for key, s, t_applied in applied:
        device = key[0]
        if device == "mvn":
            t_sent = mvn_sent.get((s.data["actor"], s.data["sample_counter"]))
            if t_sent is not None:
                out["mvn"].append(t_applied - t_sent)
                out["mvn_transport"].append(s.time - t_sent)
            continue
        if device == "fob":
            tick = _fob_tick(s.data["position"], int(key[1][4:]), near["fob"])
        else:
            tick = _glove_tick(s.data["raw"], near["glove"])
        if tick is None or tick not in sent[device]:
            continue
        near[device] = tick
        out["devices"].append(t_applied - sent[device][tick])
        out["devices_transport"].append(s.time - sent[device][tick])
    return out


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seconds", type=float, default=6.0)
    p.add_argument("--rounds", type=int, default=8)
    p.add_argument("--json", action="store_true")
    args = p.parse_args(argv)
    os.environ.setdefault("BLENDER_USER_RESOURCES", "/tmp/humananim-bench-user")
    import humananim
    baseline_dir = load_baseline()
    humananim.register()
    runs = []
    try:
        with contextlib.redirect_stdout(sys.stderr):  # Blender's BVH importer prints; stdout is the JSON
            for k in range(args.rounds):  # every other round in reverse: no configuration always runs first
                for config in CONFIGS if k % 2 == 0 else CONFIGS[::-1]:
                    runs.append(dict(run_config(config, args.seconds, baseline_dir), round=k))
    finally:
        humananim.unregister()
        shutil.rmtree(baseline_dir, ignore_errors=True)
    out = result("capture", claims_of(runs), baseline_commit=BASELINE_COMMIT, device_rate_hz=RATE,
                 mvn_rate_hz=MVN_RATE, display_rate_hz=DISPLAY, load_average=os.getloadavg(), runs=runs)
    if args.json:
        emit(out)
        return
    for r in runs:
        print(f"{r['config']:>9}: latency median {r['devices_latency_median_ms']} ms, p99 {r['devices_latency_p99_ms']} ms"
              f" ({r['devices_records_applied']} records), step {r['step_median_ms']} ms, CPU {100 * r['cpu_share']:.1f} %"
              + (f"; MVN median {r['mvn_latency_median_ms']} ms, p99 {r['mvn_latency_p99_ms']} ms"
                 if r.get("mvn_records_applied") else "") + f", dropped {r['dropped_samples']}")
    for c in out["claims"]:
        aim = f" (aim {c['aim']}: {'met' if c['met'] else 'NOT met'})" if c["aim"] else ""
        print(f"  {c['claim']}: {c['value']} {c['unit']}{aim}")


def round_ratio(runs, key, config="new", over="baseline", over_key=None):
    """The median over the rounds of each round's `config` / `over` figure (`key`, or
    `over_key` for the `over` side): the configurations of one round ran back to back, so a
    change of the host's load hits both sides of a ratio."""
    by_round = {}
    for r in runs:
        by_round.setdefault(r["round"], {})[r["config"]] = r
    ratios = [rs[config][key] / rs[over][over_key or key] for rs in by_round.values()
              if config in rs and over in rs and rs[config].get(key) and rs[over].get(over_key or key)]
    return round(float(np.median(ratios)), 3)


def above_floor(run, kind, rate):
    """A run's latency p99 above its sampling floor, ms: a display step meets a sample up to one
    sample period after it arrived (the phases sweep evenly), so 0.99 of that period is in any
    p99; the rest is transport, the display step and their tails."""
    p99 = run.get(f"{kind}_latency_p99_ms")
    return None if p99 is None else p99 - 0.99 * 1000.0 / rate


def claims_of(runs):
    for r in runs:
        r["devices_above_floor_ms"] = above_floor(r, "devices", RATE)
        r["mvn_above_floor_ms"] = above_floor(r, "mvn", MVN_RATE)
    out = []
    for text, key in (("latency median (Flock + CyberGlove)", "devices_latency_median_ms"),
                      ("latency p99 (Flock + CyberGlove)", "devices_latency_p99_ms"),
                      ("CPU share of the session", "cpu_share"),
                      ("transport median (record leaving the simulator to decoded)",
                       "devices_transport_latency_median_ms"),
                      ("transport p99", "devices_transport_latency_p99_ms")):
        value = round_ratio(runs, key)
        out.append(claim(f"{text}, new / today's device code, median of the rounds' ratios", value, "ratio",
                         "<= 1.10", value <= 1.10))
    mvn = [r for r in runs if r.get("mvn_latency_p99_ms")]
    mvn_p99 = round(float(np.median([r["mvn_latency_p99_ms"] for r in mvn])), 2)
    out.append(claim("with the MVN stream added (23 segments at 60 Hz): MVN latency p99", mvn_p99, "ms"))
    value = round_ratio(runs, "mvn_above_floor_ms", "new+mvn", "baseline", "devices_above_floor_ms")
    out.append(claim("MVN latency p99 above its sampling floor (0.99 x 16.7 ms) / today's Flock + CyberGlove p99 "
                     "above theirs (0.99 x 8.3 ms), median of the rounds' ratios", value, "ratio", "<= 1.10",
                     value <= 1.10))
    value = round_ratio(runs, "devices_latency_p99_ms", "new+mvn")
    out.append(claim("with the MVN stream added: Flock + CyberGlove latency p99 / today's device code without it",
                     value, "ratio"))
    return out


if __name__ == "__main__":
    main()
