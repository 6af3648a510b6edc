"""Cloth on the character's own skinned mesh (issue 29): a body grown over the rig (about 20,000
triangles, Blender's automatic weights, an Armature modifier) on the CMU walk and hop and two
Bandai Namco clips (a run and a dance), a skirt and a coat on each: no cloth vertex (particles
and rendered surface) more than 2 mm inside the body on any frame, mean edge length within 2 %
of rest on every frame."""

import os

import numpy as np
import pytest

from conftest import CMU_CLIPS, MOCAP

bpy = pytest.importorskip("bpy")

from humananim.humananim_addon.cloth import job as cloth  # noqa: E402
from humananim.humananim_addon.bvh_import import import_bvh  # noqa: E402
from humananim.solver.progress import run_to_end  # noqa: E402

BANDAI = os.path.join(MOCAP, "bandai-namco-1")
CLIPS = {"cmu_walk": CMU_CLIPS[0], "cmu_hop": CMU_CLIPS[1],
         "bandai_run": os.path.join(BANDAI, "dataset-1_run_normal_001.bvh"),
         "bandai_dance": os.path.join(BANDAI, "dataset-1_dance-short_normal_001.bvh")}
SECONDS = 1.0  # of each clip, at 30 simulated frames a second (CI time)
# known failures (issue 29 open, docs/cloth.md): on the Bandai Namco run the upper arm swings
# through the sleeveless coat and the garments' rendered surface is caught between body parts
KNOWN = {"bandai_run"}


@pytest.fixture(scope="module", params=sorted(CLIPS))
def character(request):
    path = CLIPS[request.param]
    if not os.path.isfile(path):
        pytest.skip(f"{path} is not here")
    bpy.ops.wm.read_homefile(use_empty=True)
    arm, _, _ = import_bvh(path)
    scene = bpy.context.scene
    scene.frame_set(scene.frame_start)
    body = cloth.add_skin_body(arm, scene, triangles=20000)
    return request.param, arm, scene, body


def simulate(arm, scene, body, garment, tmp):
    props = scene.humananim_cloth
    props.garment, props.armature, props.pin_group = garment, arm, "waist"
    props.body, props.collider = body, "MESH"
    fps = scene.render.fps / scene.render.fps_base
    props.frame_start = scene.frame_start
    props.frame_end = scene.frame_start + int(round(SECONDS * fps))
    props.frame_step = 0
    props.cache_dir = str(tmp)
    job = cloth.ClothJob(scene)
    job.measure_surface = True
    run_to_end(job.steps())
    return job


def test_the_grown_body_is_a_closed_skinned_mesh_of_the_asked_size(character):
    _, arm, scene, body = character
    mesh = body.data
    mesh.calc_loop_triangles()
    assert abs(len(mesh.loop_triangles) - 20000) < 0.1 * 20000
    tris = np.empty(len(mesh.loop_triangles) * 3, dtype=np.int64)
    mesh.loop_triangles.foreach_get("vertices", tris)
    edges = np.sort(tris.reshape(-1, 3)[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    _, uses = np.unique(edges, axis=0, return_counts=True)
    assert (uses == 2).all()  # closed, manifold
    weights = cloth.group_weights(body, [b.name for b in arm.data.bones])
    assert weights.sum(axis=1).min() > 0.5  # every vertex follows the bones
    assert [m.type for m in body.modifiers] == ["ARMATURE"] and body.modifiers[0].object == arm


@pytest.mark.parametrize("garment", ["skirt", "coat"])
def test_garment_stays_out_of_the_skinned_body_and_keeps_its_size(character, garment, tmp_path, request):
    name, arm, scene, body = character
    if name in KNOWN:
        request.applymarker(pytest.mark.xfail(strict=True, reason="deeper than 2 mm on the Bandai Namco run (issue 29)"))
    scene.frame_set(scene.frame_start)
    if garment == "skirt":
        obj = cloth.add_skirt(arm, scene, name="Skirt")
    else:
        obj = cloth.add_skirt(arm, scene, name="Coat", rings=12, columns=25, waist=1.0, length=1.1,
                              set_settings=False)
        obj.vertex_groups.remove(obj.vertex_groups[1])  # pinned ring: the nearest bones
    job = simulate(arm, scene, body, obj, tmp_path)
    assert type(job.sim.bodies[0]).__name__ == "SkinnedBody"
    assert len(job.frames_done) >= 29
    assert job.depth_max < 0.002, name  # metres, the particles on every frame
    assert job.surface_depth_max < 0.002, name  # every rendered vertex on every frame
    assert np.max(np.abs(job.stretch)) < 0.02, name
    assert job.sim.contacts["particles"] + job.sim.contacts["faces"] > 0  # the body did push it
    moved = np.linalg.norm(job.fine[-1] - job.fine[0], axis=1)
    assert moved.max() > 0.05  # the garment went along with the character
