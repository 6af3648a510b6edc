#!/usr/bin/env python3
"""Speed of the fast plausible cloth (Oshita 2003 ch. 4) on the character's own skinned mesh,
beside Blender's own cloth modifier on the same body and motion, in the same run.

    PYTHONPATH=<dir holding humananim> python benchmarks/cloth.py [--json] [--seconds 2] [--bodies 5000 20000 80000]

The motion: the bundled CMU walk (131_01), re-timed to 30 fps (an NLA strip at scale 1/4). The
bodies: grown over the rig by add_skin_body (metaball capsules on the bones, polygonised at about
5,000, 20,000 and 80,000 triangles, Blender's automatic weights, an Armature modifier), so each
is a closed skinned mesh as an animator has it. The garments:

- the thesis-size skirt: 66 particles (6 rings x 11), 110 coarse faces, smoothing level 2 ->
  1,760 rendered faces;
- a 300-particle coat (12 rings x 25, chest to knees), 550 coarse faces -> 8,800 rendered faces.

Ours collides with the skinned mesh through SkinnedBody (per-bone grids of candidate triangles
in the bones' reference frames, exact distances on the skinned triangles). On the 20,000-triangle
body the skirt also runs with MeshBody (a search structure rebuilt at every pose), the previous
method, for the ratio between the two. Blender's cloth modifier simulates a garment with the same
rendered faces (our smoothed rest surface), its waistband pinned and carried by an Armature
modifier, colliding with the same body (Collision modifier), default quality, stepped frame by
frame as a bake does; its cost is the CPU time with the cloth modifier minus the same frame
stepping without it.

Reported per body and garment: CPU milliseconds per 30 fps frame of our simulation (RK4
integration and constraints), collision (including pushing the rendered surface out of the body)
and smoothing, our total with reading the poses and the body from Blender, the deepest particle
inside the body and the largest mean stretch over the frames, Blender cloth's
ms per frame, and the speed-ups. (The rendered surface's vertices are pushed out of the body
every frame; tests/addon/test_cloth_skinned_body.py measures their depth.) Claims: ours at least 10x faster than Blender's cloth at equal
rendered faces on every body; the collision's cost growing sublinearly with the body's triangle
count (the exponent of the growth from the smallest to the largest body below 1); the thesis
skirt on the 20,000-triangle body at 30 frames a second or more in Preview Cloth (its timer's
tick measured headless, as the modal operator calls it: the frame set, the pose and the skinned
body read from Blender, one frame simulated, the preview mesh written; the first tick, which
builds the body's search grids, is reported apart). Times are CPU time of this process (time.process_time), so other
processes on a shared machine count less; numpy's a + b on two 1,000-float arrays tells how fast
the machine was.
"""

import argparse
import json
import os
import sys
import tempfile
import time

os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="humananim-bench-"))

import numpy as np  # noqa: E402
from machine import numpy_add_us  # noqa: E402  (the contract's machine-speed indicator)

CLIP = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "humananim_addon", "data", "mocap",
                    "cmu_131_01.bvh")


# CPU time of this process (all its threads: Blender's cloth may use several): on a shared
# machine wall-clock time counts the other processes' share too
_clock = time.process_time


def scene_at_30fps(seconds):
    """The CMU walk re-timed to 30 fps through an NLA strip; (armature, scene, last frame)."""
    import bpy
    from humananim.humananim_addon import action_api
    from humananim.humananim_addon.bvh_import import import_bvh
    bpy.ops.wm.read_homefile(use_empty=True)
    arm, _, _ = import_bvh(CLIP)
    scene = bpy.context.scene
    action = arm.animation_data.action
    slot = getattr(arm.animation_data, "action_slot", None)
    arm.animation_data.action = None
    track = arm.animation_data.nla_tracks.new()
    strip = track.strips.new("walk", 1, action)
    if slot is not None and hasattr(strip, "action_slot"):
        strip.action_slot = slot
    strip.scale = 0.25
    scene.render.fps, scene.render.fps_base = 30, 1.0
    last = 1 + int(round(seconds * 30))
    scene.frame_start, scene.frame_end = 1, last
    del action_api
    return arm, scene, last


def best_of(repeat, measure, key):
    """The fastest of `repeat` runs of measure() -> (result dict, extra), by result[key]."""
    runs = [measure() for _ in range(max(1, repeat))]
    return min(runs, key=lambda r: r[0][key])


def our_run(arm, scene, garment, body, collider, last, level=2):
    from humananim.humananim_addon.cloth import job as cloth
    from humananim.solver.progress import run_to_end
    props = scene.humananim_cloth
    props.garment, props.armature, props.pin_group = garment, arm, "waist"
    props.body, props.collider, props.level = body, collider, level
    props.frame_start, props.frame_end, props.frame_step = 1, last, 1
    props.cache_dir = tempfile.mkdtemp(prefix="humananim-cloth-")
    t0 = _clock()
    job = cloth.ClothJob(scene)
    run_to_end(job.steps())
    cpu = _clock() - t0
    s = job.sim.ms_per_frame()
    frames = len(job.frames_done) - 1
    return {"integration_ms": s["integration_ms"], "collision_ms": s["collision_ms"],
            "smoothing_ms": s["smoothing_ms"], "total_ms": s["total_ms"],
            "with_blender_io_ms": 1000.0 * cpu / frames, "frames": frames,
            "particles": job.mesh.particle_count, "coarse_faces": len(job.mesh.faces),
            "rendered_faces": len(job.sim.smoother.faces),
            "max_depth_inside_mm": 1000.0 * job.depth_max,
            "max_mean_stretch": float(np.max(np.abs(job.stretch))),
            "collider": type(job.sim.bodies[0]).__name__,
            "stiffness_capped": bool(job.sim.dynamics.capped)}, job


def preview_run(arm, scene, garment, body, last):
    """Preview Cloth headless: what the modal operator's timer does, tick by tick (ClothPreview.tick:
    set the frame, read the pose and the skinned body from Blender, simulate one frame, write the
    preview mesh). The first tick sets the simulation up (the body's search grids): timed apart."""
    from humananim.humananim_addon.cloth import job as cloth
    props = scene.humananim_cloth
    props.garment, props.armature, props.pin_group = garment, arm, "waist"
    props.body, props.collider, props.level = body, "MESH", 2
    props.frame_start, props.frame_end, props.frame_step = 1, last, 1
    scene.frame_set(1)
    preview = cloth.ClothPreview(scene, frames=last - 1)
    try:
        t0, w0 = _clock(), time.perf_counter()
        preview.tick()
        setup, setup_wall = _clock() - t0, time.perf_counter() - w0
        ticks = []
        while preview.simulating:
            t0 = _clock()
            preview.tick()
            ticks.append(_clock() - t0)
    finally:
        preview.stop()
    ms = 1000.0 * float(np.median(ticks))
    return {"setup_s": setup, "setup_wall_s": setup_wall, "ticks": len(ticks), "median_tick_ms": ms,
            "mean_tick_ms": 1000.0 * float(np.mean(ticks)), "frames_per_second": 1000.0 / ms}


def blender_garment(job, arm, name):
    """Our rest surface as a plain mesh for Blender's cloth: the same rendered faces; the fine
    vertices of the pinned ring pinned, carried by the pelvis through an Armature modifier."""
    import bpy
    from humananim.humananim_addon.cloth.job import new_mesh_object
    from humananim.humananim_addon.cloth.job import roles_of
    fine = job.sim.smoother.surface(job.mesh.rest)
    obj = new_mesh_object(name, fine, job.sim.smoother.faces, arm, smooth=True)
    top = fine[:, 2] >= job.mesh.rest[job.sim.pins, 2].min() - 1e-6
    pelvis = roles_of(arm).bone("pelvis")
    obj.vertex_groups.new(name="waist").add([int(i) for i in np.flatnonzero(top)], 1.0, "REPLACE")
    obj.vertex_groups.new(name=pelvis).add(list(range(len(fine))), 1.0, "REPLACE")  # carried whole
    mod = obj.modifiers.new("Armature", "ARMATURE")
    mod.object = arm
    mod.use_deform_preserve_volume = False
    cloth = obj.modifiers.new("Cloth", "CLOTH")
    cloth.settings.vertex_group_mass = "waist"
    cloth.point_cache.frame_start, cloth.point_cache.frame_end = 1, bpy.context.scene.frame_end
    return obj, mod, cloth


def step_frames(scene, last):
    t = _clock()
    for f in range(1, last + 1):
        scene.frame_set(f)
    return _clock() - t


def blender_cloth_ms(arm, scene, job, body, last, name):
    """Blender's cloth: ms per frame of stepping the frames with the cloth minus without it."""
    scene.frame_set(1)
    obj, armature_mod, cloth = blender_garment(job, arm, name)
    # the Armature modifier deforms from the rest pose: keep the pinned ring where it is at
    # frame 1 by making it rigid with the pelvis (a Child Of-like bind): vertex positions are
    # moved into the rest pose of the pelvis
    pelvis = arm.pose.bones[arm.data.bones[obj.vertex_groups[1].name].name]
    rest = np.array(arm.matrix_world @ pelvis.bone.matrix_local)
    posed = np.array(arm.matrix_world @ pelvis.matrix)
    to_rest = rest @ np.linalg.inv(posed)
    co = np.empty(len(obj.data.vertices) * 3)
    obj.data.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3) @ to_rest[:3, :3].T + to_rest[:3, 3]
    obj.data.vertices.foreach_set("co", co.ravel())
    obj.data.update()
    if body is not None and "Collision" not in [m.type.title() for m in body.modifiers]:
        body.modifiers.new("Collision", "COLLISION")
    cloth.show_viewport = False
    scene.frame_set(1)
    without = step_frames(scene, last)
    cloth.show_viewport = True
    cloth.point_cache.frame_end = last
    scene.frame_set(1)
    with_cloth = step_frames(scene, last)
    frames = last - 1
    faces = len(obj.data.polygons)
    # proof that the cloth simulated: the hem hangs and swings away from the rigidly carried shape
    cloth_co = _evaluated(obj)
    cloth.show_viewport = False
    rigid_co = _evaluated(obj)
    hem = np.linalg.norm(cloth_co - rigid_co, axis=1)
    cloth.show_viewport = False  # out of the way of the next measurement
    return {"ms": 1000.0 * (with_cloth - without) / frames, "faces": faces, "frames": frames,
            "stepping_without_cloth_ms": 1000.0 * without / frames,
            "cloth_moved_max_m": float(hem.max()), "cloth_moved_mean_m": float(hem.mean())}


def _evaluated(obj):
    import bpy
    ev = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
    co = np.empty(len(ev.data.vertices) * 3)
    ev.data.vertices.foreach_get("co", co)
    return co.reshape(-1, 3)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true", help="print one JSON object (and write benchmarks/results/cloth.json)")
    parser.add_argument("--seconds", type=float, default=2.0, help="seconds of the walk (default 2)")
    parser.add_argument("--bodies", type=int, nargs="+", default=[5000, 20000, 80000],
                        help="triangle counts of the grown bodies (default 5000 20000 80000)")
    parser.add_argument("--repeat", type=int, default=1,
                        help="measure each of our cases this many times and keep the fastest (default 1)")
    parser.add_argument("--no-blender", action="store_true", help="skip Blender's cloth (ours only)")
    args = parser.parse_args(argv)
    import humananim
    from humananim.humananim_addon.cli import _chatter_to_stderr
    humananim.register()
    try:
        with _chatter_to_stderr():  # Blender's importer prints on stdout
            out = measure(args)
    finally:
        humananim.unregister()
    report(out, args.json)


def garment(arm, scene, kind):
    from humananim.humananim_addon.cloth import job as cloth
    scene.frame_set(1)
    if kind == "skirt":
        return cloth.add_skirt(arm, scene, name="Skirt")
    coat = cloth.add_skirt(arm, scene, name="Coat", rings=12, columns=25, waist=1.0, length=1.1, set_settings=False)
    coat.vertex_groups.remove(coat.vertex_groups[1])  # pinned ring: the nearest bones (spine, chest, arms)
    return coat


def measure(args):
    from humananim.humananim_addon.cloth import job as cloth
    out = {"numpy_add_us": numpy_add_us(), "seconds": args.seconds, "cases": {}}
    arm, scene, last = scene_at_30fps(args.seconds)
    garments = {kind: garment(arm, scene, kind) for kind in ("skirt", "coat")}
    r = args.repeat
    for size in args.bodies:
        scene.frame_set(1)
        body = cloth.add_skin_body(arm, scene, name=f"Body{size}", triangles=size)
        body.data.calc_loop_triangles()
        triangles = len(body.data.loop_triangles)
        for kind, obj in garments.items():
            ours, job = best_of(r, lambda: our_run(arm, scene, obj, body, "MESH", last), "total_ms")
            case = {"body_triangles": triangles, "ours": ours}
            if size == 20000 and kind == "skirt":  # the previous method, for the ratio; the preview
                case["mesh_body"] = measure_mesh_body(arm, scene, obj, body, last)
                case["preview"] = preview_run(arm, scene, obj, body, last)
            if not args.no_blender:
                b = blender_cloth_ms(arm, scene, job, body, last, f"{kind.title()}Blender{size}")
                case["blender_cloth"] = b
                case["speedup_vs_blender_cloth"] = b["ms"] / ours["total_ms"]
            out["cases"][f"{kind}_{size}"] = case
        body.hide_viewport = True  # (out of the next body's way: no Collision modifier on it)
        for mod in body.modifiers:
            if mod.type == "COLLISION":
                body.modifiers.remove(mod)
    out["claims"] = claims(out, args)
    return out


def measure_mesh_body(arm, scene, garment_obj, body, last):
    """Our run with the body searched by MeshBody (rebuilt per pose) instead of SkinnedBody."""
    from humananim.humananim_addon.cloth import job as cloth
    keep = cloth.skinned_collider
    cloth.skinned_collider = lambda body, arm, tris, positions, world: cloth.MeshBody(tris, len(positions))
    try:
        return our_run(arm, scene, garment_obj, body, "MESH", last)[0]
    finally:
        cloth.skinned_collider = keep


def claims(out, args):
    cases = out["cases"]
    found = []
    for key, case in cases.items():
        if "speedup_vs_blender_cloth" in case:
            v = case["speedup_vs_blender_cloth"]
            found.append({"claim": f"{key.split('_')[0]} on the {case['body_triangles']}-triangle skinned body: ours "
                                   f"vs Blender's cloth at equal rendered faces", "value": round(v, 2), "unit": "x",
                          "aim": ">= 10x", "met": bool(v >= 10.0)})
    for kind in ("skirt", "coat"):
        sizes = sorted(c["body_triangles"] for k, c in cases.items() if k.startswith(kind))
        if len(sizes) >= 2:
            lo = next(c for k, c in cases.items() if k.startswith(kind) and c["body_triangles"] == sizes[0])
            hi = next(c for k, c in cases.items() if k.startswith(kind) and c["body_triangles"] == sizes[-1])
            e = np.log(hi["ours"]["collision_ms"] / lo["ours"]["collision_ms"]) / np.log(sizes[-1] / sizes[0])
            found.append({"claim": f"{kind}: growth exponent of the collision's ms/frame with the body's triangles "
                                   f"({sizes[0]} -> {sizes[-1]})", "value": round(float(e), 3), "unit": "exponent",
                          "aim": "< 1 (sublinear)", "met": bool(e < 1.0)})
    skirt = cases.get("skirt_20000")
    if skirt:
        c = skirt["ours"]
        found.append({"claim": "thesis skirt on the 20,000-triangle body: collision ms per frame",
                      "value": round(c["collision_ms"], 2), "unit": "ms", "aim": "a few ms (<= 5)",
                      "met": bool(c["collision_ms"] <= 5.0)})
        if "preview" in skirt:
            fps = skirt["preview"]["frames_per_second"]
            found.append({"claim": "thesis skirt on the 20,000-triangle body: Preview Cloth frames a second (median "
                                   "timer tick after its setup, Blender I/O included)", "value": round(fps, 1),
                          "unit": "frames/s", "aim": ">= 30", "met": bool(fps >= 30.0)})
            found.append({"claim": "thesis skirt on the 20,000-triangle body: Preview Cloth's setup (first tick)",
                          "value": round(skirt["preview"]["setup_s"], 2), "unit": "s", "aim": None, "met": None})
        if "mesh_body" in skirt:
            v = skirt["mesh_body"]["collision_ms"] / c["collision_ms"]
            found.append({"claim": "thesis skirt on the 20,000-triangle body: collision, MeshBody (rebuilt per pose) "
                                   "over SkinnedBody", "value": round(v, 2), "unit": "x", "aim": None, "met": None})
    worst = max((c["ours"]["max_depth_inside_mm"] for c in cases.values()), default=0.0)
    found.append({"claim": "deepest particle inside the body, any case and frame", "value": round(worst, 3),
                  "unit": "mm", "aim": "<= 2", "met": bool(worst <= 2.0)})
    return found


def report(out, as_json):
    import datetime
    doc = {"benchmark": "cloth", "date": datetime.date.today().isoformat(),
           "machine_speed": {"numpy_add_us": round(out["numpy_add_us"], 4)}, "claims": out["claims"],
           "seconds": out["seconds"], "cases": out["cases"]}
    if as_json:
        folder = os.path.join(os.path.dirname(os.path.abspath(__file__)), "results")
        os.makedirs(folder, exist_ok=True)
        text = json.dumps(doc, indent=1, default=float)
        with open(os.path.join(folder, "cloth.json"), "w") as f:
            f.write(text + "\n")
        print(text)
        return
    print(f"numpy a+b on 1,000 floats: {out['numpy_add_us']:.2f} us (the machine's speed now)")
    for key, case in out["cases"].items():
        r = case["ours"]
        line = (f"{key:12s} body {case['body_triangles']:6d} triangles, {r['particles']:3d} particles -> "
                f"{r['rendered_faces']:5d} faces: simulation {r['integration_ms']:6.2f}  collision "
                f"{r['collision_ms']:6.2f}  smoothing {r['smoothing_ms']:5.2f}  total {r['total_ms']:6.2f} ms/frame "
                f"(with Blender I/O {r['with_blender_io_ms']:6.2f}); deepest {r['max_depth_inside_mm']:.2f} mm "
                f"stretch {100 * r['max_mean_stretch']:.2f} %")
        print(line)
        if "mesh_body" in case:
            print(f"{'':12s} the same with MeshBody: collision {case['mesh_body']['collision_ms']:6.2f} ms/frame")
        if "preview" in case:
            v = case["preview"]
            print(f"{'':12s} Preview Cloth: setup {v['setup_s']:.2f} s, then {v['median_tick_ms']:.1f} ms a tick "
                  f"({v['frames_per_second']:.1f} frames/s)")
        if "blender_cloth" in case:
            b = case["blender_cloth"]
            print(f"{'':12s} Blender cloth {b['faces']} faces: {b['ms']:.1f} ms/frame -> ours "
                  f"{case['speedup_vs_blender_cloth']:.1f}x faster")
    for c in out["claims"]:
        print(f"claim: {c['claim']}: {c['value']} {c['unit']} (aim {c['aim']}: {c['met']})")


if __name__ == "__main__":
    sys.exit(main())
