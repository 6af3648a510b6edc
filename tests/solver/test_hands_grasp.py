"""Automatic grasping (Huang 1996 sec. 4.3) and the issue's grasp benchmark: spheres, boxes,
cylinders and frusta from 1 cm to 60 cm within reach around the character: the chosen type
matches the table; every finger the type uses ends touching the surface (within 2 mm); nothing
penetrates it by more than 1 mm on any frame; the hand reaches without passing through the body;
two hands for the large ones."""

import numpy as np
import pytest

from hands_cases import SPOTS, expected, frame, metarig, object_cases
from humananim.solver.hands import grasp as G
from humananim.solver.hands.checks import grasp_measures
from humananim.solver.hands.grasp import TYPE_FINGERS
from humananim.solver.hands.primitives import Box, Cylinder, Sphere
from humananim.solver.hands.sensors import sensor_centres

CASES = object_cases()


@pytest.fixture(scope="module")
def rig():
    return metarig()


@pytest.mark.slow
@pytest.mark.parametrize("name,size,spot,shape", CASES,
                         ids=[f"{n}-{s * 100:g}cm-{k % 3}" for k, (n, s, _, _) in enumerate(CASES)])
def test_grasp_benchmark(rig, name, size, spot, shape):
    sk, basis, a2w = rig
    result = G.grasp(sk, basis, a2w, shape)
    m = grasp_measures(sk, result, shape, a2w)
    assert (m["type"], m["hands"]) == expected(name, size)
    for h in result.hands:
        assert set(TYPE_FINGERS[result.gtype]) <= set(h.fingers_touching)
    assert m["max_finger_gap_m"] <= 0.002, m["finger_gaps_m"]
    assert m["max_penetration_m"] <= 0.001
    assert m["max_body_penetration_m"] == 0.0
    assert m["reach_error_m"] < 0.002
    if m["hands"] == 2:
        assert {h.side for h in result.hands} == {"L", "R"}


def test_table_is_relative_to_the_hand(rig):
    sk, basis, a2w = rig
    ball = Sphere(np.zeros(3), 0.04)  # 8 cm: one adult hand wraps it ...
    assert G.grasp_type(ball, 0.20) == ("WRAP", 1)
    assert G.grasp_type(ball, 0.10) == ("WRAP", 2)  # ... a small child's hand does not
    assert G.grasp_type(ball, 0.40)[0] == "TRIPOD"


def test_grasp_frame_rules(rig):
    """The thumb stays on the side the eye sees, the palm does not face away from the body, and
    of the allowed frames the least change of hand pose wins."""
    sk, basis, a2w = rig
    world = sk.world_frames(basis, a2w)
    geom = G.hand_geometry(sk, "R", world)
    hand = sk.role_index("hand.R")
    box = Box(frame(SPOTS[0]), np.array([0.03, 0.04, 0.05]))
    body, eye = G.body_landmarks(sk, world)
    loc = np.zeros((0, 4))
    cands = G.candidates(box, "WRAP", geom, world[hand], eye, body, loc)
    assert cands and all(a.cost <= b.cost for a, b in zip(cands, cands[1:]))
    for c in cands:
        h = c.hand_world
        palm = h[:3, :3] @ geom.palm + h[:3, 3]
        n = h[:3, :3] @ geom.normal
        away = (palm - body) * [1, 1, 0]
        assert n @ away / np.linalg.norm(away) <= 0.5 + 1e-9
        thumb = -(h[:3, :3] @ geom.across)
        to_eye = eye - palm
        assert thumb @ to_eye >= -0.2 * np.linalg.norm(to_eye) - 1e-9
    # an eye behind the character flips which frames keep the thumb visible
    behind = G.candidates(box, "WRAP", geom, world[hand], eye + [0, 3.0, 0], body, loc)
    assert {tuple(np.round(c.hand_world[:3, 3], 4)) for c in cands} != \
        {tuple(np.round(c.hand_world[:3, 3], 4)) for c in behind}


def test_reach_is_a_pd_servo_not_a_blend():
    q = G.pd_servo(np.zeros(2), np.array([1.0, -0.5]), 24, 24.0)
    assert np.allclose(q[0], 0) and np.allclose(q[-1], [1.0, -0.5])
    # critically damped: monotone, fast start then slow settling, no overshoot
    assert np.all(np.diff(q[:, 0]) >= -1e-12) and q[:, 0].max() <= 1.0 + 1e-12
    lin = np.linspace(0, 1, 25)
    assert not np.allclose(q[:, 0], lin, atol=0.05)
    assert abs(q[-2, 0] - 1.0) < 0.01  # settled within the duration
    # eq. 4-1 with a desired velocity: tracking a moving target
    qv = G.pd_servo(np.zeros(1), np.zeros(1), 24, 24.0, qd_vel=np.ones(1))
    assert qv[12, 0] > 0.0


def test_touching_sensor_stops_its_ancestors_only(rig):
    """A wall touched by the index's first phalanx stops that joint; the two distal joints go on
    closing (sec. 4.3.4)."""
    sk, basis, a2w = rig
    world = sk.world_frames(basis, a2w)
    geom = G.hand_geometry(sk, "R", world)
    h = world[sk.role_index("hand.R")]
    chains = G.finger_chains(sk, "R")
    index = chains["index"]
    pattern = G.builtin_pattern(sk, "R", world, geom, "WRAP", geom.palm + geom.normal * 0.05, basis=basis)
    free, _, _ = G.close_fingers(sk, "R", basis, world, pattern, [], frames=12)
    # a small ball where the index's first phalanx passes halfway through its motion
    half = basis.copy()
    for j, rots in free.items():
        half[j, :3, :3] = rots[6]
    wh = sk.world_frames(half, a2w)
    p = wh[index[0]][:3, :3] @ [0, 0.6 * sk.lengths[index[0]], 0] + wh[index[0]][:3, 3]
    n = h[:3, :3] @ geom.normal
    ball = Sphere(p + n * 0.02, 0.01)
    track, touching, sensors = G.close_fingers(sk, "R", basis, world, pattern, [ball], frames=12)
    assert any(k.startswith("index.0") for k in touching)
    assert not np.allclose(track[index[0]][-1], free[index[0]][-1], atol=1e-3)  # stopped early
    # the distal joints kept moving after the proximal one stopped
    stop = next(t for t in range(1, 13) if np.allclose(track[index[0]][t], track[index[0]][-1]))
    assert not np.allclose(track[index[2]][stop], track[index[2]][-1], atol=1e-4)
    # other fingers unaffected
    assert np.allclose(track[chains["pinky"][0]][-1], free[chains["pinky"][0]][-1])


def test_pose_pattern_and_type_override(rig):
    sk, basis, a2w = rig
    shape = Cylinder(frame(SPOTS[0]), 0.016, 0.12)
    assert G.grasp_type(shape, 0.2)[0] == "PINCH"
    r = G.grasp(sk, basis, a2w, shape, gtype="WRAP")
    assert r.gtype == "WRAP" and set(r.hands[0].fingers_touching) == set(TYPE_FINGERS["WRAP"])
    # an animator's pose (fingers curled a fixed way) as the pattern
    pose = r.basis[-1]
    r2 = G.grasp(sk, basis, a2w, shape, gtype="WRAP", pattern=pose)
    radii = np.array([s.radius for s in r2.hands[0].sensors])
    d = shape.distance(sensor_centres(r2.hands[0].sensors, r2.world, sk)) - radii
    assert d.min() > -0.001 and r2.hands[0].fingers_touching


def test_sensors_sized_from_the_skin(rig):
    """Sec. 4.3.1: each sphere fitted to its joint's shape: skin vertices 7 mm around the index
    bones give 7 mm sensors there; bones without skin keep the bone-based size."""
    from humananim.solver.hands.sensors import default_hand_sensors, sensors_from_mesh
    sk, basis, a2w = rig
    world = sk.world_frames(basis, a2w)
    chains = G.finger_chains(sk, "R")
    verts, owner = [], []
    for j in chains["index"]:
        f = world[j]
        for t in np.linspace(0, 1, 9):
            for a in np.linspace(0, 2 * np.pi, 12, endpoint=False):
                p = np.array([0.007 * np.cos(a), t * sk.lengths[j], 0.007 * np.sin(a)])
                verts.append(f[:3, :3] @ p + f[:3, 3])
                owner.append(j)
    base = default_hand_sensors(sk, "R")
    sized = sensors_from_mesh(sk, base, world, np.array(verts), np.array(owner))
    for a, b in zip(base, sized):
        if a.joint in chains["index"]:
            assert b.radius == pytest.approx(0.007, abs=1e-6)
        else:
            assert b == a
    # a grasp with them keeps the proof's limits
    shape = Cylinder(frame(SPOTS[0]), 0.03, 0.08)
    r = G.grasp(sk, basis, a2w, shape, hand_sensors={"R": sized})
    m = grasp_measures(sk, r, shape, a2w)
    assert r.hands[0].sensors == sized
    assert m["max_penetration_m"] <= 0.001 and m["max_finger_gap_m"] <= 0.002
