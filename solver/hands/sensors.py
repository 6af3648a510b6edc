"""Sphere sensors on a hand (Huang 1996 §4.7, fig. 4-25): small spheres along each finger bone and
on the palm, placed from the rig's bones, for contact with objects. No bpy: the hands issue can
add sensors (more per segment, other sizes) by extending `default_hand_sensors` or passing its
own list."""

from dataclasses import dataclass

import numpy as np

from ..body_roles import FINGERS, sided


@dataclass(frozen=True)
class SphereSensor:
    name: str
    joint: int  # skeleton joint the sphere rides on
    finger: str  # 'thumb'..'pinky' or 'palm'
    along: float  # position along the bone (0 head, 1 tail) on its Y axis
    radius: float  # metres
    offset: tuple = (0.0, 0.0, 0.0)  # extra offset in the bone's frame, metres


def default_hand_sensors(skeleton, side, radius_scale=0.35):
    """Two spheres per finger bone (mid-bone and tip) and three on the palm, sized from the
    bones' lengths."""
    out = []
    for f in FINGERS:
        for k, name in enumerate(skeleton.roles.chain(sided(f, side))):
            j = skeleton.index(name)
            r = max(0.004, radius_scale * 0.5 * skeleton.lengths[j])
            out.append(SphereSensor(f"{f}.{k}.mid", j, f, 0.5, r))
            out.append(SphereSensor(f"{f}.{k}.tip", j, f, 1.0, r))
    hand = skeleton.role_index(sided("hand", side))
    if hand is not None:
        r = max(0.008, 0.18 * skeleton.lengths[hand])
        for along in (0.35, 0.6, 0.85):
            out.append(SphereSensor(f"palm.{along:g}", hand, "palm", along, r))
    return out


def sensors_from_mesh(skeleton, sensors, world, vertices, owner):
    """Resize sensors to the skin (Huang 1996 sec. 4.3.1: each sphere fitted to its joint's
    shape): a sensor's radius is the median distance from its bone's axis of the skin vertices
    the bone owns (`owner[v]` = joint index of the vertex's strongest weight, world `vertices`),
    near the sensor's place along the bone. Sensors whose bone owns too few vertices keep their
    size from the bones."""
    vertices = np.asarray(vertices, float)
    owner = np.asarray(owner, int)
    out = []
    for s in sensors:
        f = world[s.joint]
        length = skeleton.lengths[s.joint]
        local = (vertices[owner == s.joint] - f[:3, 3]) @ f[:3, :3]
        near = local[np.abs(local[:, 1] - s.along * length) < 0.3 * length] if len(local) else local
        if len(near) < 4:
            out.append(s)
            continue
        r = float(np.median(np.linalg.norm(near[:, [0, 2]], axis=1)))
        out.append(SphereSensor(s.name, s.joint, s.finger, s.along, float(np.clip(r, 0.003, 0.05)), s.offset))
    return out


def sensor_layout(sensors, skeleton):
    """(joints (S,), centres in their bones' frames (S, 3)) of the sensors."""
    joints = np.array([s.joint for s in sensors], int)
    local = np.array([[0.0, s.along * skeleton.lengths[s.joint], 0.0] for s in sensors]).reshape(-1, 3)
    return joints, local + np.array([s.offset for s in sensors], float).reshape(-1, 3)


def sensor_centres(sensors, world, skeleton):
    """World centres (..., S, 3) of the sensors for world joint frames (..., J, 4, 4)."""
    joints, local = sensor_layout(sensors, skeleton)
    f = np.asarray(world)[..., joints, :, :]
    return (f[..., :3, :3] @ local[:, :, None])[..., 0] + f[..., :3, 3]


def length(v):
    """Euclidean lengths (...,) of vectors (..., k)."""
    return np.linalg.norm(v, axis=-1)


@dataclass
class Sphere:
    centre: np.ndarray
    radius: float

    def distance(self, points):
        return length(np.asarray(points) - self.centre) - self.radius

    def transformed(self, m):
        return Sphere(m[:3, :3] @ self.centre + m[:3, 3], self.radius)


@dataclass
class Box:
    """A box: world frame (4, 4) of its centre and half extents along its axes."""
    frame: np.ndarray
    half: np.ndarray

    def distance(self, points):
        p = np.asarray(points) - self.frame[:3, 3]
        local = p @ self.frame[:3, :3]
        q = np.abs(local) - self.half
        return length(np.maximum(q, 0.0)) + np.minimum(q.max(axis=-1), 0.0)

    def transformed(self, m):
        return Box(m @ self.frame, self.half)


def contacts(centres, radii, shape, tolerance=0.002):
    """Which sensors touch the shape (sphere surface within `tolerance` of it or inside), and how
    deep each is (positive inside)."""
    depth = np.asarray(radii) - shape.distance(centres)
    return depth > -tolerance, depth
