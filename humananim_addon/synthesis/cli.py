"""Batch motion synthesis: `python -m humananim synthesize clip.blend --queue still --queue kick:connect`.

Runs the same bridge code as the Motion Queue panel, saves a .blend (--out) and prints a summary
(--json: one object)."""

import os
import re
import time

from ..arguments import NON_NEGATIVE, POSITIVE, UsageError, add_arrows, add_collider, add_input, add_out, add_output

_QUEUE = re.compile(r"^(?P<action>.+?)(?:@(?P<start>-?\d+)-(?P<end>-?\d+))?(?::(?P<mode>blend|connect|inertialize))?"
                    r"(?::now=(?P<now>\d+))?$", re.IGNORECASE)


def add_commands(sub, add_common_options):
    c = sub.add_parser("synthesize", help="motion synthesis: join actions (blend, connect, inertialize) with "
                                          "planted feet kept, optionally with dynamic reactions; writes a new action")
    add_input(c)
    c.add_argument("--queue", action="append", default=[], metavar="ACTION[@START-END][:MODE][:now=FRAME]",
                   help="an action to queue (in order; MODE blend (default), connect or inertialize; now=FRAME "
                        "interrupts the motion so far at that frame, counted from its start); repeatable; "
                        "default: the NLA strips, else the active action")
    c.add_argument("--initial", type=NON_NEGATIVE, default=0.25, help="initial phase of every action, s (default 0.25)")
    c.add_argument("--terminal", type=NON_NEGATIVE, default=0.25, help="terminal phase of every action, s (default 0.25)")
    c.add_argument("--react", action="store_true", help="dynamic control with protective steps, falls, recovery")
    add_arrows(c, "--impulse", "a push (N s, world axes) on a bone for --react; repeatable")
    add_collider(c, "an armature or mesh object in the .blend that collides with the character for --react "
                    "(the puncher of the thesis's scene)")
    c.add_argument("--collide-mass", type=NON_NEGATIVE, default=0.0,
                   help="the collider's mass in kg (a fist with the arm behind it: a few kg); 0: kinematic, it "
                        "keeps pushing (default 0)")
    c.add_argument("--step-speed", type=POSITIVE, nargs=2, metavar=("MIN", "MAX"), default=(0.5, 1.0),
                   help="eq. 3.6 root speeds, m/s (default 0.5 1.0)")
    c.add_argument("--step-acceleration", type=POSITIVE, default=10.0, help="eq. 3.6 root acceleration, m/s^2")
    add_output(c)
    add_out(c, "synthesis.blend")
    add_common_options(c)
    return {"synthesize": cmd_synthesize}


def parse_queue(text):
    m = _QUEUE.match(text.strip())
    if not m:
        raise UsageError(f"--queue '{text}': expected ACTION[@START-END][:blend|connect|inertialize][:now=FRAME]")
    rng = (int(m["start"]), int(m["end"])) if m["start"] is not None else None
    return m["action"], rng, (m["mode"] or "blend").upper(), (int(m["now"]) if m["now"] is not None else None)


def _check_range(text, action, rng):
    first, last = action.frame_range
    if rng[1] <= rng[0] or rng[0] < first or rng[1] > last:
        raise UsageError(f"--queue {text!r}: frames {rng[0]}-{rng[1]} are not a range inside '{action.name}' "
                         f"(frames {first:g}-{last:g})")


def cmd_synthesize(args):
    import bpy
    from ...solver.progress import run_to_end
    from . import job as synthesis
    from ..cli import load_rig, parse_arrow
    from ..motion_control.cli import add_impulse_from_vector
    t0 = time.perf_counter()
    obj, scene, unit = load_rig(args)
    props = scene.humananim_synthesis
    props.entries.clear()
    if args.queue:
        for text in args.queue:
            name, rng, mode, now = parse_queue(text)
            act = bpy.data.actions.get(name)
            if act is None:
                raise UsageError(f"--queue: no action named '{name}' (actions: "
                                 f"{', '.join(a.name for a in bpy.data.actions) or 'none'})")
            if rng is not None:
                _check_range(text, act, rng)
            synthesis.add_entry(scene, act, mode, rng, now)
    elif obj.animation_data and any(t.strips for t in obj.animation_data.nla_tracks):
        synthesis.entries_from_nla(obj, scene)
    elif obj.animation_data and obj.animation_data.action:
        synthesis.add_entry(scene, obj.animation_data.action)
    else:
        raise UsageError("nothing to synthesize: pass --queue ACTION ...")
    for e in props.entries:
        e.initial_duration, e.terminal_duration = args.initial, args.terminal
    props.reactions = args.react
    props.step_speed_min, props.step_speed_max = args.step_speed
    props.step_acceleration = args.step_acceleration
    scene.humananim.output = args.output
    for text in args.impulse:
        frame, bone, vector, seconds = parse_arrow(text, obj, "--impulse", 0.0)
        add_impulse_from_vector(obj, scene, bone, frame, vector, seconds)
    if args.collide:
        other = bpy.data.objects.get(args.collide)
        if other is None:
            raise UsageError(f"--collide: no object named '{args.collide}'")
        control = scene.humananim_control
        control.collider, control.collider_radius = other, args.collide_radius
        control.collider_mass = max(0.0, args.collide_mass)
    summary = run_to_end(synthesis.run(obj, scene))
    from ..cli import save_blend
    out = save_blend(args.out, summary, obj)
    summary.update(command="synthesize", file=os.path.abspath(args.file), armature=obj.name, wrote=[out],
                   seconds=round(time.perf_counter() - t0, 3))
    if unit:
        summary["bvh_unit"] = unit
    summary["summary"] = text_summary(summary)
    return summary


def text_summary(s):
    lines = [f"synthesize: '{s['armature']}' {s['frames']} frames from {len(s['source_actions'])} actions "
             f"({s['accepted']} joined, {s['rejected']} rejected)"]
    for r in s["requests"]:
        if not r["accepted"]:
            lines.append(f"  {r['action']} ({r['mode']}): {r['reason']}")
        elif r["mode"] == "start":
            lines.append(f"  {r['action']}: first")
        else:
            lines.append(f"  {r['action']} ({r['mode']}, {r['when']}): from frame {r['start_frame']:g}, planted "
                         f"foot moved {r['max_planted_slide_mm']:.2f} mm, acceleration {r['spike_ratio_angular']:.2f}"
                         f"x of the clips' 99th percentile")
    if "reaction" in s:
        rx = s["reaction"]
        lines.append(f"  reaction: {rx['kind']}" + (f" at frame {rx['frame']:g}" if rx["frame"] is not None else ""))
    lines.append(f"  wrote action '{s['action']}'")
    for path in s["wrote"]:
        lines.append(f"  wrote {path}")
    lines.append(f"  took {s['seconds']:.2f} s")
    return "\n".join(lines)
