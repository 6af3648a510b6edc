"""Huang's closed loop on the skeletons the product builds from Blender armatures (de Leva
masses): a CMU clip imported by Blender's BVH importer and Rigify's human metarig (fingers, face
bones). Fixtures: tests/data/dynamics (see make_fixtures.py there).

Stated accuracy of full tracking (tracking = 1, root_support = 1), measured on these fixtures:
  * joint angles: the angle between simulated and source local rotations of every bone that
    carries mass; fingers lighter than Settings.kinematic_fraction follow the source exactly and
    are included (their error is zero); massless helper bones are not (they turn no mass, and
    their parents and children are measured);
  * positions: every bone head (massless bones included), world.
"""

import json
from pathlib import Path

import numpy as np
import pytest

from humananim.solver import rotations
from humananim.solver.body_roles import RoleMap
from humananim.solver.dynamics import (GroundModel, Settings, SimulationError, build_model, motion_floor,
                                       default_contacts, desired_motion, point_positions, simulate)
from humananim.solver.skeleton import Skeleton
from humananim.solver.trajectories import Trajectories

DATA = Path(__file__).parent.parent / "data" / "dynamics"


def load(name, frames=None):
    z = np.load(DATA / f"{name}.npz")
    roles = RoleMap({k: tuple(v) for k, v in json.loads(str(z["roles"])).items()})
    sk = Skeleton(names=tuple(str(n) for n in z["names"]), parents=z["parents"], rest=z["rest"],
                  lengths=z["lengths"], connected=z["connected"], dof=z["dof"], limits=z["limits"],
                  mass=z["mass"], com=z["com"], inertia=z["inertia"], roles=roles,
                  unit_scale=float(z["unit_scale"]))
    s = slice(None) if frames is None else slice(0, frames)
    tr = Trajectories(z["frames"][s], float(z["fps"]), z["rotations"][s], z["translations"][s],
                      z["armature_to_world"])
    return sk, tr


def held_still(tr, seconds=3.0):
    """The first frame of a motion held for `seconds`."""
    n = int(round(seconds * tr.fps)) + 1
    return Trajectories(np.arange(n) + tr.frames[0], tr.fps, np.repeat(tr.rotations[:1], n, axis=0),
                        np.repeat(tr.translations[:1], n, axis=0), tr.armature_to_world)


def test_motion_floor_is_the_lowest_contact_point(cmu):
    sk, tr = cmu
    assert motion_floor(sk, tr) == pytest.approx(float(lowest_points(sk, tr).min()))


def lowest_points(sk, tr):
    """Per frame, the lowest point of any contact sphere (world z, metres)."""
    m = build_model(sk, reference_basis=tr.basis()[0])
    d = m.create_data()
    c = default_contacts(m)
    return np.array([(point_positions(m, d, q, c.joints, c.points)[:, 2] - c.radii).min()
                     for q in desired_motion(m, sk, tr)[0]])


def tracking_errors(sk, tr, res):
    """Joint-angle errors (F, bones with mass) in degrees, bone-head errors (F, J) in metres."""
    rot = np.degrees(rotations.angle_between(res.trajectories.rotations, tr.rotations))[:, sk.mass > 0]
    w0, w1 = tr.world_frames(sk), res.trajectories.world_frames(sk)
    return rot, np.linalg.norm(w1[..., :3, 3] - w0[..., :3, 3], axis=-1)


def rms(x):
    return float(np.sqrt(np.mean(np.square(x))))


# ---- full tracking ----

@pytest.fixture(scope="module")
def cmu():
    return load("cmu_131_01")


@pytest.fixture(scope="module")
def cmu_tracked(cmu):
    sk, tr = cmu
    ground = GroundModel(height=float(lowest_points(sk, tr).min()))  # the clip's own floor
    return simulate(sk, tr, Settings(ground=ground))


def test_cmu_full_tracking_with_unbounded_strength():
    """The dynamics and the controller alone: measured 0.6 deg RMS / 6.7 deg max (a toe),
    0.12 cm RMS / 0.96 cm max on the first 180 frames of 131_01 at 120 fps."""
    sk, tr = load("cmu_131_01", frames=180)
    ground = GroundModel(height=float(lowest_points(sk, tr).min()))
    res = simulate(sk, tr, Settings(ground=ground, strength_scale=1e3))
    rot, pos = tracking_errors(sk, tr, res)
    assert rms(rot) < 2.0 and rot.max() < 10.0
    assert rms(pos) < 0.02 and pos.max() < 0.05
    assert np.abs(res.usage[:-1]).max() < 0.01


def test_cmu_full_tracking_with_default_strength(cmu, cmu_tracked):
    """Default strength: the fast swing of the right leg (knee and hip turning at 6-15 rad/s)
    still exceeds the strength model briefly, so the leg lags a little. Measured on frames
    1-200: 0.66 deg RMS / 6.0 deg max, 0.31 cm RMS / 5.1 cm max (the right toe), usage 2.8."""
    sk, tr = cmu
    rot, pos = tracking_errors(sk, tr, cmu_tracked)
    assert rms(rot) < 2.0 and rot.max() < 10.0
    assert rms(pos) < 0.01 and pos.max() < 0.08
    usage = np.abs(cmu_tracked.usage[:-1])
    clamped = {cmu_tracked.dof_names[d].split(".")[0] for d in np.flatnonzero(usage.max(axis=0) > 1.0)}
    assert clamped <= {"RightHip", "RightKnee", "RightAnkle", "LeftHip"}
    assert usage.max() < 5.0
    # light distal segments: toes within their strength, fingers follow the source kinematically
    for name in ("LeftToe", "RightToe"):
        d = [i for i, n in enumerate(cmu_tracked.dof_names) if n.startswith(name + ".")]
        assert usage[:, d].max() < 1.0
    assert not any(n.startswith(("LThumb", "RThumb", "LFingers", "RFingers")) for n in cmu_tracked.dof_names)


def test_metarig_full_tracking():
    """Rigify metarig, 90 frames at 30 fps: the pelvis stays up while the legs bend, so the feet
    leave the floor and come back; the floor is put at the lowest point of the source. Measured:
    0.10 deg RMS / 0.53 deg max, 0.03 cm RMS / 0.23 cm max, usage 0.29 at most."""
    sk, tr = load("metarig_legs")
    ground = GroundModel(height=float(lowest_points(sk, tr).min()) - 0.005)
    res = simulate(sk, tr, Settings(ground=ground))
    rot, pos = tracking_errors(sk, tr, res)
    assert rms(rot) < 2.0 and rot.max() < 10.0
    assert rms(pos) < 0.02 and pos.max() < 0.05
    assert res.model.nv - 6 < 100  # fingers carry no dynamics of their own


# ---- ragdoll ----

@pytest.mark.parametrize("name", ["metarig_legs", "cmu_131_01"])
def test_ragdoll_falls_and_rests_on_the_ground(name):
    """The first pose held still, no controller, no support: the body falls, lands without
    exploding or sinking and lies still."""
    sk, tr = load(name, frames=2)
    still = held_still(tr, 4.0)
    res = simulate(sk, still, Settings(tracking=0.0, root_support=0.0))
    w = res.trajectories.world_frames(sk)[..., :3, 3]
    assert np.all(np.isfinite(w))
    root = w[:, sk.root, 2]
    assert root[-1] < 0.4 * root[0]  # it fell
    last = int(0.5 * still.fps)
    speed = np.linalg.norm(np.diff(w[-last - 1:], axis=0), axis=-1) * still.fps
    # measured over the last 0.5 s of 4 s: pelvis 1.1 cm/s (metarig), 0 (CMU); median 0
    assert speed[:, sk.root].max() < 0.05
    assert np.median(speed) < 0.01
    low = lowest_points(sk, res.trajectories)
    assert low.min() > -0.04  # impact: measured 2.5 cm (metarig), 1.2 cm (CMU)
    assert low[-last:].min() > -0.003  # at rest: measured 0.4 mm (metarig), 0.5 mm (CMU)
    weight = (sk.total_mass) * 9.81
    assert res.contact_force[-1, 2] == pytest.approx(weight, rel=0.1)


def test_divergence_is_reported_as_a_simulation_error():
    """No numpy error escapes: a step far too long for the contact makes a SimulationError."""
    sk, tr = load("cmu_131_01", frames=30)
    bad = Settings(tracking=0.0, root_support=0.0, forward="aba", max_step=1.0 / 120,
                   ground=GroundModel(height=float(lowest_points(sk, tr).max()) + 0.3))
    with pytest.raises(SimulationError, match="diverged"):
        simulate(sk, tr, bad)


def test_limbs_outside_the_pelvis_hierarchy_are_refused_not_dropped():
    """A rig whose thigh hangs from a control bone (not below the pelvis) can't be simulated:
    refused with the part named, rather than simulated without the leg."""
    from dataclasses import replace
    sk, tr = load("metarig_legs", frames=3)
    thigh = sk.index(sk.roles.bone("thigh.L"))
    parents = sk.parents.copy()
    parents[thigh] = -1  # a second root, like DEF-thigh.L under ORG-spine
    loose = replace(sk, parents=parents)
    with pytest.raises(SimulationError, match=r"thigh\.L"):
        simulate(loose, tr)
