"""A small BVH reader (no bpy): hierarchy, channels and motion, converted to Blender's Z-up axes
the way Blender's importer does (Blender (x, y, z) = BVH (x, -z, y)), and turned into a
`Skeleton` plus `Trajectories` of pose-bone bases."""

from dataclasses import dataclass

import numpy as np

from . import rotations
from .errors import MotionError
from .skeleton import Skeleton
from .trajectories import Trajectories

# BVH (Y up) to Blender (Z up): x stays, BVH y becomes z, BVH z becomes -y
Y_UP_TO_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
_AXES = {"X": 0, "Y": 1, "Z": 2}


@dataclass
class BVH:
    names: tuple
    parents: np.ndarray  # (J,)
    offsets: np.ndarray  # (J, 3) head relative to the parent's head, Z up, scaled
    end_sites: np.ndarray  # (J, 3) end-site offset, NaN where there is none
    channels: tuple  # per joint, channel names in file order
    frame_time: float
    root_positions: np.ndarray  # (F, 3) root head in the world, Z up, scaled
    rotations: np.ndarray  # (F, J, 4) local rotations in Z-up world-aligned joint frames
    values: np.ndarray = None  # (F, C) the channels as the file has them (file units, degrees, Y up)

    @property
    def fps(self):
        return 1.0 / self.frame_time

    @property
    def frame_count(self):
        return len(self.rotations)

    def positions(self):
        """World head positions (F, J, 3) by forward kinematics of the BVH itself."""
        F, J = self.rotations.shape[:2]
        mats = rotations.to_matrix(self.rotations)
        world_r = np.empty((F, J, 3, 3))
        pos = np.empty((F, J, 3))
        for j, p in enumerate(self.parents):
            if p < 0:
                world_r[:, j], pos[:, j] = mats[:, j], self.root_positions
            else:
                world_r[:, j] = world_r[:, p] @ mats[:, j]
                pos[:, j] = pos[:, p] + world_r[:, p] @ self.offsets[j]
        return pos


def read(path, scale=1.0):
    with open(path) as f:
        return parse(f.read(), scale)


def parse(text, scale=1.0):
    tokens = text.split()
    names, parents, offsets, ends, channels = [], [], [], [], []
    stack, i = [], 0
    if not tokens or tokens[0] != "HIERARCHY":
        raise MotionError("not a BVH file: no HIERARCHY")
    i = 1
    while i < len(tokens) and tokens[i] != "MOTION":
        tok = tokens[i]
        if tok in ("ROOT", "JOINT"):
            names.append(tokens[i + 1])
            parents.append(stack[-1] if stack else -1)
            offsets.append(np.zeros(3))
            ends.append(np.full(3, np.nan))
            channels.append(())
            stack.append(len(names) - 1)
            i += 2
        elif tok == "End":
            i, end = _end_site(tokens, i)
            ends[stack[-1]] = end
        elif tok == "OFFSET":
            offsets[stack[-1]] = np.array(tokens[i + 1:i + 4], float)
            i += 4
        elif tok == "CHANNELS":
            n = int(tokens[i + 1])
            channels[stack[-1]] = tuple(tokens[i + 2:i + 2 + n])
            i += 2 + n
        elif tok == "}":
            stack.pop()
            i += 1
        else:
            i += 1
    if not names:
        raise MotionError("the BVH file has no joints")
    i += 1
    frames = int(tokens[i + 1])
    frame_time = float(tokens[i + 4])
    width = sum(len(c) for c in channels)
    values = np.array(tokens[i + 5:i + 5 + frames * width], float)
    if values.size != frames * width:
        raise MotionError(f"the BVH motion has {values.size} values, expected {frames * width}")
    values = values.reshape(frames, width)
    return _convert(names, parents, offsets, ends, channels, frame_time, values, scale)


def _end_site(tokens, i):
    # End Site { OFFSET x y z }
    j = tokens.index("OFFSET", i)
    return tokens.index("}", j) + 1, np.array(tokens[j + 1:j + 4], float)


def _convert(names, parents, offsets, ends, channels, frame_time, values, scale):
    c = Y_UP_TO_Z_UP
    J, F = len(names), len(values)
    offsets = np.array(offsets) @ c.T * scale
    ends = np.array(ends) @ c.T * scale
    rot = np.zeros((F, J, 4))
    rot[..., 0] = 1.0
    root_pos = np.zeros((F, 3))
    col = 0
    for j, chans in enumerate(channels):
        for ch in chans:
            axis = _AXES[ch[0].upper()]
            v = values[:, col]
            col += 1
            if ch.lower().endswith("position"):
                if parents[j] < 0:
                    root_pos[:, axis] += v
            else:  # channels listed outermost first: R = R(c1) R(c2) R(c3)
                rot[:, j] = rotations.multiply(rot[:, j], rotations.axis_rotation(axis, np.radians(v)))
    # change of basis to Z up: R' = C R C^T, as quaternions
    cq = rotations.from_matrix(c)
    rot = rotations.multiply(rotations.multiply(cq, rot), rotations.conjugate(cq))
    root = int(np.flatnonzero(np.array(parents) < 0)[0])
    root_pos = root_pos @ c.T * scale + offsets[root]
    return BVH(tuple(names), np.array(parents), offsets, ends, tuple(channels), frame_time,
               root_pos, rotations.make_continuous(rot), values)


def rest_heads(bvh):
    heads = np.zeros_like(bvh.offsets)
    for j, p in enumerate(bvh.parents):
        heads[j] = bvh.offsets[j] + (heads[p] if p >= 0 else 0.0)
    return heads


def rest_tails(bvh, min_length=0.01):
    """Bone tails as Blender's importer places them: the average of the children's heads, else the
    end site, else along the parent bone; bones shorter than `min_length` get that length up +Z."""
    heads = rest_heads(bvh)
    tails = np.empty_like(heads)
    for j, p in enumerate(bvh.parents):
        kids = np.flatnonzero(bvh.parents == j)
        if len(kids):
            tails[j] = heads[kids].mean(axis=0)
        elif np.all(np.isfinite(bvh.end_sites[j])):
            tails[j] = heads[j] + bvh.end_sites[j]
        else:
            d = heads[j] - heads[p] if p >= 0 else np.array([0.0, 0.0, 1.0])
            tails[j] = heads[j] + 0.5 * d
        if np.linalg.norm(tails[j] - heads[j]) < min_length:
            tails[j] = heads[j] + np.array([0.0, 0.0, min_length])
    return tails


# common BVH joint names (CMU, Mixamo-like) to body roles; a joint names the bone it starts
_ROLE_NAMES = {
    "pelvis": ("hips",), "spine": ("lowerback", "spine", "chest"), "chest": ("chest2", "spine2"),
    "neck": ("lowerneck", "neck"), "head": ("head",),
    "clavicle": ("collar", "shoulder_l", "clavicle"), "upper_arm": ("shoulder", "arm"),
    "forearm": ("elbow", "forearm"), "hand": ("wrist", "hand"), "thigh": ("hip", "upleg"),
    "shin": ("knee", "leg"), "foot": ("ankle", "foot"), "toe": ("toe", "toebase"),
}


def guess_roles(names):
    """A RoleMap for common BVH joint names (CMU's LeftHip, LeftKnee, ...); unknown names get none."""
    from .body_roles import RoleMap
    bones = {}
    for n in names:
        low = n.lower()
        side = "L" if low.startswith("left") else "R" if low.startswith("right") else None
        core = low[4:] if side == "L" else low[5:] if side == "R" else low
        for role, keys in _ROLE_NAMES.items():
            if core in keys:
                if role in ("clavicle", "upper_arm", "forearm", "hand", "thigh", "shin", "foot", "toe"):
                    if side is None:
                        break
                    role = f"{role}.{side}"
                elif side is not None:
                    break
                if role == "spine" or role not in bones:
                    bones[role] = bones.get(role, ()) + (n,)
                break
    if "chest" not in bones and len(bones.get("spine", ())) > 1:
        bones["chest"] = bones["spine"][-1:]
    return RoleMap(bones)


def skeleton(bvh, mass_model=None, roles=None):
    """A Skeleton of the BVH: bones from each joint's head to its tail (Blender's rest frames with
    roll 0), three free axes everywhere, no limits. mass_model(skeleton) -> (mass, com, inertia);
    default: 70 kg by body role (figures.role_mass_model, de Leva's fractions)."""
    from .dynamics.figures import bone_frame, role_mass_model
    heads, tails = rest_heads(bvh), rest_tails(bvh)
    J = len(bvh.names)
    rest = np.array([bone_frame(h, t) for h, t in zip(heads, tails)])
    lengths = np.linalg.norm(tails - heads, axis=1)
    connected = np.array([p >= 0 and np.allclose(tails[p], heads[j]) for j, p in enumerate(bvh.parents)])
    limits = np.zeros((J, 3, 2))
    limits[..., 0], limits[..., 1] = -np.inf, np.inf
    sk = Skeleton(names=bvh.names, parents=bvh.parents, rest=rest, lengths=lengths,
                  connected=connected, dof=np.ones((J, 3), bool), limits=limits, mass=np.zeros(J),
                  com=np.zeros((J, 3)), inertia=np.zeros((J, 3, 3)),
                  roles=roles if roles is not None else guess_roles(bvh.names))
    return sk.with_mass_model(*(mass_model or role_mass_model)(sk))


def trajectories(bvh, skeleton):
    """Pose-bone bases of the BVH motion: basis = A' R A for a bone of rest rotation A and BVH
    local rotation R; the root also moves by its position channels."""
    rest_q = rotations.from_matrix(skeleton.rest[:, :3, :3])
    local = rotations.multiply(rotations.multiply(rotations.conjugate(rest_q), bvh.rotations), rest_q)
    F, J = bvh.rotations.shape[:2]
    trans = np.zeros((F, J, 3))
    root = int(np.flatnonzero(bvh.parents < 0)[0])
    a = skeleton.rest[root, :3, :3]
    trans[:, root] = (bvh.root_positions - skeleton.rest[root, :3, 3]) @ a
    return Trajectories(frames=np.arange(1, F + 1), fps=bvh.fps,
                        rotations=rotations.make_continuous(local), translations=trans,
                        armature_to_world=np.eye(4))
