"""Flexible characters in Blender: a lattice with shape keys and a mesh, baked into new actions;
the source is untouched; the optimisation stores a controller that can be baked again."""

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from humananim.humananim_addon import action_api  # noqa: E402
from humananim.humananim_addon.flexible import job as flexible  # noqa: E402
from humananim.solver.progress import run_to_end  # noqa: E402


def fcurve_map(action, idtype_owner):
    """{(data_path, index): fcurve} of the action as applied to its owner."""
    ad = idtype_owner.animation_data
    if not action_api.SLOTTED:
        return {(fc.data_path, fc.array_index): fc for fc in action.fcurves}
    out = {}
    for layer in action.layers:
        for strip in layer.strips:
            bag = strip.channelbag(ad.action_slot)
            if bag is not None:
                out.update({(fc.data_path, fc.array_index): fc for fc in bag.fcurves})
    return out


def make_character(scene):
    """A 3x3x3 lattice with 'stretch' and 'lean' keys and a cube (not its child) deformed by it,
    both at 1 m above the ground; the lattice has its own transform and Key animation."""
    lat_data = bpy.data.lattices.new("Lat")
    lat_data.points_u = lat_data.points_v = lat_data.points_w = 3
    lat = bpy.data.objects.new("Lat", lat_data)
    scene.collection.objects.link(lat)
    lat.location = (0.0, 0.0, 1.0)
    grid = np.empty(27 * 3)
    lat_data.points.foreach_get("co", grid)
    grid = grid.reshape(27, 3)
    lat.scale = tuple(0.6 / np.ptp(grid, axis=0))
    lat.shape_key_add(name="Basis", from_mix=False)
    z = (grid[:, 2] - grid[:, 2].min()) / np.ptp(grid[:, 2])
    for name, offset in (("stretch", np.stack([0 * z, 0 * z, z * 0.4 * np.ptp(grid[:, 2])], 1)),
                         ("lean", np.stack([z * 0.5 * np.ptp(grid[:, 0]), 0 * z, 0 * z], 1))):
        kb = lat.shape_key_add(name=name, from_mix=False)
        kb.data.foreach_set("co", (grid + offset).ravel())
    mesh = bpy.data.meshes.new("Blob")
    s = 0.28
    verts = [(x, y, zz) for zz in (-s, s) for y in (-s, s) for x in (-s, s)]
    faces = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    mesh.from_pydata(verts, [], faces)
    mesh.update()
    obj = bpy.data.objects.new("Blob", mesh)
    scene.collection.objects.link(obj)
    obj.location = (0.0, 0.0, 1.0)
    obj.modifiers.new("Lattice", "LATTICE").object = lat
    # the animator's own animation of the lattice's Key: stretch keyed 0 -> 0.8 over frames 1-10
    key = lat_data.shape_keys
    key.key_blocks["stretch"].value = 0.0
    key.key_blocks["stretch"].keyframe_insert("value", frame=1)
    key.key_blocks["stretch"].value = 0.8
    key.key_blocks["stretch"].keyframe_insert("value", frame=10)
    lat.keyframe_insert("location", frame=1)
    bpy.context.view_layer.update()
    return obj, lat


def snapshot(obj, lat):
    key = lat.data.shape_keys
    pts = [np.array([p.co[:] for p in kb.data]) for kb in key.key_blocks]
    verts = np.array([v.co[:] for v in obj.data.vertices])
    key_action = key.animation_data.action
    lat_action = lat.animation_data.action
    return {"pts": pts, "verts": verts, "key_action": key_action.name, "lat_action": lat_action.name,
            "curves": {a.name: _keys_of(a) for a in (key_action, lat_action)}}


def _keys_of(action):
    """Every keyframe of every F-curve (all slots): what 'untouched' compares."""
    return sorted((k, [tuple(p.co) for p in fc.keyframe_points]) for k, fc in _curves_any(action).items())


def test_bake_writes_new_actions_and_leaves_the_source(empty_scene):
    scene = empty_scene
    obj, lat = make_character(scene)
    props = obj.humananim_flexible
    assert flexible.sync_modes(obj) == ["stretch", "lean"]
    props.frame_start, props.frame_end, props.handover_frame = 1, 40, 10
    props.sample_count = 12
    props.use_control = False
    before = snapshot(obj, lat)
    summary = run_to_end(flexible.run(obj, scene))
    assert summary["modes"] == ["stretch", "lean"] and summary["points"] == 12 and summary["frames"] == 40
    assert summary["mass_kg"] == pytest.approx(0.56 ** 3 * 500.0, rel=1e-3)
    # new actions, assigned; the old ones kept (fake user) and unchanged
    lat_action = bpy.data.actions[summary["lattice_action"]]
    key_action = bpy.data.actions[summary["key_action"]]
    obj_action = bpy.data.actions[summary["object_action"]]   # the cube isn't the lattice's child
    key = lat.data.shape_keys
    assert lat.animation_data.action == lat_action and key.animation_data.action == key_action
    assert obj.animation_data.action == obj_action
    assert {lat_action.name, key_action.name}.isdisjoint({before["lat_action"], before["key_action"]})
    after = {"pts": [np.array([p.co[:] for p in kb.data]) for kb in key.key_blocks],
             "verts": np.array([v.co[:] for v in obj.data.vertices])}
    assert all(np.array_equal(a, b) for a, b in zip(before["pts"], after["pts"]))
    assert np.array_equal(before["verts"], after["verts"])
    for name, keys in before["curves"].items():
        assert bpy.data.actions[name].use_fake_user and _keys_of(bpy.data.actions[name]) == keys
    # keys: location, rotation of the lattice and every mode's value at every frame
    lat_curves = fcurve_map(lat_action, lat)
    assert {("location", i) for i in range(3)} <= set(lat_curves)
    assert any(path.startswith("rotation") for path, _ in lat_curves)
    key_curves = fcurve_map(key_action, key)
    assert set(key_curves) == {('key_blocks["stretch"].value', 0), ('key_blocks["lean"].value', 0)}
    stretch = key_curves[('key_blocks["stretch"].value', 0)]
    assert len(stretch.keyframe_points) == 40
    # key-framed by hand up to the hand-over: the animator's values; then the simulation
    values = np.array([stretch.evaluate(f) for f in range(1, 41)])
    source = _curves_any(bpy.data.actions[before["key_action"]])[('key_blocks["stretch"].value', 0)]
    assert np.allclose(values[:10], [source.evaluate(f) for f in range(1, 11)], atol=1e-6)
    assert values[9] == pytest.approx(0.8)
    assert np.abs(np.diff(values[9:])).max() > 1e-4
    # it fell: the lattice came down towards the ground and rests on it
    z = np.array([lat_curves[("location", 2)].evaluate(f) for f in range(1, 41)])
    assert z[-1] < z[0] - 0.2
    scene.frame_set(40)
    bpy.context.view_layer.update()
    deformed = obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).to_mesh()
    lowest = min((obj.matrix_world @ v.co).z for v in deformed.vertices)
    assert -0.1 < lowest < 0.1            # as Blender draws it, with its own lattice interpolation
    assert -0.03 < summary["end_lowest_point_m"] < 0.0    # the simulated mass points are on the ground


def test_lattice_points_as_the_masses(empty_scene):
    """The Masses choice 'Lattice Points': the lattice's own points carry the mass (from the
    lattice's volume), not samples of the mesh."""
    obj, lat = make_character(empty_scene)
    props = obj.humananim_flexible
    flexible.sync_modes(obj)
    props.frame_start, props.frame_end, props.handover_frame = 1, 12, 1
    props.use_control = False
    props.points = "LATTICE"
    summary = run_to_end(flexible.run(obj, empty_scene))
    assert summary["points"] == int(np.prod(summary["lattice_points"])) != props.sample_count
    assert summary["mass_kg"] == pytest.approx(0.6 ** 3 * props.density, rel=1e-3)  # the 0.6 m lattice
    assert bpy.data.actions[summary["lattice_action"]] == lat.animation_data.action


def _curves_any(action):
    if not action_api.SLOTTED:
        return {(fc.data_path, fc.array_index): fc for fc in action.fcurves}
    out = {}
    for layer in action.layers:
        for strip in layer.strips:
            for bag in strip.channelbags:
                out.update({(fc.data_path, fc.array_index): fc for fc in bag.fcurves})
    return out


def test_cancelled_bake_writes_nothing(empty_scene):
    obj, lat = make_character(empty_scene)
    props = obj.humananim_flexible
    props.frame_start, props.frame_end, props.use_control = 1, 60, False
    actions = set(bpy.data.actions.keys())
    steps = flexible.run(obj, empty_scene)
    for _ in range(3):
        next(steps)
    steps.close()  # what Esc does
    assert set(bpy.data.actions.keys()) == actions
    props.use_control, props.trials, props.trial_seconds = True, 3, 1.0
    flexible.sync_modes(obj)
    props.modes[0].active = True
    props.poses.add().values[0] = 0.5
    steps = flexible.optimize(obj, empty_scene)
    progress = [next(steps) for _ in range(5)]
    assert all(0 <= a <= b <= 1 for a, b in zip(progress, progress[1:]))
    steps.close()
    assert not len(props.best_poses)


def test_demo_table_optimises_and_bakes_the_best_controller(empty_scene):
    assert bpy.ops.humananim.flexible_demo_table() == {"FINISHED"}
    obj = bpy.context.active_object
    props = obj.humananim_flexible
    assert [m.key for m in props.modes] == ["shear", "bend", "squash", "hsquash"]
    assert [m.active for m in props.modes] == [True, True, True, False]
    assert len(props.poses) == 2
    assert bpy.ops.humananim.flexible_pose_add() == {"FINISHED"} and len(props.poses) == 3
    assert bpy.ops.humananim.flexible_pose_remove() == {"FINISHED"} and len(props.poses) == 2
    props.trials, props.trial_seconds, props.seed = 3, 2.0, 4
    assert bpy.ops.humananim.flexible_optimize() == {"FINISHED"}
    assert len(props.best_poses) == 2 and props.best_cost > 0
    stored = [tuple(p.values[:3]) for p in props.best_poses]
    # the stored controller survives a save and load, and bakes again
    props.controller = "BEST"
    props.frame_end = 25
    assert bpy.ops.humananim.flexible_simulate() == {"FINISHED"}
    lat = props.lattice
    assert lat.animation_data.action.name.startswith("Flexible Table Lattice Flexible")
    assert [tuple(p.values[:3]) for p in props.best_poses] == stored


def test_duplicated_modes_are_reported_by_name(empty_scene):
    bpy.ops.humananim.flexible_demo_table()
    obj = bpy.context.active_object
    lat = obj.humananim_flexible.lattice
    kb = lat.shape_key_add(name="shear again", from_mix=False)
    shear = lat.data.shape_keys.key_blocks["shear"]
    kb.data.foreach_set("co", np.array([p.co[:] for p in shear.data]).ravel())
    assert bpy.ops.humananim.flexible_sync_modes() == {"FINISHED"}
    with pytest.raises(RuntimeError, match="shear again"):
        bpy.ops.humananim.flexible_simulate()
    assert not [a for a in bpy.data.actions if "Flexible" in a.name]


def test_panel_draws_every_setting(empty_scene):
    from test_panels import draw_all
    log = draw_all(bpy.context)
    assert ("operator", "humananim.flexible_demo_table") in log
    bpy.ops.humananim.flexible_demo_table()
    props = bpy.context.active_object.humananim_flexible
    props.cost, props.use_hold = "custom", True
    log = draw_all(bpy.context)
    for name in ("flexible_simulate", "flexible_optimize", "flexible_pose_add", "flexible_sync_modes"):
        assert ("operator", f"humananim.{name}") in log
    for name in ("modes", "poses", "hold_point", "w_energy", "seed", "friction", "ground_slope", "stiffness"):
        assert ("prop", name) in log


def test_spring_to_an_animated_object_carries_the_character(empty_scene):
    """A spring from the top of the table to an Empty that rises: the table hangs from it and
    follows it up."""
    bpy.ops.humananim.flexible_demo_table()
    obj = bpy.context.active_object
    props = obj.humananim_flexible
    props.use_control = False
    props.frame_start, props.frame_end = 1, 73
    hook = bpy.data.objects.new("Hook", None)
    empty_scene.collection.objects.link(hook)
    hook.location = (0.0, 0.0, 0.6)
    hook.keyframe_insert("location", frame=1)
    hook.location = (0.0, 0.0, 2.6)
    hook.keyframe_insert("location", frame=49)
    obj.select_set(True)
    hook.select_set(True)
    assert bpy.ops.humananim.flexible_spring_add() == {"FINISHED"}
    sp = props.springs[0]
    assert sp.target == hook
    sp.point, sp.stiffness, sp.damping = (0.5, 0.5, 1.0), 3000.0, 150.0
    summary = run_to_end(flexible.run(obj, empty_scene))
    lat = props.lattice
    z = fcurve_map(lat.animation_data.action, lat)[("location", 2)]
    end = z.evaluate(73)
    # hanging below the hook by half its height, the spring's stretch under its weight and the
    # sag of its passive modes
    stretch = summary["mass_kg"] * 9.81 / 3000.0
    assert z.evaluate(1) == pytest.approx(0.3, abs=0.01)
    assert end == pytest.approx(2.6 - 0.3 - stretch, abs=0.1)
    assert bpy.ops.humananim.flexible_spring_remove() == {"FINISHED"} and not len(props.springs)

def test_keyframed_part_holds_the_chosen_point(empty_scene):
    """Holding the top centre while the animator's 'stretch' grows to 0.8 over frames 1-10: the
    lattice moves down by the top's rise, 0.8 x 0.4 x 0.6 m."""
    obj, lat = make_character(empty_scene)
    props = obj.humananim_flexible
    flexible.sync_modes(obj)
    props.frame_start, props.frame_end, props.handover_frame = 1, 12, 10
    props.use_control, props.use_hold, props.hold_point = False, True, (0.5, 0.5, 1.0)
    run_to_end(flexible.run(obj, empty_scene))
    z = fcurve_map(lat.animation_data.action, lat)[("location", 2)]
    assert z.evaluate(1) == pytest.approx(1.0, abs=1e-5)
    assert z.evaluate(10) == pytest.approx(1.0 - 0.8 * 0.4 * 0.6, abs=1e-4)
