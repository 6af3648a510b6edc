"""The body's volumes for collision tests (Huang 1996 sec. 4.6): capsules on the trunk, head and
limbs sized from the skeleton (a mesh can replace them), and the body sensors at elbows, hands,
knees, ankles and feet, with paired sensors along the forearms and shins for the special case of
fig. 4-20 (a segment crossing the body while its end sensors are outside)."""

from dataclasses import dataclass

import numpy as np

from ..body_roles import sided


@dataclass
class Capsule:
    name: str
    a: np.ndarray
    b: np.ndarray
    radius: float
    joints: tuple = ()  # bones the volume belongs to (not tested against their own sensors)

    def distance(self, points):
        p = np.asarray(points, float)
        ab = self.b - self.a
        t = np.clip(((p - self.a) @ ab) / max(ab @ ab, 1e-12), 0.0, 1.0)
        return np.linalg.norm(p - (self.a + t[..., None] * ab), axis=-1) - self.radius

    def normal(self, point):
        ab = self.b - self.a
        t = np.clip(((point - self.a) @ ab) / max(ab @ ab, 1e-12), 0.0, 1.0)
        d = point - (self.a + t * ab)
        n = np.linalg.norm(d)
        return d / n if n > 1e-9 else np.array([0.0, 0.0, 1.0])


def shoulder_width(skeleton, world):
    a = world[skeleton.role_index("upper_arm.L")][:3, 3]
    b = world[skeleton.role_index("upper_arm.R")][:3, 3]
    return float(np.linalg.norm(a - b))


def body_volumes(skeleton, world):
    """Trunk (pelvis to neck), head, thighs and shins as capsules in world, from the bones."""
    w = shoulder_width(skeleton, world)
    pelvis = skeleton.role_index("pelvis")
    neck = skeleton.role_index("neck")
    chest = skeleton.role_index("chest")
    head = skeleton.role_index("head")
    top = world[neck][:3, 3] if neck is not None else world[chest][:3, 3]
    trunk_joints = tuple(j for j in range(skeleton.joint_count)
                         if j == pelvis or j in (skeleton.ancestors(chest) + [chest]) or skeleton.parents[j] == pelvis
                         and skeleton.roles.role_of(skeleton.names[j]) in (None, "spine"))
    out = [Capsule("trunk", world[pelvis][:3, 3] + [0, 0, 0.05 * w], top - [0, 0, 0.18 * w], 0.31 * w,
                   trunk_joints + tuple(skeleton.index(n) for n in skeleton.roles.chain("spine")))]
    if head is not None:
        h = world[head]
        c = h[:3, :3] @ [0, 0.45 * skeleton.lengths[head], 0] + h[:3, 3]
        out.append(Capsule("head", c, c, 0.27 * w, (head,)))
    for s in ("L", "R"):
        th, sh = skeleton.role_index(sided("thigh", s)), skeleton.role_index(sided("shin", s))
        if th is not None and sh is not None:
            out.append(Capsule(f"thigh.{s}", world[th][:3, 3], world[sh][:3, 3], 0.2 * w, (th,)))
            # the shin, knee to ankle: what the other leg's knee, ankle and foot pass through
            ankle = world[sh][:3, :3] @ [0, skeleton.lengths[sh], 0] + world[sh][:3, 3]
            out.append(Capsule(f"shin.{s}", world[sh][:3, 3], ankle, 0.13 * w, (sh,)))
    return out


@dataclass
class BodySensor:
    name: str
    joint: int
    along: float
    radius: float
    chain_side: str  # 'L'/'R'
    limb: str  # 'arm' or 'leg'


def body_sensors(skeleton, world, paired=True):
    """Ten sensors (elbows, hands, knees, ankles, feet) and, with `paired`, two more along each
    forearm and shin (fig. 4-20)."""
    w = shoulder_width(skeleton, world)
    out = []
    for s in ("L", "R"):
        fa, hand = skeleton.role_index(sided("forearm", s)), skeleton.role_index(sided("hand", s))
        sh, foot = skeleton.role_index(sided("shin", s)), skeleton.role_index(sided("foot", s))
        if fa is not None:
            out.append(BodySensor(f"elbow.{s}", fa, 0.0, 0.12 * w, s, "arm"))
            if paired:
                out += [BodySensor(f"forearm.{s}.{k}", fa, a, 0.1 * w, s, "arm") for k, a in ((1, 0.35), (2, 0.7))]
        if hand is not None:
            out.append(BodySensor(f"hand.{s}", hand, 0.5, 0.12 * w, s, "arm"))
        if sh is not None:
            out.append(BodySensor(f"knee.{s}", sh, 0.0, 0.15 * w, s, "leg"))
            out.append(BodySensor(f"ankle.{s}", sh, 1.0, 0.12 * w, s, "leg"))
            if paired:
                out += [BodySensor(f"shin.{s}.{k}", sh, a, 0.13 * w, s, "leg") for k, a in ((1, 0.35), (2, 0.7))]
        if foot is not None:
            out.append(BodySensor(f"foot.{s}", foot, 0.6, 0.1 * w, s, "leg"))
    return out


def sensor_points(skeleton, sensors, world):
    """World centres (S, 3) of body sensors."""
    j = np.array([s.joint for s in sensors], int)
    local = np.zeros((len(sensors), 3))
    local[:, 1] = [s.along * skeleton.lengths[s.joint] for s in sensors]
    return (world[j, :3, :3] @ local[:, :, None])[:, :, 0] + world[j, :3, 3]


def own_volume(sensor, volume):
    """A leg's sensors ride inside its own thigh and shin volumes: those are not tested."""
    return sensor.limb == "leg" and volume.name in (f"thigh.{sensor.chain_side}", f"shin.{sensor.chain_side}")


def collisions(skeleton, sensors, world, volumes, margin=0.0):
    """(sensor index, volume index, depth, response direction) of every sensor inside a volume it
    is not attached to (a leg's sensors are not tested against its own thigh and shin)."""
    pts = sensor_points(skeleton, sensors, world)
    out = []
    for i, s in enumerate(sensors):
        for k, v in enumerate(volumes):
            if own_volume(s, v):
                continue
            d = s.radius - v.distance(pts[i])
            if d > -margin:
                out.append((i, k, float(d), v.normal(pts[i])))
    return out
