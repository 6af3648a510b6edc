"""Batch live capture: `python -m humananim capture rig.blend --flock sim --bones Hips,Chest --seconds 5`.

Runs the same session as the Live Capture panel without a window: devices (real ports or their
simulators), calibration in the rig's rest pose, recording for a while with the display step at
the display rate, then the take as a new action in the saved .blend."""

import os
import time

from ..arguments import UsageError, add_input, add_out


def add_commands(sub, add_common_options):
    c = sub.add_parser("capture", help="record a take from capture devices (or their simulators) into a new "
                                       "action")
    add_input(c, help="a .blend or .bvh file with the armature")
    c.add_argument("--flock", metavar="PORT", help="a Flock of Birds on PORT, or 'sim' for its simulator")
    c.add_argument("--birds", default="1", help="FBB addresses of the birds (default 1)")
    c.add_argument("--bones", default="", help="the bone each bird is strapped on, in the order of --birds")
    c.add_argument("--record", default="POSITION/QUATERNION", help="Flock of Birds record format")
    c.add_argument("--glove", metavar="PORT", help="a CyberGlove on PORT, or 'sim' for its simulator")
    c.add_argument("--glove-sensors", choices=("18", "22"), default="18")
    c.add_argument("--hand", choices=("L", "R"), default="R")
    c.add_argument("--vmc", type=int, metavar="UDP_PORT", help="listen for VMC on 127.0.0.1:UDP_PORT")
    c.add_argument("--mvn", metavar="UDP_PORT", help="listen for an Xsens MVN stream on 127.0.0.1:UDP_PORT, or "
                                                    "'sim' for its simulator (on a free port)")
    c.add_argument("--actor", type=int, default=0, help="the MVN character ID that drives the rig (default 0)")
    c.add_argument("--replay", metavar="BVH", help="replay a BVH file as a device")
    c.add_argument("--rate", type=float, default=100.0, help="simulators' samples per second (default 100)")
    c.add_argument("--seconds", type=float, default=3.0, help="how long to record (default 3)")
    c.add_argument("--display-rate", type=float, default=60.0, help="display steps per second (default 60)")
    add_out(c, "capture.blend")
    add_common_options(c)
    return {"capture": cmd_capture}


def cmd_capture(args):
    import bpy
    import numpy as np
    from . import job as capture
    from ..cli import _load
    t0 = time.perf_counter()
    if not (args.flock or args.glove or args.vmc is not None or args.mvn or args.replay):
        raise UsageError("give at least one device: --flock, --glove, --mvn, --vmc or --replay")
    if args.mvn and args.mvn != "sim" and not args.mvn.isdigit():
        raise UsageError(f"--mvn: a UDP port number or 'sim', not '{args.mvn}'")
    if args.seconds <= 0:
        raise UsageError("--seconds must be positive")
    obj, scene, unit = _load(args.file, args.armature, args.scale)
    bpy.context.view_layer.objects.active = obj
    settings = scene.humananim_capture
    settings.devices.clear()
    if args.flock:
        capture.add_device(scene, "FLOCK", name="fob", simulate=args.flock == "sim", port=args.flock,
                           rate=args.rate, birds=args.birds, bones=args.bones, record=args.record)
    if args.glove:
        capture.add_device(scene, "CYBERGLOVE", name="glove", simulate=args.glove == "sim", port=args.glove,
                           rate=args.rate, sensors=args.glove_sensors, hand=args.hand)
    if args.vmc is not None:
        capture.add_device(scene, "VMC", name="vmc", vmc_port=args.vmc)
    if args.mvn:
        capture.add_device(scene, "MVN", name="mvn", simulate=args.mvn == "sim", actor=args.actor,
                           mvn_port=_free_udp_port() if args.mvn == "sim" else int(args.mvn), rate=args.rate)
    if args.replay:
        if not os.path.isfile(args.replay):
            raise UsageError(f"--replay: no such file: {args.replay}")
        capture.add_device(scene, "REPLAY", name="replay", filepath=os.path.abspath(args.replay), rate=0.0)
    live = capture.connect(obj, scene)
    try:
        deadline = time.perf_counter() + 10.0
        while not all(d.seq for d in live.session.devices if d.kind != "vmc") and time.perf_counter() < deadline:
            live.session.pump()
            time.sleep(0.01)
        if live.attach:
            _calibrate_when_every_sensor_reads(live, deadline)  # the performer starts in the rest pose
        live.start_recording(scene)
        period, end = 1.0 / args.display_rate, time.perf_counter() + args.seconds
        steps = 0
        while time.perf_counter() < end:
            live.step(bpy.context)
            steps += 1
            time.sleep(period)
        action, take = live.stop_recording(bpy.context)
        status = live.status()
        latency = float(np.median(live.latency)) if live.latency else None
    finally:
        capture.disconnect()
    if action is None:
        raise UsageError("nothing was recorded: no device sent data")
    out = os.path.abspath(args.out)
    os.makedirs(os.path.dirname(out), exist_ok=True)
    bpy.ops.wm.save_as_mainfile(filepath=out)
    samples = {f"{d}/{c}": take.count((d, c)) for d, c in take.keys}
    summary = {"command": "capture", "file": os.path.abspath(args.file), "armature": obj.name,
               "action": action.name, "samples": samples, "take_seconds": round(take.duration, 3),
               "display_steps": steps, "devices": status,
               "dropped": sum(d["dropped"] for d in status),
               "discarded_bytes": sum(d["discarded_bytes"] for d in status),
               "resyncs": sum(d["resyncs"] for d in status),
               "median_latency_ms": None if latency is None else round(1000 * latency, 3),
               "wrote": [out], "seconds": round(time.perf_counter() - t0, 3)}
    if unit:
        summary["bvh_unit"] = unit
    lines = [f"capture: '{obj.name}' recorded {sum(samples.values())} samples in {take.duration:.2f} s "
             f"into '{action.name}' ({summary['dropped']} dropped)"]
    lines += [f"  {d['name']}: {d['status']}, {d['rate_hz']:.0f} Hz, {d['samples']} samples, {d['dropped']} lost, "
              f"{d['discarded_bytes']} bytes discarded, {d['resyncs']} resyncs"
              + (f", last error: {d['last_error']}" if d["last_error"] else "") for d in status]
    lines += [f"  wrote {out}", f"  took {summary['seconds']:.2f} s"]
    summary["summary"] = "\n".join(lines)
    return summary


def _free_udp_port():
    import socket
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _calibrate_when_every_sensor_reads(live, deadline):
    """Calibrate once every sensor has sent a reading (the birds of one Flock in group mode come in
    one by one at start-up); after the deadline the calibration's own error says which is silent."""
    from ...solver.anatomical_converter import CalibrationError
    while True:
        try:
            return live.calibrate()
        except CalibrationError:
            if time.perf_counter() >= deadline:
                raise
            live.session.pump()
            time.sleep(0.01)
