#!/usr/bin/env python3
"""Latency and CPU share of a live capture session: this tree's device code side by side with
the device code of commit 7a9849e (before issue 30), in one run, plus the Xsens MVN stream.

    PYTHONPATH=<worktree parent> /work/main/.venv/bpy50/bin/python benchmarks/capture.py [--seconds 6] [--rounds 8] [--aa] [--json]

The earlier device code is loaded with `git show 7a9849e:humananim_addon/devices/<file>` into a
temporary package (humananim.humananim_addon.devices_baseline), nothing of it is copied into
the repository. Four configurations run back to back in each of `--rounds` rounds (every other
round in reverse order), `--seconds` each:

- 'baseline': the earlier drivers, simulators and session;
- 'new': this tree's drivers, simulators and session, the same devices;
- 'new+mvn': the same plus an Xsens MVN stream (one actor, 23 segments at 60 Hz, on UDP),
  its segments attached to the rig through body roles;
- 'transport at once': both codes' Flock + CyberGlove in one session at the same time, each
  code's on its own simulators (the new code's drive the rig and the right hand, today's the
  left hand; the two swap every round), for the transport figures;
- 'MVN at once': this tree's MVN receiver beside today's Flock + CyberGlove drivers (today's
  simulators) in one session at the same time: MVN drives the rig's body, the glove the right
  hand, the Flock no bone (its records are still shown by every display step), for the MVN
  figure;
- 'sessions at once': two whole sessions at the same time, each in its own process (its own
  Blender, display step and simulators, started with `--worker`): 'new+mvn' and 'baseline'
  (today's device code without MVN). Both start their display steps at the same moment, so the
  records of both meet the same moments of the host's load, while each display step solves only
  its own session: the figures of a session with the MVN stream added against today's.

With `--aa`, three A/A configurations more: 'baseline-again' (today's code once more, back to
back), 'A/A transport at once' (today's code on both sides at once, latency and transport) and
'A/A sessions at once' (today's session in both processes): the same statistics of today's code
against itself, the spread the measurement has by itself.

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
transport part alone (leaving the simulator to decoded in the reader thread) for every record
decoded, applied or not (a record decoded late is seldom the newest at the next display step,
so the applied ones alone would hide the transport's tail); the display step's own time; the
CPU share of this process (reader threads, pump and display steps) over the run, process CPU
seconds / wall seconds (1.0 = one core). Records are matched to the ticks that sent them by
content (the simulators' motion is a known function of the tick), searched from the last tick
sent before the record was decoded.

Claims, new over today's, aim no worse (ratio <= 1.10): latency median and CPU share, the
median over the rounds of that round's ratio (a round runs its configurations back to back, so
a change of the host's load hits both sides of a ratio); latency p99, the p99 of every round's
records pooled over the p99 of today's, with a 90 % interval from resampling the rounds (one
round's p99 is its ~20 latest records, and on a shared host their ratio spans 0.5-2 for the
same code); transport median and p99 from 'transport at once', where every tick of one code
meets the same moment of the host's load as the other's (back to back, the transport tail is
mostly the host's scheduling during whichever seconds a configuration drew), the median of the
rounds' ratios and the pooled p99 with its interval. With MVN added: its latency p99 in ms;
the same above its sampling floor (0.99 of its 16.7 ms sample period, which any p99 holds
whatever the code: a 60 Hz stream shown by a 60 Hz display waits up to a frame) over today's
Flock + CyberGlove p99 above theirs (0.99 of 8.3 ms), aim no worse (<= 1.10): what the code
adds to the wait, MVN's path (socket read, datagram parse, shown by the display step) against
today's. It is measured in 'MVN at once', both sides' records pooled over the rounds with a
90 % interval from resampling the rounds; its A/A is the same statistic of today's Flock +
CyberGlove against the same code beside it ('A/A transport at once', both above 0.99 of 8.3
ms). Back to back ('new+mvn' against 'baseline', a different moment of the host's load and
the display step solving 23 more segments) it is reported without aim, beside the Flock +
CyberGlove p99 with MVN in the session over today's without it, and the display step's CPU
time per step with MVN over without (the segments' solve on the rig, which every device of
the session waits for).

The session with the MVN stream added against today's session without it, aim no worse (<=
1.10), all from 'sessions at once': the display step's own CPU time per step (what
LiveCapture.step measures of itself with the thread's CPU clock, not the benchmark's
bookkeeping around it: its matching of 26 channels' records against 3 would count as the
step's) and the CPU share of the whole session (process CPU seconds / wall seconds), each the
median of the rounds' ratios with a 90 % interval from resampling the rounds; the Flock +
CyberGlove latency p99, every round's records pooled, with its interval. With `--aa` the same
figures of today's session against itself. The JSON holds every round's ratio of every figure
(`ratios_by_round`).
"""

import argparse
import contextlib
import dataclasses
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
AT_ONCE, AA_AT_ONCE = "transport at once", "A/A transport at once"
MVN_AT_ONCE = "MVN at once"
SESSIONS_AT_ONCE, AA_SESSIONS_AT_ONCE = "sessions at once", "A/A sessions at once"
CONFIGS = ("baseline", "new", "new+mvn", AT_ONCE, MVN_AT_ONCE, SESSIONS_AT_ONCE)
AGAIN = "baseline-again"  # today's code once more: the A/A comparison of the back-to-back runs
NEW_AT_ONCE, TODAY_AT_ONCE = ("new (at once)", False), ("today's (at once)", True)
AA_SIDES = (("today's (A/A at once)", True), ("today's again (A/A at once)", True))
# (name, configuration) of the two sessions run at once, each in its own process
MVN_SESSION, TODAY_SESSION = ("new+mvn (sessions at once)", "new+mvn"), ("today's (sessions at once)", "baseline")
AA_SESSIONS = (("today's (A/A sessions at once)", "baseline"), ("today's again (A/A sessions at once)", "baseline"))
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

if config.startswith("baseline"):
    register(baseline_dir)
    fob = importlib.import_module(%(name)r + ".fob")
    cg = importlib.import_module(%(name)r + ".cyberglove")
    f = stamped(fob.FlockSimulator(birds=(1, 2), rate=%(rate)r))
    g = stamped(cg.CyberGloveSimulator(sensors=22, rate=%(rate)r))
else:
    from humananim.humananim_addon.devices import sim_fob, sim_glove, sim_mvn
    f = stamped(sim_fob.FlockSimulator(birds=(1, 2), rate=%(rate)r))
    g = stamped(sim_glove.CyberGloveSimulator(sensors=22, rate=%(rate)r))
if config.endswith("+mvn"):  # the MVN sender is this tree's (today's code has none)
    from humananim.humananim_addon.devices import sim_mvn
    m = sim_mvn.MVNSender(port=mvn_port, actors=(0,), rate=%(mvn_rate)r).start()
else:
    m = None
print(json.dumps({"fob": f.port, "glove": g.port}), flush=True)
sys.stdin.readline()
if m is not None:
    m.stop()
log = {"fob": f.sent, "glove": g.sent, "dropped_bytes": f.dropped_bytes + g.dropped_bytes,
       "mvn": [[a, c, t, s] for (a, c), (t, s) in m.sent.items()] if m is not None else []}
f.stop(); g.stop()
print(json.dumps(log), flush=True)
"""


def extract_baseline():
    """Today's device code (commit 7a9849e) in a temporary folder, for the comparison."""
    directory = tempfile.mkdtemp(prefix="humananim-devices-baseline-")
    files = subprocess.run(["git", "-C", REPO, "ls-tree", "--name-only", BASELINE_COMMIT, "humananim_addon/devices/"],
                           capture_output=True, text=True, check=True).stdout.split()
    for path in files:
        text = subprocess.run(["git", "-C", REPO, "show", f"{BASELINE_COMMIT}:{path}"], capture_output=True,
                              text=True, check=True).stdout
        with open(os.path.join(directory, os.path.basename(path)), "w") as f:
            f.write(text)
    return directory


def register_baseline(directory):
    """Today's device code as a package beside this tree's (humananim...devices_baseline)."""
    namespace = {}
    exec(LOADER % {"name": BASELINE_PACKAGE}, namespace)
    namespace["register"](directory)


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


def _start_sim(code, baseline_dir, mvn_port):
    """The simulators of `code` ('baseline': today's, or this tree's; 'new+mvn' adds the MVN
    sender) in their own process; returns (process, ports)."""
    sim = subprocess.Popen([sys.executable, "-c", SIM_SCRIPT % {"rate": RATE, "mvn_rate": MVN_RATE,
                                                               "name": BASELINE_PACKAGE},
                            code, baseline_dir, str(mvn_port)],
                           stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=dict(os.environ))
    return sim, json.loads(sim.stdout.readline())


def _stop_sim(sim):
    """The simulator's log: when each tick left it."""
    sim.stdin.write("\n")
    sim.stdin.flush()
    log = json.loads(sim.stdout.readline())
    sim.wait(10)
    return log


def _todays_device(item):
    """Today's driver for a device of the benchmark (Flock of Birds or CyberGlove)."""
    if item.kind == "FLOCK":
        base_fob = importlib.import_module(BASELINE_PACKAGE + ".fob")
        return base_fob.FlockOfBirds(item.name, item.port, item.baud, birds=(1, 2), record=item.record,
                                     settle=0.3), None
    base_glove = importlib.import_module(BASELINE_PACKAGE + ".cyberglove")
    return base_glove.CyberGlove(item.name, item.port, item.baud, sensors=22, hand=item.hand), None


def _session(devices, build_today, session=None):
    """A live session on the CMU clip's armature with `devices` [(kind, settings)], calibrated;
    `build_today(item)` says which are built with today's drivers, `session` replaces this
    tree's Session class. Returns (live, decoded): `decoded` receives every record the readers
    decode (a list append in their push, the same for every driver)."""
    import bpy
    from humananim.humananim_addon.capture import job as capture
    from humananim.humananim_addon.bvh_import import import_bvh
    patched = {"build_device": capture.build_device, "Session": capture.Session}
    capture.build_device = lambda item: _todays_device(item) if build_today(item) else patched["build_device"](item)
    capture.Session = session or capture.Session
    try:
        bpy.ops.wm.read_homefile(use_empty=True)
        obj, _, _ = import_bvh(_clip())
        bpy.context.view_layer.objects.active = obj
        for kind, settings in devices:
            capture.add_device(bpy.context.scene, kind, **settings)
        live = capture.connect(obj, bpy.context.scene)
    finally:
        for k, v in patched.items():
            setattr(capture, k, v)
    end = time.perf_counter() + 15
    while not set(live.attach) <= set(live.session.pose_readings()) and time.perf_counter() < end:
        live.session.pump()
        time.sleep(0.01)
    live.calibrate()
    decoded = []
    for device in live.session.devices:
        def push_many(items, push=device.buffer.push_many):
            decoded.extend(items)
            push(items)
        device.buffer.push_many = push_many
    return live, decoded


def _display(live, seconds):
    """The display step at 60 Hz for `seconds`, as the modal operator runs it. Returns (applied
    [(key, sample, time applied)], step durations, start, end)."""
    import bpy
    applied, steps, last_seq = [], [], {}
    wall0 = next_t = time.perf_counter()
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
    return applied, steps, wall0, time.perf_counter()


def _figures(out, latency):
    for kind, values in latency.items():
        v = np.array(values) * 1000
        out[f"{kind}_records_{'decoded' if kind.endswith('transport') else 'applied'}"] = int(len(v))
        out[f"{kind}_latency_median_ms"] = round(float(np.median(v)), 3) if len(v) else None
        out[f"{kind}_latency_p99_ms"] = round(float(np.percentile(v, 99)), 3) if len(v) else None
        out[f"{kind}_latency_ms"] = v  # every record's, for the p99s pooled over the rounds (not in the JSON)
    return out


FLOCK = dict(birds="1,2", record="POSITION/QUATERNION")


def run_config(config, seconds, baseline_dir, start=None):
    """One configuration's session, measured for `seconds`; `start()`, when given, is called
    once the session is calibrated and returns when the display steps may begin."""
    from humananim.humananim_addon.capture import job as capture
    today = config in ("baseline", AGAIN)
    mvn_port = _free_udp_port()
    sim, ports = _start_sim("baseline" if today else config, baseline_dir, mvn_port)
    try:
        devices = [("FLOCK", dict(FLOCK, name="fob", port=ports["fob"], bones="Hips, LeftWrist")),
                   ("CYBERGLOVE", dict(name="glove", port=ports["glove"], sensors="22", hand="R"))]
        if config == "new+mvn":
            devices.append(("MVN", dict(name="mvn", mvn_port=mvn_port)))
        # today's: the earlier drivers and session behind this tree's display step
        live, decoded = _session(devices, lambda item: today,
                                 importlib.import_module(BASELINE_PACKAGE + ".session").Session if today else None)
        threads = [t for t in threading.enumerate() if t.name.startswith("humananim-capture")]
        if start is not None:
            start()
        thread_cpu0 = sum(_thread_cpu(t) for t in threads)
        main0 = time.thread_time()
        cpu0 = time.process_time()
        steps0 = len(live.step_cpu)
        applied, steps, wall0, end = _display(live, seconds)
        own_cpu = [cpu for cpu, _ in list(live.step_cpu)[steps0:]]  # what the step measured of itself
        cpu, wall = time.process_time() - cpu0, end - wall0
        main_cpu = time.thread_time() - main0
        thread_cpu = sum(_thread_cpu(t) for t in threads) - thread_cpu0
        status = live.status()
        capture.disconnect()
    finally:
        log = _stop_sim(sim)
    latency = _latencies(applied, [s for s in decoded if wall0 <= s.time <= end], log)
    steps = np.array(steps) * 1000
    out = {"config": config, "seconds": round(wall, 2), "cpu_share": round(cpu / wall, 4),
           "cpu_share_readers_and_pump": round(thread_cpu / wall, 4), "cpu_share_display_steps": round(main_cpu / wall, 4),
           "step_median_ms": round(float(np.median(steps)), 3), "step_p99_ms": round(float(np.percentile(steps, 99)), 3),
           "step_cpu_ms": round(1000 * main_cpu / max(1, len(steps)), 3),
           "step_own_cpu_ms": round(1000 * float(np.mean(own_cpu)), 3) if own_cpu else None,
           "dropped_samples": int(sum(d["dropped"] for d in status)), "line_dropped_bytes": int(log["dropped_bytes"])}
    return _figures(out, latency)


def run_at_once(sides, seconds, baseline_dir):
    """Both sides' Flock + CyberGlove in one session at the same time, each on its own
    simulators: every tick of one side meets the same moment of the host's load as the other
    side's. `sides`: (name, today's code?) twice; returns each side's transport figures."""
    from humananim.humananim_addon.capture import job as capture
    sims = [_start_sim("baseline" if today else "new", baseline_dir, 0) for _, today in sides]
    logs = []
    try:
        devices = []
        for i, (_, ports) in enumerate(sims):  # the first side drives the rig, the second its left hand
            devices += [("FLOCK", dict(FLOCK, name=f"fob{i}", port=ports["fob"], bones="Hips, LeftWrist" if i == 0 else "")),
                        ("CYBERGLOVE", dict(name=f"glove{i}", port=ports["glove"], sensors="22", hand="RL"[i]))]
        live, decoded = _session(devices, lambda item: sides[int(item.name[-1])][1])
        applied, _, wall0, end = _display(live, seconds)
        capture.disconnect()
    finally:
        logs = [_stop_sim(sim) for sim, _ in sims]
    out = []
    for i, ((name, _), log) in enumerate(zip(sides, logs)):
        mine = [dataclasses.replace(s, device=s.device[:-1]) for s in decoded
                if s.device[-1] == str(i) and wall0 <= s.time <= end]
        shown = [(key, dataclasses.replace(s, device=s.device[:-1]), t) for key, s, t in applied
                 if s.device[-1] == str(i)]
        latency = _latencies(shown, mine, log)
        out.append(_figures({"config": name, "seconds": round(end - wall0, 2)},
                            {k: latency[k] for k in ("devices", "devices_transport")}))
    return out


def run_sessions_at_once(sides, seconds, baseline_dir):
    """Two whole sessions at the same time, each in its own process (its own Blender, display
    step and simulators): `sides` ((name, configuration) twice, e.g. this tree's session with the
    MVN stream added and today's without it). Both start their 60 Hz display steps at the same
    moment, so every record of one meets the same moments of the host's load as the other's,
    while each display step solves only its own session. Returns each side's run_config figures."""
    workers = [subprocess.Popen([sys.executable, os.path.abspath(__file__), "--worker", config, "--seconds",
                                 str(seconds), "--baseline-dir", baseline_dir],
                                stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=dict(os.environ))
               for _, config in sides]
    try:
        for w in workers:
            _worker_line(w, "ready")
        start = time.perf_counter() + 0.5  # the monotonic clock is the host's: both processes read the same
        for w in workers:
            w.stdin.write(f"{start!r}\n")
            w.stdin.flush()
        out = [json.loads(_worker_line(w, "result")) for w in workers]
    finally:
        for w in workers:
            if w.poll() is None:
                w.kill()
            w.wait(10)
    for (name, _), r in zip(sides, out):
        r["config"] = name
        for k in [k for k in r if k.endswith("_latency_ms")]:
            r[k] = np.array(r[k])
    return out


def _worker_line(worker, tag):
    """The text after '@@<tag> ' on the worker's stdout (Blender may print other lines there)."""
    for line in worker.stdout:
        if line.startswith(f"@@{tag}"):
            return line[len(tag) + 2:].strip()
    raise RuntimeError(f"the benchmark's worker ended before '{tag}' (exit code {worker.wait(10)})")


def worker(config, seconds, baseline_dir):
    """One side of run_sessions_at_once: `config`'s session, its display steps from the moment
    the parent writes on stdin; the figures as one JSON line on stdout (every record's latency
    too, for the p99s pooled over the rounds)."""
    os.environ.setdefault("BLENDER_USER_RESOURCES", "/tmp/humananim-bench-user")
    import humananim
    register_baseline(baseline_dir)
    humananim.register()
    stdout = sys.stdout

    def start():
        print("@@ready", file=stdout, flush=True)
        at = float(sys.stdin.readline())
        time.sleep(max(0.0, at - time.perf_counter()))
    try:
        with contextlib.redirect_stdout(sys.stderr):
            r = run_config(config, seconds, baseline_dir, start)
    finally:
        humananim.unregister()
    r = {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in r.items()}
    print("@@result " + json.dumps(r), file=stdout, flush=True)


def run_mvn_at_once(seconds, baseline_dir):
    """This tree's MVN receiver beside today's Flock + CyberGlove drivers in one session at the
    same time (MVN drives the rig's body, the glove its right hand, the Flock no bone): both
    sides' records meet the same moments of the host's load and the same display steps, which
    solve MVN's segments for both. Returns the MVN and the Flock + CyberGlove latency figures."""
    from humananim.humananim_addon.capture import job as capture
    mvn_port = _free_udp_port()
    sim, ports = _start_sim("baseline+mvn", baseline_dir, mvn_port)
    try:
        devices = [("FLOCK", dict(FLOCK, name="fob", port=ports["fob"], bones="")),
                   ("CYBERGLOVE", dict(name="glove", port=ports["glove"], sensors="22", hand="R")),
                   ("MVN", dict(name="mvn", mvn_port=mvn_port))]
        live, decoded = _session(devices, lambda item: item.kind != "MVN")
        applied, _, wall0, end = _display(live, seconds)
        capture.disconnect()
    finally:
        log = _stop_sim(sim)
    latency = _latencies(applied, [s for s in decoded if wall0 <= s.time <= end], log)
    return _figures({"config": MVN_AT_ONCE, "seconds": round(end - wall0, 2)}, latency)


def _fob_tick(position, bird, near):
    """The simulator tick whose bird position is this one (within one 14-bit step), searched
    from `near` outwards."""
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


def _latencies(applied, decoded, log):
    """Seconds from a record leaving its simulator to the display step that applied it
    ('devices': Flock + glove, the devices of the baseline; 'mvn'), and to its decoding in the
    reader thread ('devices_transport', 'mvn_transport') for every record decoded, applied or
    not: a record decoded late is seldom the newest when the next display step comes, so the
    applied ones alone would leave out the transport's tail."""
    sent = {"fob": dict(log["fob"]), "glove": dict(log["glove"])}
    ticks = {d: np.array(sorted(sent[d])) for d in sent}
    times = {d: np.array([sent[d][t] for t in ticks[d]]) for d in sent}
    mvn_sent = {(a, c): s for a, c, _, s in log["mvn"]}
    out = {"devices": [], "mvn": [], "devices_transport": [], "mvn_transport": []}
    for kind, samples in (("", [(s, t) for _, s, t in applied]), ("_transport", [(s, None) for s in decoded])):
        for s, t_applied in samples:
            if s.device == "mvn":
                t_sent = mvn_sent.get((s.data["actor"], s.data["sample_counter"]))
            else:  # its tick by content, searched from the last tick sent before it was decoded
                i = max(0, int(np.searchsorted(times[s.device], s.time)) - 1)
                near = int(ticks[s.device][i]) if len(ticks[s.device]) else 0
                if s.device == "fob":
                    tick = _fob_tick(s.data["position"], int(s.channel[4:]), near)
                else:
                    tick = _glove_tick(s.data["raw"], near)
                t_sent = sent[s.device].get(tick)
            if t_sent is not None:
                out[("mvn" if s.device == "mvn" else "devices") + kind].append(
                    (s.time if t_applied is None else t_applied) - t_sent)
    return out


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seconds", type=float, default=6.0)
    p.add_argument("--rounds", type=int, default=8)
    p.add_argument("--aa", action="store_true",
                   help="today's device code a second time in every round (A/A: the measurement's own spread)")
    p.add_argument("--json", action="store_true")
    p.add_argument("--worker", help=argparse.SUPPRESS)  # one side of 'sessions at once' (run_sessions_at_once)
    p.add_argument("--baseline-dir", help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.worker:
        return worker(args.worker, args.seconds, args.baseline_dir)
    configs = CONFIGS + (AGAIN, AA_AT_ONCE, AA_SESSIONS_AT_ONCE) if args.aa else CONFIGS
    configs = tuple(sorted(configs, key=ORDER.index))
    os.environ.setdefault("BLENDER_USER_RESOURCES", "/tmp/humananim-bench-user")
    import humananim
    baseline_dir = extract_baseline()
    register_baseline(baseline_dir)
    humananim.register()
    runs = []
    try:
        with contextlib.redirect_stdout(sys.stderr):  # Blender's BVH importer prints; stdout is the JSON
            for k in range(args.rounds):  # every other round in reverse: no configuration always runs first
                for config in configs if k % 2 == 0 else configs[::-1]:
                    if config in (SESSIONS_AT_ONCE, AA_SESSIONS_AT_ONCE):  # started first: every other round
                        sides = (MVN_SESSION, TODAY_SESSION) if config == SESSIONS_AT_ONCE else AA_SESSIONS
                        sides = sides if k % 2 == 0 else sides[::-1]
                        runs += [dict(r, round=k) for r in run_sessions_at_once(sides, args.seconds, baseline_dir)]
                    elif config in (AT_ONCE, AA_AT_ONCE):  # the sides swap places every round
                        sides = (NEW_AT_ONCE, TODAY_AT_ONCE) if config == AT_ONCE else AA_SIDES
                        sides = sides if k % 2 == 0 else sides[::-1]
                        runs += [dict(r, round=k) for r in run_at_once(sides, args.seconds, baseline_dir)]
                    elif config == MVN_AT_ONCE:
                        runs.append(dict(run_mvn_at_once(args.seconds, baseline_dir), round=k))
                    else:
                        runs.append(dict(run_config(config, args.seconds, baseline_dir), round=k))
    finally:
        humananim.unregister()
        shutil.rmtree(baseline_dir, ignore_errors=True)
    claims = claims_of(runs)
    for r in runs:
        for kind in ("devices", "mvn", "devices_transport", "mvn_transport"):
            r.pop(f"{kind}_latency_ms", None)
    out = result("capture", claims, baseline_commit=BASELINE_COMMIT, device_rate_hz=RATE,
                 mvn_rate_hz=MVN_RATE, display_rate_hz=DISPLAY, load_average=os.getloadavg(),
                 ratios_by_round=ratios_by_round(runs), runs=runs)
    if args.json:
        emit(out)
        return
    for r in runs:
        if r["config"] == MVN_AT_ONCE:
            print(f"{r['round']} {r['config']:>27}: MVN p99 {r['mvn_latency_p99_ms']} ms ({r['mvn_records_applied']} "
                  f"records), today's devices p99 {r['devices_latency_p99_ms']} ms ({r['devices_records_applied']}), "
                  f"MVN transport p99 {r['mvn_transport_latency_p99_ms']} ms")
            continue
        if "cpu_share" not in r:
            print(f"{r['round']} {r['config']:>27}: transport median {r['devices_transport_latency_median_ms']} ms, "
                  f"p99 {r['devices_transport_latency_p99_ms']} ms ({r['devices_transport_records_decoded']} records)")
            continue
        print(f"{r['round']} {r['config']:>27}: latency median {r['devices_latency_median_ms']} ms, p99 "
              f"{r['devices_latency_p99_ms']} ms ({r['devices_records_applied']} records), transport median "
              f"{r['devices_transport_latency_median_ms']} ms, p99 {r['devices_transport_latency_p99_ms']} ms "
              f"({r['devices_transport_records_decoded']} records), step {r['step_median_ms']} ms, CPU "
              f"{100 * r['cpu_share']:.1f} %" + (f"; MVN median {r['mvn_latency_median_ms']} ms, p99 "
                                                 f"{r['mvn_latency_p99_ms']} ms" if r.get("mvn_records_applied") else "")
              + f", dropped {r['dropped_samples']}")
    for c in out["claims"]:
        aim = f" (aim {c['aim']}: {'met' if c['met'] else 'NOT met'})" if c["aim"] else ""
        print(f"  {c['claim']}: {c['value']} {c['unit']}{aim}")
    for key, ratios in out["ratios_by_round"].items():
        print(f"  {key}: {ratios}")


ORDER = ("baseline", "new", AGAIN, "new+mvn", AT_ONCE, MVN_AT_ONCE, AA_AT_ONCE, SESSIONS_AT_ONCE, AA_SESSIONS_AT_ONCE)

COMPARED = (("latency median (Flock + CyberGlove)", "devices_latency_median_ms"),
            ("latency p99 (Flock + CyberGlove)", "devices_latency_p99_ms"),
            ("CPU share of the session", "cpu_share"),
            ("transport median (back to back)", "devices_transport_latency_median_ms"),
            ("transport p99 (back to back)", "devices_transport_latency_p99_ms"))


def round_ratios(runs, key, config="new", over="baseline", over_key=None):
    """Each round's `config` / `over` figure (`key`, or `over_key` for the `over` side): the
    configurations of a round ran back to back, so a change of the host's load hits both sides
    of a ratio."""
    by_round = {}
    for r in runs:
        by_round.setdefault(r["round"], {})[r["config"]] = r
    return [round(rs[config][key] / rs[over][over_key or key], 3) for _, rs in sorted(by_round.items())
            if config in rs and over in rs and rs[config].get(key) and rs[over].get(over_key or key)]


def round_ratio(runs, key, config="new", over="baseline", over_key=None):
    """The median over the rounds of each round's ratio."""
    return round(float(np.median(round_ratios(runs, key, config, over, over_key))), 3)


def round_ratio_interval(runs, key, config, over, resamples=2000, seed=30):
    """The median of the rounds' ratios and its 90 % interval from resampling the rounds."""
    ratios = np.array(round_ratios(runs, key, config, over))
    rng = np.random.default_rng(seed)
    boot = [np.median(ratios[rng.integers(0, len(ratios), len(ratios))]) for _ in range(resamples)]
    return round(float(np.median(ratios)), 3), [round(float(x), 3) for x in np.percentile(boot, [5, 95])]


POOLED = (("latency p99 (Flock + CyberGlove)", "devices_latency"),
          ("transport p99 (every record)", "devices_transport_latency"))


def pooled_p99_ratio(runs, kind, config="new", over="baseline", over_kind=None, floors=(0.0, 0.0),
                     resamples=2000, seed=30):
    """The p99 of every record of `config` (figure `kind`) in every round over the same of `over`
    (figure `over_kind`, else `kind`), each less its `floors` (ms): a p99 over thousands of
    records, not one round's few hundred behind its 99th percentile; and its 90 % interval from
    resampling the rounds (a round's two sides kept together)."""
    over_kind = over_kind or kind
    by_round = {}
    for r in runs:
        for side, k in (("a", kind), ("b", over_kind)):
            if r["config"] == (config if side == "a" else over) and f"{k}_ms" in r:
                by_round.setdefault(r["round"], {})[side] = r[f"{k}_ms"]
    rounds = [rs for _, rs in sorted(by_round.items()) if "a" in rs and "b" in rs]

    def ratio(chosen):
        return ((np.percentile(np.concatenate([rs["a"] for rs in chosen]), 99) - floors[0])
                / (np.percentile(np.concatenate([rs["b"] for rs in chosen]), 99) - floors[1]))
    rng = np.random.default_rng(seed)
    boot = [ratio([rounds[i] for i in rng.integers(0, len(rounds), len(rounds))]) for _ in range(resamples)]
    return round(float(ratio(rounds)), 3), [round(float(x), 3) for x in np.percentile(boot, [5, 95])]


def ratios_by_round(runs):
    """Every round's ratio of every compared figure: new / today's, today's again / today's
    (A/A) when it ran, and the transport measured at once: the spread one round's ratio has."""
    out = {f"{key}: new / today's": round_ratios(runs, key) for _, key in COMPARED}
    if any(r["config"] == AGAIN for r in runs):
        out.update({f"{key}: A/A": round_ratios(runs, key, AGAIN) for _, key in COMPARED})
    out["MVN above its floor / today's devices above theirs, at once"] = round_ratios(
        runs, "mvn_above_floor_ms", MVN_AT_ONCE, MVN_AT_ONCE, "devices_above_floor_ms")
    if any(r["config"] == AA_SIDES[0][0] for r in runs):
        out["devices above their floor: A/A, at once"] = round_ratios(runs, "devices_above_floor_ms", AA_SIDES[1][0],
                                                                       AA_SIDES[0][0])
    for key in ("step_own_cpu_ms", "cpu_share", "devices_latency_p99_ms"):
        out[f"{key}: new+mvn / today's, sessions at once"] = round_ratios(runs, key, MVN_SESSION[0], TODAY_SESSION[0])
        if any(r["config"] == AA_SESSIONS[0][0] for r in runs):
            out[f"{key}: A/A, sessions at once"] = round_ratios(runs, key, AA_SESSIONS[1][0], AA_SESSIONS[0][0])
    for key in ("devices_transport_latency_median_ms", "devices_transport_latency_p99_ms"):
        out[f"{key}: new / today's, at once"] = round_ratios(runs, key, NEW_AT_ONCE[0], TODAY_AT_ONCE[0])
        if any(r["config"] == AA_SIDES[0][0] for r in runs):
            out[f"{key}: A/A, at once"] = round_ratios(runs, key, AA_SIDES[1][0], AA_SIDES[0][0])
    return out


MVN_FLOOR_MS, DEVICES_FLOOR_MS = 0.99 * 1000.0 / MVN_RATE, 0.99 * 1000.0 / RATE


def above_floor(run, kind, rate):
    """A run's latency p99 above its sampling floor, ms: a display step meets a sample up to one
    sample period after it arrived (the phases sweep evenly), so 0.99 of that period is in any
    p99; the rest is transport, the display step and their tails."""
    p99 = run.get(f"{kind}_latency_p99_ms")
    return None if p99 is None else p99 - 0.99 * 1000.0 / rate


def claims_of(runs):
    for r in runs:
        if r.get("devices_latency_p99_ms") is not None:
            r["devices_above_floor_ms"] = above_floor(r, "devices", RATE)
            r["mvn_above_floor_ms"] = above_floor(r, "mvn", MVN_RATE)
    out = []
    for text, key in COMPARED[:1] + COMPARED[2:3]:  # every round's ratio is steady
        value = round_ratio(runs, key)
        out.append(claim(f"{text}, new / today's device code, median of the rounds' ratios", value, "ratio",
                         "<= 1.10", value <= 1.10))
    # one round's p99 is its ~20 latest records: the p99 of all rounds' records
    value, (low, high) = pooled_p99_ratio(runs, "devices_latency")
    out.append(claim(f"latency p99 (Flock + CyberGlove), new / today's device code, every round's records pooled "
                     f"(90 % interval over the rounds {low}-{high})", value, "ratio", "<= 1.10", value <= 1.10))
    new, today = NEW_AT_ONCE[0], TODAY_AT_ONCE[0]
    value = round_ratio(runs, "devices_transport_latency_median_ms", new, today)
    out.append(claim("transport median (record leaving the simulator to decoded, every record; both sides at once), "
                     "new / today's device code, median of the rounds' ratios", value, "ratio", "<= 1.10",
                     value <= 1.10))
    value, (low, high) = pooled_p99_ratio(runs, "devices_transport_latency", new, today)
    out.append(claim(f"transport p99 (every record; both sides at once), new / today's device code, every round's "
                     f"records pooled (90 % interval over the rounds {low}-{high})", value, "ratio", "<= 1.10",
                     value <= 1.10))
    if any(r["config"] == AGAIN for r in runs):  # the measurements' own spread: no aim, the yardsticks
        for text, kind in (("latency p99", "devices_latency"), ("transport p99 (back to back)", "devices_transport_latency")):
            value, (low, high) = pooled_p99_ratio(runs, kind, AGAIN)
            out.append(claim(f"A/A: {text}, today's device code run again / today's, pooled (90 % interval "
                             f"{low}-{high})", value, "ratio"))
    if any(r["config"] == AA_SIDES[0][0] for r in runs):
        value, (low, high) = pooled_p99_ratio(runs, "devices_transport_latency", AA_SIDES[1][0], AA_SIDES[0][0])
        out.append(claim(f"A/A: transport p99 (both sides at once), today's device code / itself, pooled (90 % "
                         f"interval {low}-{high})", value, "ratio"))
    mvn = [r for r in runs if r.get("mvn_latency_p99_ms")]
    mvn_p99 = round(float(np.median([r["mvn_latency_p99_ms"] for r in mvn])), 2)
    out.append(claim("with the MVN stream added (23 segments at 60 Hz): MVN latency p99", mvn_p99, "ms"))
    floors = (MVN_FLOOR_MS, DEVICES_FLOOR_MS)
    value, (low, high) = pooled_p99_ratio(runs, "mvn_latency", MVN_AT_ONCE, MVN_AT_ONCE, "devices_latency", floors)
    out.append(claim(f"MVN latency p99 above its sampling floor (0.99 x 16.7 ms) / today's Flock + CyberGlove p99 "
                     f"above theirs (0.99 x 8.3 ms), this tree's MVN receiver and today's drivers in one session at "
                     f"once, every round's records pooled (90 % interval over the rounds {low}-{high})",
                     value, "ratio", "<= 1.10", value <= 1.10))
    value, (low, high) = pooled_p99_ratio(runs, "mvn_transport_latency", MVN_AT_ONCE, MVN_AT_ONCE,
                                          "devices_transport_latency")
    out.append(claim(f"its transport part: MVN transport p99 (datagram sent to read from the socket) / today's Flock + "
                     f"CyberGlove transport p99, at once, pooled (90 % interval {low}-{high})", value, "ratio"))
    if any(r["config"] == AA_SIDES[0][0] for r in runs):
        floors = (DEVICES_FLOOR_MS, DEVICES_FLOOR_MS)
        value, (low, high) = pooled_p99_ratio(runs, "devices_latency", AA_SIDES[1][0], AA_SIDES[0][0], None, floors)
        out.append(claim(f"A/A of the MVN claim: today's Flock + CyberGlove latency p99 above its floor / the same "
                         f"code's beside it in one session at once, pooled (90 % interval {low}-{high})",
                         value, "ratio"))
    value, (low, high) = pooled_p99_ratio(runs, "mvn_latency", "new+mvn", "baseline", "devices_latency",
                                          (MVN_FLOOR_MS, DEVICES_FLOOR_MS))
    out.append(claim(f"the same MVN figure back to back (new+mvn's session / today's without MVN, a different "
                     f"moment of the host's load), pooled (90 % interval {low}-{high})", value, "ratio"))
    value, (low, high) = pooled_p99_ratio(runs, "devices_latency", "new+mvn")
    out.append(claim(f"with the MVN stream added: Flock + CyberGlove latency p99 / today's device code without it, "
                     f"back to back, pooled (90 % interval {low}-{high})", value, "ratio"))
    value = round_ratio(runs, "step_cpu_ms", "new+mvn", "new")
    out.append(claim("with the MVN stream added: the display step's CPU time (its 23 segments solved on the rig) / "
                     "the same session without it, median of the rounds' ratios", value, "ratio"))
    if any(r["config"] == MVN_SESSION[0] for r in runs):
        mvn, today = MVN_SESSION[0], TODAY_SESSION[0]
        value, (low, high) = round_ratio_interval(runs, "step_own_cpu_ms", mvn, today)
        out.append(claim(f"with the MVN stream added: the display step's CPU time per step / today's session without "
                         f"it (today's device code), two sessions at once in two processes, median of the rounds' "
                         f"ratios (90 % interval over the rounds {low}-{high})", value, "ratio", "<= 1.10",
                         value <= 1.10))
        value, (low, high) = round_ratio_interval(runs, "cpu_share", mvn, today)
        out.append(claim(f"with the MVN stream added: CPU share of the session (readers, pump and display steps) / "
                         f"today's session without it, two sessions at once, median of the rounds' ratios (90 % "
                         f"interval {low}-{high})", value, "ratio", "<= 1.10", value <= 1.10))
        value, (low, high) = round_ratio_interval(runs, "devices_latency_median_ms", mvn, today)
        out.append(claim(f"with the MVN stream added: Flock + CyberGlove latency median / today's session without it, "
                         f"two sessions at once in two processes, median of the rounds' ratios (90 % interval over "
                         f"the rounds {low}-{high})", value, "ratio", "<= 1.10", value <= 1.10))
        value, (low, high) = pooled_p99_ratio(runs, "devices_latency", mvn, today)
        out.append(claim(f"with the MVN stream added: Flock + CyberGlove latency p99 / today's session without it, two "
                         f"sessions at once in two processes, every round's records pooled (90 % interval over the "
                         f"rounds {low}-{high})", value, "ratio", "<= 1.10", value <= 1.10))
        value, (low, high) = round_ratio_interval(runs, "step_own_cpu_ms", "new+mvn", "baseline")
        out.append(claim(f"the same CPU figure back to back (new+mvn / today's without MVN, one process), median of "
                         f"the rounds' ratios (90 % interval {low}-{high})", value, "ratio"))
    if any(r["config"] == AA_SESSIONS[0][0] for r in runs):
        again, today = AA_SESSIONS[1][0], AA_SESSIONS[0][0]
        value, (low, high) = round_ratio_interval(runs, "step_own_cpu_ms", again, today)
        out.append(claim(f"A/A of the two-session claims: today's display step CPU time / today's, two sessions at "
                         f"once (90 % interval {low}-{high})", value, "ratio"))
        value, (low, high) = round_ratio_interval(runs, "cpu_share", again, today)
        out.append(claim(f"A/A of the two-session claims: today's CPU share / today's, two sessions at once (90 % "
                         f"interval {low}-{high})", value, "ratio"))
        value, (low, high) = round_ratio_interval(runs, "devices_latency_median_ms", again, today)
        out.append(claim(f"A/A of the two-session claims: today's Flock + CyberGlove latency median / today's, two "
                         f"sessions at once (90 % interval {low}-{high})", value, "ratio"))
        value, (low, high) = pooled_p99_ratio(runs, "devices_latency", again, today)
        out.append(claim(f"A/A of the two-session claims: today's Flock + CyberGlove latency p99 / today's, two "
                         f"sessions at once, pooled (90 % interval {low}-{high})", value, "ratio"))
    return out


if __name__ == "__main__":
    main()
