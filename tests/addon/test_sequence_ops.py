"""Keyframe sequence operators in Blender: equalizer, blend, compression, time warp, squeeze/stretch,
band analysis, the Graph Editor menu and the Sequence panel."""

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from conftest import CMU_CLIPS, assert_same_pose, fcurve_snapshot, import_cmu, world_pose  # noqa: E402
from humananim.humananim_addon import action_api, sequence  # noqa: E402
from humananim.solver.sequence import key_reduction  # noqa: E402

SEQUENCE_OPS = ("equalize", "multires_blend", "compress_keys", "time_warp", "squeeze_stretch")


def activate(obj, action):
    action_api.assign_action(obj, action, action_api.object_slot(action, obj))


def local_errors(obj, a, b):
    """Largest local rotation error (degrees) of any bone and largest root location error (cm)
    between two world-pose arrays (F, J, 4, 4) of the same armature."""
    parents = [list(obj.pose.bones).index(pb.parent) if pb.parent else -1 for pb in obj.pose.bones]

    def local_rot(m):
        r = m[..., :3, :3] / np.linalg.norm(m[..., :3, :3], axis=-2, keepdims=True)
        out = r.copy()
        for j, p in enumerate(parents):
            if p >= 0:
                out[:, j] = np.swapaxes(r[:, p], -1, -2) @ r[:, j]
        return out
    ra, rb = local_rot(a), local_rot(b)
    cos = (np.trace(np.swapaxes(ra, -1, -2) @ rb, axis1=-2, axis2=-1) - 1.0) / 2.0
    deg = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    roots = [j for j, p in enumerate(parents) if p < 0]
    cm = 100.0 * np.linalg.norm(a[:, roots, :3, 3] - b[:, roots, :3, 3], axis=-1)
    return float(deg.max()), float(cm.max())


def keyed_metarig(metarig, frames=(1, 9, 17, 25, 33, 41)):
    """The Rigify metarig with sparse Bezier keys on quaternion and Euler bones and a location."""
    bpy.ops.object.mode_set(mode="POSE")
    rng = np.random.default_rng(3)
    bones = {"spine": "QUATERNION", "upper_arm.L": "QUATERNION", "forearm.L": "QUATERNION",
             "thigh.R": "XYZ", "shin.R": "ZXY"}
    for f in frames:
        for name, mode in bones.items():
            pb = metarig.pose.bones[name]
            pb.rotation_mode = mode
            angles = rng.uniform(-0.6, 0.6, 3)
            if mode == "QUATERNION":
                from mathutils import Euler
                pb.rotation_quaternion = Euler(angles).to_quaternion()
                pb.keyframe_insert("rotation_quaternion", frame=f)
            else:
                pb.rotation_euler = angles
                pb.keyframe_insert("rotation_euler", frame=f)
        root = metarig.pose.bones["spine"]
        root.location = rng.uniform(-0.1, 0.1, 3)
        root.keyframe_insert("location", frame=f)
    bpy.ops.object.mode_set(mode="OBJECT")
    return metarig.animation_data.action


@pytest.fixture
def cmu_pair(empty_scene):
    """CMU 131_01 as the active rig, and 131_03's action (its armature removed)."""
    other = import_cmu(CMU_CLIPS[1])
    second = other.animation_data.action
    second.use_fake_user = True
    bpy.data.objects.remove(other)
    obj = import_cmu(CMU_CLIPS[0])
    return obj, obj.animation_data.action, second


def test_operators_are_undoable_and_write_new_actions_by_default():
    for name in SEQUENCE_OPS:
        rna = getattr(bpy.ops.humananim, name).get_rna_type()
        cls = getattr(bpy.types, f"HUMANANIM_OT_{name}")
        assert {"REGISTER", "UNDO"} <= set(cls.bl_options), name
        assert "replace" in rna.properties and rna.properties["replace"].default is False
        assert "channels" in rna.properties


def test_equalizer_with_unit_gains_reproduces_the_source_and_redo_never_compounds(cmu_rig):
    scene = bpy.context.scene
    source = cmu_rig.animation_data.action
    before = fcurve_snapshot(source, cmu_rig)
    frames = np.arange(1, 996, 7)
    reference = world_pose(cmu_rig, scene, frames)
    assert bpy.ops.humananim.equalize(channels="ALL") == {"FINISHED"}
    result = cmu_rig.animation_data.action
    assert result != source and result.name.startswith(source.name)
    assert_same_pose(reference, world_pose(cmu_rig, scene, frames), pos_tol=1e-5, rot_tol=1e-5)
    # the same gains run twice (as the redo panel does, with the source remembered) give the same action
    gains = (0.0, 0.3, 1.0, 1.5, 1.0, 1.0) + (1.0,) * 3
    bpy.ops.humananim.equalize(channels="ALL", gains=gains, levels=5, source_action=source.name)
    once = fcurve_snapshot(cmu_rig.animation_data.action, cmu_rig)
    bpy.ops.humananim.equalize(channels="ALL", gains=gains, levels=5, source_action=source.name)
    twice = fcurve_snapshot(cmu_rig.animation_data.action, cmu_rig)
    assert once.keys() == twice.keys()
    assert all(np.allclose(once[k], twice[k], atol=1e-9) for k in once)
    after = fcurve_snapshot(source, cmu_rig)
    assert before.keys() == after.keys() and all(np.array_equal(before[k], after[k]) for k in before)
    # denoising removes the finest bands: the filtered curves are smoother
    bpy.ops.humananim.equalize(channels="ALL", mode="DENOISE", cutoff_hz=6.0, source_action=source.name)
    fc_src = next(fc for fc in action_api.fcurves_of(source, cmu_rig) if "LeftKnee" in fc.data_path)
    fc_new = next(fc for fc in action_api.fcurves_of(cmu_rig.animation_data.action, cmu_rig)
                  if fc.data_path == fc_src.data_path and fc.array_index == fc_src.array_index)
    rough = [np.abs(np.diff([fc.evaluate(f) for f in range(1, 996)], 2)).mean() for fc in (fc_src, fc_new)]
    assert rough[1] < 0.8 * rough[0]


def test_equalizer_on_the_metarig_keeps_rotations_unit_and_replace_rewrites_in_place(metarig):
    scene = bpy.context.scene
    source = keyed_metarig(metarig)
    frames = np.arange(1, 42)
    reference = world_pose(metarig, scene, frames)
    bpy.ops.humananim.equalize(channels="ALL")
    assert metarig.animation_data.action != source
    assert_same_pose(reference, world_pose(metarig, scene, frames), pos_tol=1e-5, rot_tol=1e-5)
    activate(metarig, source)
    before = fcurve_snapshot(source, metarig)
    count = len(bpy.data.actions)
    bpy.ops.humananim.equalize(channels="ALL", gains=(1.0, 2.0, 2.0) + (1.0,) * 6, replace=True)
    assert metarig.animation_data.action == source and len(bpy.data.actions) == count
    after = fcurve_snapshot(source, metarig)
    assert any(len(after[k]) != len(before[k]) or not np.allclose(after[k], before[k]) for k in before)
    q = np.array([[fc.evaluate(f) for fc in action_api.fcurves_of(source, metarig)
                   if fc.data_path.endswith('["spine"].rotation_quaternion')] for f in frames])
    assert np.allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-6)  # renormalised on every frame


def test_selected_curves_only_are_processed_and_the_rest_copied(metarig):
    source = keyed_metarig(metarig)
    curves = action_api.fcurves_of(source, metarig)
    for fc in curves:
        fc.select = fc.data_path.endswith('["thigh.R"].rotation_euler') and fc.array_index == 1
    sel = sequence.select_channels(metarig, bpy.context.scene, source, "CURVES")
    assert [g.label for g in sel.groups] == ["thigh.R rotation_euler"]  # the whole rotation
    assert len(sel.groups[0].fcurves) == 3
    before = fcurve_snapshot(source, metarig)
    bpy.ops.humananim.equalize(channels="CURVES", gains=(0.0,) * 3 + (1.0,) * 6, levels=3)
    new = fcurve_snapshot(metarig.animation_data.action, metarig)
    assert new.keys() == before.keys()
    for key in before:
        if "thigh.R" in key[0]:
            assert len(new[key]) == 2 * 41  # keyed on every frame
        else:
            assert np.array_equal(new[key], before[key]), key  # copied unchanged


def test_compression_meets_its_tolerance_on_every_frame_and_bone(cmu_rig):
    scene = bpy.context.scene
    source = cmu_rig.animation_data.action
    before = fcurve_snapshot(source, cmu_rig)
    frames = np.arange(1, 996)
    reference = world_pose(cmu_rig, scene, frames)
    sel = sequence.select_channels(cmu_rig, scene, source)
    s = sequence.compress(cmu_rig, scene, source, sel, degrees=0.5, centimetres=0.5)
    result = cmu_rig.animation_data.action
    assert result.name == s["action"] != source.name
    assert s["keys_after"] < s["keys_before"] / 10
    assert s["max_error_deg"] <= 0.5 and s["max_error_cm"] <= 0.5
    assert 0.0 < s["tail_error_cm"] <= s["tail_10cm_error_cm"] < 5.0
    deg, cm = local_errors(cmu_rig, reference, world_pose(cmu_rig, scene, frames))
    assert deg <= 0.5 + 1e-3 and cm <= 0.5 + 1e-3, (deg, cm)
    assert deg == pytest.approx(s["max_error_deg"], abs=0.02)
    after = fcurve_snapshot(source, cmu_rig)
    assert all(np.array_equal(before[k], after[k]) for k in before)
    # Blender keeps the FREE handles we set and plays the keys as the solver's evaluator does
    fc = action_api.fcurves_of(result, cmu_rig)[5]
    assert {k.handle_left_type for k in fc.keyframe_points} == {"FREE"}
    keys = sequence.read_keys(fc)
    ours = key_reduction.evaluate(keys, frames.astype(float))
    assert np.abs(ours - [fc.evaluate(f) for f in frames]).max() < 1e-5
    # the operator (a job) runs to the end in the background and writes the same way
    activate(cmu_rig, source)
    assert bpy.ops.humananim.compress_keys(degrees=2.0, centimetres=2.0, method="PYRAMID") == {"FINISHED"}
    assert cmu_rig.animation_data.action != source


def test_compression_to_a_bone_tail_tolerance(cmu_rig):
    """Tolerance also as the largest error at any bone's tail and 10 cm beyond, on every frame,
    measured as Blender plays the result."""
    scene = bpy.context.scene
    source = cmu_rig.animation_data.action
    sel = sequence.select_channels(cmu_rig, scene, source)
    loose = sequence.compress(cmu_rig, scene, source, sel, degrees=1.0, centimetres=1.0)
    assert loose["tail_10cm_error_cm"] > 1.0  # channel tolerances alone don't bound the tails
    activate(cmu_rig, source)
    s = sequence.compress(cmu_rig, scene, source, sel, degrees=1.0, centimetres=1.0, tail_cm=1.0)
    assert s["tolerance_tail_cm"] == 1.0
    assert s["tail_error_cm"] <= 1.0 + 1e-3 and s["tail_10cm_error_cm"] <= 1.0 + 1e-3  # Blender's playback
    tight = sequence.compress(cmu_rig, scene, source, sel, degrees=0.1, centimetres=0.1)
    assert loose["keys_after"] < s["keys_after"] < tight["keys_after"]


def test_compression_keeps_planted_feet_by_default(cmu_rig):
    """The channel tolerances bound each channel, not the feet: the root's and legs' errors add up
    at a planted foot. By default the legs' tolerances are tightened until every foot point the
    source plants stays within 2.5 mm of it, so the motion QA's slide (the source's own plus 5 mm)
    holds as Blender plays the result; 0 turns it off."""
    from humananim.humananim_addon.qa.job import measure_result
    scene = bpy.context.scene
    source = cmu_rig.animation_data.action
    sel = sequence.select_channels(cmu_rig, scene, source)
    loose = sequence.compress(cmu_rig, scene, source, sel, degrees=2.0, centimetres=2.0, feet_mm=0.0)
    assert "feet_error_mm" not in loose
    loose_qa = measure_result(cmu_rig, scene, bpy.data.actions[loose["action"]], [source], store=False)
    activate(cmu_rig, source)
    s = sequence.compress(cmu_rig, scene, source, sel, degrees=2.0, centimetres=2.0)
    assert s["tolerance_feet_mm"] == sequence.FEET_MM == 2.5
    assert s["feet_error_mm"] <= 2.5 and 0.0 < s["feet_tolerance_scale"] < 1.0
    assert s["max_error_deg"] <= 2.0 and s["max_error_cm"] <= 2.0
    qa = measure_result(cmu_rig, scene, bpy.data.actions[s["action"]], [source], store=False)
    slide, loose_slide = qa["measures"]["slide"], loose_qa["measures"]["slide"]
    assert loose_slide["passed"] is False  # the loose legs drag a planted foot past the limit
    assert slide["passed"] is True and slide["value"] < loose_slide["value"]
    assert loose["keys_after"] < s["keys_after"]  # only the legs' channels took more keys


def test_compression_on_quaternion_bones_of_the_metarig(metarig):
    scene = bpy.context.scene
    keyed_metarig(metarig)
    bpy.ops.humananim.equalize(channels="ALL")  # dense keys on every frame
    dense = metarig.animation_data.action
    frames = np.arange(1, 42)
    reference = world_pose(metarig, scene, frames)
    s = sequence.compress(metarig, scene, dense, sequence.select_channels(metarig, scene, dense), 0.2, 0.2)
    assert s["keys_after"] < s["keys_before"]
    deg, cm = local_errors(metarig, reference, world_pose(metarig, scene, frames))
    assert deg <= 0.2 + 1e-3 and s["max_error_deg"] <= 0.2 and s["max_error_cm"] <= 0.2
    # in place, to a bone-tail tolerance: the tails are measured against the source as it was
    result = metarig.animation_data.action
    s = sequence.compress(metarig, scene, result, sequence.select_channels(metarig, scene, result), 1.0, 1.0,
                          replace=True, tail_cm=0.5)
    assert s["replaced"] and metarig.animation_data.action == result and s["action"] == result.name
    assert 0.0 < s["tail_error_cm"] <= 0.5 + 1e-3 and s["tail_10cm_error_cm"] <= 0.5 + 1e-3


def test_blend_is_continuous_across_the_window(cmu_pair):
    obj, a, b = cmu_pair
    scene = bpy.context.scene
    before = fcurve_snapshot(a, obj)
    start, window = 900, 24
    assert bpy.ops.humananim.multires_blend(action_b=b.name, start=start, window=window) == {"FINISHED"}
    result = obj.animation_data.action
    assert result not in (a, b)
    assert result.frame_range[1] == pytest.approx(start + (b.frame_range[1] - b.frame_range[0]))
    frames = np.arange(820, 1000)
    blended = world_pose(obj, scene, frames)[..., :3, 3]
    step = np.linalg.norm(np.diff(blended, axis=0), axis=-1).max()
    activate(obj, a)
    pa = world_pose(obj, scene, np.arange(820, 996))[..., :3, 3]
    activate(obj, b)
    pb = world_pose(obj, scene, np.arange(1, 181))[..., :3, 3]
    natural = max(np.linalg.norm(np.diff(p, axis=0), axis=-1).max() for p in (pa, pb))
    cut = np.linalg.norm(pb[0] - pa[start - 820], axis=-1).max()  # a hard cut's jump at the start
    assert step < max(2.0 * natural, 0.2 * cut), (step, natural, cut)
    # well before the window the result is A
    assert np.abs(blended[:20] - pa[:20]).max() < 1e-4
    after = fcurve_snapshot(a, obj)
    assert all(np.array_equal(before[k], after[k]) for k in before)


def test_blend_holds_the_feet_as_on_its_result_read_back_from_blender(cmu_pair, monkeypatch):
    """The planted feet are held on the blend's own poses before the action is written. The
    reference is the way it was done before, recorded here in the same run: the blend written
    unheld, read back from Blender as trajectories and held there. Same result within 0.1 deg on
    every bone and 1 mm on every joint."""
    from humananim.humananim_addon.actions import read_action
    from humananim.humananim_addon.armature import skeleton_from_armature
    from humananim.solver import rotations
    from humananim.solver.sequence import planted_feet
    obj, a, b = cmu_pair
    scene = bpy.context.scene
    hold = planted_feet.hold_planted_feet
    seen = {}

    def unheld(skeleton, traj, transition, *args, **kw):
        seen.update(traj=traj, transition=transition.copy())
        return traj, hold(skeleton, traj, transition, *args, **kw)[1]
    monkeypatch.setattr(planted_feet, "hold_planted_feet", unheld)
    sequence.blend(obj, scene, a, b, 900, window=120)
    monkeypatch.undo()
    skeleton = skeleton_from_armature(obj, scene, require=False)
    span = (seen["traj"].frames[0], seen["traj"].frames[-1])
    read_back = read_action(obj, scene, skeleton, obj.animation_data.action, frame_range=span)
    # the poses the feet are held on are the ones Blender shows for the written blend
    assert np.degrees(rotations.angle_between(seen["traj"].rotations, read_back.rotations)).max() < 1e-4
    assert np.abs(seen["traj"].translations - read_back.translations).max() < 1e-6
    expected, report = hold(skeleton, read_back, seen["transition"])
    assert report["held"]["L"] or report["held"]["R"]
    s = sequence.blend(obj, scene, a, b, 900, window=120)
    assert s["feet"]["held"] == report["held"] and s["feet"]["bones"]
    got = read_action(obj, scene, skeleton, obj.animation_data.action, frame_range=span)
    assert np.degrees(rotations.angle_between(got.rotations, expected.rotations)).max() < 0.1
    heads = [t.world_frames(skeleton)[..., :3, 3] for t in (got, expected)]
    assert np.linalg.norm(heads[0] - heads[1], axis=-1).max() < 1e-3
    # a rig with constraints is held on Blender's evaluation of the written result: the same here
    # (a constraint with no influence), the other way
    obj.pose.bones["LeftShoulder"].constraints.new("COPY_ROTATION").influence = 0.0
    s = sequence.blend(obj, scene, a, b, 900, window=120)
    assert s["feet"]["held"] == report["held"]
    evaluated = read_action(obj, scene, skeleton, obj.animation_data.action, frame_range=span)
    assert np.degrees(rotations.angle_between(evaluated.rotations, expected.rotations)).max() < 0.1


def test_blend_of_two_nla_strips(cmu_pair):
    obj, a, b = cmu_pair
    ad = obj.animation_data
    track = ad.nla_tracks.new()
    track.strips.new("A", 1, a)
    track2 = ad.nla_tracks.new()
    track2.strips.new("B", 950, b)
    ad.action = None
    activate(obj, a)
    assert bpy.ops.humananim.multires_blend(second="NLA", window=20, channels="ALL") == {"FINISHED"}
    assert obj.animation_data.action.name.startswith(a.name + ".blend")


def test_time_warp_hits_its_marker_constraints(cmu_rig):
    scene = bpy.context.scene
    source = cmu_rig.animation_data.action
    before = fcurve_snapshot(source, cmu_rig)
    reference = world_pose(cmu_rig, scene, [100, 500, 700])
    for old, new in ((100, 80), (500, 520)):
        scene.frame_set(old)
        assert bpy.ops.humananim.add_warp_marker() == {"FINISHED"}
        scene.timeline_markers[f"warp:{old}"].frame = new  # the animator drags it
    assert bpy.ops.humananim.time_warp() == {"FINISHED"}
    warped = world_pose(cmu_rig, scene, [80, 520, 700])
    assert_same_pose(reference[:2], warped[:2], pos_tol=1e-5, rot_tol=1e-5)
    assert cmu_rig.animation_data.action.frame_range[:] == pytest.approx(source.frame_range[:])
    after = fcurve_snapshot(source, cmu_rig)
    assert all(np.array_equal(before[k], after[k]) for k in before)
    # a frame map, keyed on every frame, does the same
    activate(cmu_rig, source)
    bpy.ops.humananim.time_warp(constraints="MAP", warp_map="100:80, 500:520", resample=True)
    assert_same_pose(reference[:2], world_pose(cmu_rig, scene, [80, 520]), pos_tol=1e-4, rot_tol=1e-4)


def test_squeeze_stretch_moves_a_key_and_rescales_its_neighbours(metarig):
    scene = bpy.context.scene
    source = keyed_metarig(metarig)
    reference = world_pose(metarig, scene, [17])
    assert bpy.ops.humananim.squeeze_stretch(frame=17, new_frame=13, left_limit=9, right_limit=41) == {"FINISHED"}
    result = metarig.animation_data.action
    fc = action_api.fcurves_of(result, metarig)[0]
    times = [k.co[0] for k in fc.keyframe_points]
    # left side (9..17) -> (9..13), right side (17..41) -> (13..41) with kept ratios
    assert times == pytest.approx([1, 9, 13, 13 + 8 * 28 / 24, 13 + 16 * 28 / 24, 41])
    assert_same_pose(reference, world_pose(metarig, scene, [13]), pos_tol=1e-5, rot_tol=1e-5)
    assert result != source


def test_band_analysis_panel_and_graph_editor_menu(cmu_rig):
    from humananim.panels import sequence as panel
    from test_panels import RecordingLayout, draw_all
    bpy.ops.object.mode_set(mode="POSE")
    cmu_rig.data.bones.active = cmu_rig.data.bones["LeftKnee"]
    assert bpy.ops.humananim.analyse_bands() == {"FINISHED"}
    props = bpy.context.scene.humananim_sequence
    assert props.analysed == "LeftKnee rotation_euler" and props.units == "deg"
    energies = [b.energy for b in props.bands]
    assert len(energies) == 9 and energies[0] < energies[4]  # capture noise is small beside the motion
    bpy.ops.object.mode_set(mode="OBJECT")
    log = draw_all(bpy.context)
    for name in SEQUENCE_OPS + ("analyse_bands",):
        assert ("operator", f"humananim.{name}") in log
    assert any(kind == "label" and "Hz" in text and "deg" in text for kind, text in log)
    assert panel.draw_key_menu in bpy.types.GRAPH_MT_key._dyn_ui_initialize()
    log = []
    panel.GRAPH_MT_humananim_sequence.draw(type("M", (), {"layout": RecordingLayout(log)})(), bpy.context)
    assert ("operator", "humananim.time_warp") in log and ("operator", "humananim.compress_keys") in log


def test_user_errors_are_reported_not_raised(cmu_rig):
    with pytest.raises(RuntimeError, match="time warp needs two constraints|keep their order"):
        bpy.ops.humananim.time_warp(constraints="MAP", warp_map="100:80, 200:50", keep_ends=True)
    with pytest.raises(RuntimeError, match="choose the second action"):
        bpy.ops.humananim.multires_blend()
    with pytest.raises(RuntimeError, match="left limit"):
        bpy.ops.humananim.squeeze_stretch(frame=100, new_frame=2000, left_limit=1, right_limit=995)


BANDAI = __import__("pathlib").Path(__file__).resolve().parents[3] / "shared" / "data" / "mocap" / "bandai-namco-1"


@pytest.mark.parametrize("clip", ("walk_normal_001", "dash_happy_001"))
def test_denoise_cutoff_is_a_frequency_of_the_clip_own_rate(empty_scene, clip):
    """A 30 fps Bandai clip (corpus beside the repo; CC BY-NC, never copied): 8 Hz smooths the
    curves (the pyramid's finest band there is 7.5-15 Hz, and removing the bands wholly above the
    cut-off changed nothing); 15 Hz, its Nyquist frequency, is refused with a message and no
    action is written."""
    path = BANDAI / f"dataset-1_{clip}.bvh"
    if not path.exists():
        pytest.skip(f"the Bandai Namco corpus is not at {BANDAI}")
    rig = import_cmu(str(path))
    source = rig.animation_data.action
    assert bpy.ops.humananim.equalize(channels="ALL", mode="DENOISE", cutoff_hz=8.0,
                                      source_action=source.name) == {"FINISHED"}
    result = rig.animation_data.action
    assert result != source
    fc_src = next(fc for fc in action_api.fcurves_of(source, rig) if "UpperLeg_L" in fc.data_path
                  and "rotation" in fc.data_path)
    fc_new = next(fc for fc in action_api.fcurves_of(result, rig)
                  if fc.data_path == fc_src.data_path and fc.array_index == fc_src.array_index)
    end = int(fc_src.range()[1])
    values = np.array([[fc.evaluate(f) for f in range(1, end)] for fc in (fc_src, fc_new)])
    assert np.abs(values[1] - values[0]).max() > 1e-3  # the pyramid's bands: exactly 0
    rough = np.abs(np.diff(values, 2, axis=1)).mean(axis=1)
    assert rough[1] < 0.98 * rough[0]  # smoother: measured 0.87 and 0.96 (a walk curves mostly below 8 Hz)
    activate(rig, source)
    count = len(bpy.data.actions)
    with pytest.raises(RuntimeError, match="Nyquist"):
        bpy.ops.humananim.equalize(channels="ALL", mode="DENOISE", cutoff_hz=15.0, source_action=source.name)
    assert len(bpy.data.actions) == count
