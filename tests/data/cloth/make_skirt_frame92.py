"""Writes skirt_frame92.npz for tests/solver/test_cloth_frame_end.py: the benchmark's thesis-size
skirt on capsules (benchmarks/cloth.py: 4 s of the CMU walk at 30 fps) as its solver saw it, the
state after frame 88 and the inputs of frames 89-92, recorded in Blender 4.2 from the solver
before collisions were resolved inside the frame-end Provot sweeps (commit e71ec42), whose mean
shortening reached 2.55 % at frame 92:

    cd <checkout of e71ec42> && PYTHONPATH=.. <bpy 4.2 python> <this file>
"""

import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).parent
FIRST, LAST = 89, 92


def main():
    import humananim
    from humananim.humananim_addon.cloth import job as cloth
    from humananim.humananim_addon.cli import _chatter_to_stderr
    from humananim.solver.cloth import simulation
    sys.path.insert(0, str(Path(humananim.__file__).parent / "benchmarks"))
    import cloth as bench

    out = {"ends": [], "pins": []}
    step = simulation.ClothSimulation.step

    def recording_step(sim, pin_targets=None, dt=1.0 / 30.0):
        frame = sim.frames + 1
        if frame == FIRST:
            out.update(rest=sim.mesh.rest, faces=sim.mesh.faces, pinned=sim.pins, x=sim.x.copy(), v=sim.v.copy(),
                       thickness=sim.params.thickness, radii=sim.bodies[0].radius, dt=dt)
        if FIRST <= frame <= LAST:
            body = sim.bodies[0]  # its motion over this frame is set before the step
            out["ends"].append(np.array([body.a0, body.b0, body.a1, body.b1]))
            out["pins"].append(np.array(pin_targets))
        return step(sim, pin_targets, dt)

    simulation.ClothSimulation.step = recording_step
    humananim.register()
    with _chatter_to_stderr():
        arm, scene, last = bench.scene_at_30fps(4.0)
        scene.frame_set(1)
        skirt = cloth.add_skirt(arm, scene, name="Skirt")
        _, job = bench.our_run(arm, scene, skirt, None, "CAPSULES", last)
    out["recorded_stretch"] = np.asarray(job.stretch)[FIRST:LAST + 1]
    np.savez_compressed(HERE / "skirt_frame92.npz", **out)
    print("mean stretch of frames %d-%d as recorded:" % (FIRST, LAST), out["recorded_stretch"])


if __name__ == "__main__":
    main()
