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
    joint_offsets: np.ndarray = None  # (F, J, 3) each head from its parent's per frame, Z up, scaled
    file_offsets: np.ndarray = None  # (J, 3) OFFSETs as written (file units, Y up)
    file_ends: np.ndarray = None  # (J, 3) End Site OFFSETs as written, NaN where there is none
    scale: float = 1.0  # metres per file unit used

    @property
    def fps(self):
        return 1.0 / self.frame_time

    @property
    def frame_count(self):
        return len(self.rotations)

    def positions(self, with_ends=False):
        """World head positions (F, J, 3) by forward kinematics of the BVH itself (a joint's
        position channels place it as Blender's importer does); with_ends adds the end sites
        after the heads (F, J + E, 3)."""
        F, J = self.rotations.shape[:2]
        mats = rotations.to_matrix(self.rotations)
        world_r = np.empty((F, J, 3, 3))
        pos = np.empty((F, J, 3))
        local = self.joint_offsets if self.joint_offsets is not None else np.broadcast_to(self.offsets, (F, J, 3))
        for j, p in enumerate(self.parents):
            if p < 0:
                world_r[:, j], pos[:, j] = mats[:, j], self.root_positions
            else:
                world_r[:, j] = world_r[:, p] @ mats[:, j]
                pos[:, j] = pos[:, p] + (world_r[:, p] @ local[:, j, :, None])[..., 0]
        if not with_ends:
            return pos
        ends = [pos[:, j] + world_r[:, j] @ e for j, e in enumerate(self.end_sites) if np.all(np.isfinite(e))]
        return np.concatenate((pos, np.stack(ends, axis=1)), axis=1) if ends else pos


def read(path, scale=1.0):
    try:
        with open(path, encoding="utf-8", errors="replace") as f:
            return parse(f.read(), scale)
    except OSError as error:
        raise MotionError(f"cannot read {path}: {error.strerror}") from None


def parse(text, scale=1.0):
    """A BVH from its text: any whitespace between words (spaces, tabs), any line endings, any
    channel order, position channels on any joint, joint names with spaces (joined with '_' as
    Blender does), frames on one line or spread over several. A broken file (no hierarchy, a
    bad number, NaN or infinite values, fewer values than the header promises) is a MotionError
    naming the line or frame."""
    hierarchy, motion, motion_line = split_motion(text)
    names, parents, offsets, ends, channels = parse_hierarchy(hierarchy)
    frames, frame_time, values = parse_motion(motion, motion_line, sum(len(c) for c in channels))
    _check_values(values, names, channels)
    return _convert(names, parents, offsets, ends, channels, frame_time, values, scale)


def split_motion(text):
    """(hierarchy lines, motion text, line number of MOTION) of a BVH text."""
    lines = text.replace("\r\n", "\n").replace("\r", "\n").split("\n")
    first = next((w for w in (line.split() for line in lines) if w), [""])
    if first[0].upper() != "HIERARCHY":
        raise MotionError("not a BVH file: it does not start with HIERARCHY")
    for i, line in enumerate(lines):
        words = line.split()
        if words and words[0].upper() == "MOTION":
            return lines[:i], "\n".join([" ".join(words[1:])] + lines[i + 1:]), i + 1
    raise MotionError("the BVH file has no MOTION section (truncated?)")


def parse_hierarchy(lines):
    """names, parents, offsets (file axes and units), end-site offsets, channels of the lines
    between HIERARCHY and MOTION."""
    names, parents, offsets, ends, channels = [], [], [], [], []
    stack, in_end = [], False
    for n, line in enumerate(lines, 1):
        words = line.split()
        if not words:
            continue
        key = words[0].upper()
        braces = [w for w in words if w in "{}"]
        if key in ("ROOT", "JOINT"):
            name = "_".join(w for w in words[1:] if w != "{")
            if not name:
                raise MotionError(f"BVH line {n}: {key} without a name")
            names.append(name)
            parents.append(stack[-1] if stack else -1)
            offsets.append(np.zeros(3))
            ends.append(np.full(3, np.nan))
            channels.append(())
            stack.append(len(names) - 1)
            braces = braces[1:] if braces[:1] == ["{"] else braces
        elif key == "END":
            in_end = True
        elif key == "OFFSET":
            if not stack:
                raise MotionError(f"BVH line {n}: OFFSET outside a joint")
            xyz = _numbers(words[1:4], f"BVH line {n}: OFFSET", 3)
            if in_end:
                ends[stack[-1]] = xyz
            else:
                offsets[stack[-1]] = xyz
        elif key == "CHANNELS":
            if not stack or in_end:
                raise MotionError(f"BVH line {n}: CHANNELS outside a joint")
            count = int(_numbers(words[1:2], f"BVH line {n}: CHANNELS", 1)[0])
            chans = tuple(words[2:2 + count])
            if len(chans) != count or any(c[:1].upper() not in _AXES or not c.lower().endswith(
                    ("position", "rotation")) for c in chans):
                raise MotionError(f"BVH line {n}: expected {count} channels like Xposition or Zrotation, "
                                  f"got {' '.join(words[2:]) or 'none'}")
            channels[stack[-1]] = chans
        for b in braces:
            if b == "}":
                if in_end:
                    in_end = False
                elif stack:
                    stack.pop()
                else:
                    raise MotionError(f"BVH line {n}: a '}}' closes nothing")
    if not names:
        raise MotionError("the BVH file has no joints")
    if stack:
        raise MotionError("the BVH hierarchy is not closed (a '}' is missing: truncated?)")
    return names, parents, offsets, ends, channels


def parse_motion(motion, first_line, width):
    """(frame count, frame time, values (F, width)) of the MOTION section."""
    words = motion.split()
    if len(words) < 5 or words[0].lower() != "frames:" or words[2].lower() != "frame" \
            or words[3].lower() != "time:":
        raise MotionError(f"BVH line {first_line + 1}: expected 'Frames: N' and 'Frame Time: T' after MOTION")
    frames = _numbers(words[1:2], "BVH 'Frames:'", 1)[0]
    frame_time = _numbers(words[4:5], "BVH 'Frame Time:'", 1)[0]
    if frames != int(frames) or frames < 1:
        raise MotionError(f"BVH 'Frames: {words[1]}': expected a whole number of frames, at least 1")
    if not frame_time > 0.0 or not np.isfinite(frame_time):
        raise MotionError(f"BVH 'Frame Time: {words[4]}': expected a positive time in seconds")
    frames = int(frames)
    tokens = words[5:]
    if len(tokens) < frames * width:
        raise MotionError(f"the BVH header promises {frames} frames of {width} values, the file holds "
                          f"{len(tokens) // max(width, 1)} complete frames (truncated?)")
    try:
        values = np.array(tokens[:frames * width], float)
    except ValueError:
        bad = next(i for i, t in enumerate(tokens) if not _is_number(t))
        raise MotionError(f"BVH frame {bad // max(width, 1) + 1}: {tokens[bad][:20]!r} is not a number") from None
    return frames, frame_time, values.reshape(frames, width)


def _check_values(values, names, channels):
    bad = ~np.isfinite(values)
    if bad.any():
        frame, col = np.argwhere(bad)[0]
        owner = np.repeat(np.arange(len(names)), [len(c) for c in channels])[col]
        raise MotionError(f"the BVH motion has {int(bad.sum())} NaN or infinite values (first at frame "
                          f"{frame + 1}, joint '{names[owner]}')")


def _is_number(token):
    try:
        float(token)
    except ValueError:
        return False
    return True


def _numbers(words, what, count):
    if len(words) < count:
        raise MotionError(f"{what}: expected {count} number{'s' if count > 1 else ''}")
    try:
        out = np.array(words[:count], float)
    except ValueError:
        raise MotionError(f"{what}: {' '.join(words[:count])!r} is not {count} number(s)") from None
    if not np.isfinite(out).all():
        raise MotionError(f"{what}: {' '.join(words[:count])!r} is not finite")
    return out


def write(bvh_file, path=None):
    """The canonical text of a parsed BVH (file units and axes, one frame per line, spaces),
    which every BVH reader (Blender's included) reads the same way; written to `path` if given."""
    out, depth = ["HIERARCHY"], 0
    kids = {j: [k for k, p in enumerate(bvh_file.parents) if p == j] for j in range(len(bvh_file.names))}

    def joint(j, depth):
        pad = "  " * depth
        out.append(f"{pad}{'ROOT' if bvh_file.parents[j] < 0 else 'JOINT'} {bvh_file.names[j]}")
        out.append(pad + "{")
        out.append(f"{pad}  OFFSET {_text(bvh_file.file_offsets[j])}")
        chans = bvh_file.channels[j]
        out.append(f"{pad}  CHANNELS {len(chans)} {' '.join(chans)}".rstrip())
        for k in kids[j]:
            joint(k, depth + 1)
        if np.all(np.isfinite(bvh_file.file_ends[j])):
            out.extend([f"{pad}  End Site", pad + "  {", f"{pad}    OFFSET {_text(bvh_file.file_ends[j])}",
                        pad + "  }"])
        out.append(pad + "}")

    for root in np.flatnonzero(np.asarray(bvh_file.parents) < 0):
        joint(int(root), depth)
    out += ["MOTION", f"Frames: {bvh_file.frame_count}", f"Frame Time: {float(bvh_file.frame_time)!r}"]
    out += [_text(row) for row in bvh_file.values]
    text = "\n".join(out) + "\n"
    if path is not None:
        with open(path, "w", encoding="utf-8") as f:
            f.write(text)
    return text


def _text(numbers):
    return " ".join(repr(float(v)) for v in numbers)


def figure_height(bvh_file):
    """The figure's height in file units: the vertical extent (BVH Y) of the posed figure (heads
    and end sites), the 90th percentile over frames so a raised arm or a crouch moves it little;
    the rest skeleton when the motion is missing."""
    pos = bvh_file.positions(with_ends=True) / bvh_file.scale
    if len(pos) == 0:
        heads = rest_heads(bvh_file)
        return float(np.ptp(heads[:, 2])) / bvh_file.scale if len(heads) else 0.0
    return float(np.percentile(np.ptp(pos[..., 2], axis=1), 90))


def _convert(names, parents, offsets, ends, channels, frame_time, values, scale):
    c = Y_UP_TO_Z_UP
    J, F = len(names), len(values)
    file_offsets, file_ends = np.array(offsets, float), np.array(ends, float)
    # a joint's position channels replace its OFFSET (axes without a channel are 0), as in Blender
    local = np.broadcast_to(file_offsets, (F, J, 3)).copy()
    rot = np.zeros((F, J, 4))
    rot[..., 0] = 1.0
    col = 0
    for j, chans in enumerate(channels):
        if any(ch.lower().endswith("position") for ch in chans):
            local[:, j] = 0.0
        for ch in chans:
            axis = _AXES[ch[0].upper()]
            v = values[:, col]
            col += 1
            if ch.lower().endswith("position"):
                local[:, j, axis] = v
            else:  # channels listed outermost first: R = R(c1) R(c2) R(c3)
                rot[:, j] = rotations.multiply(rot[:, j], rotations.axis_rotation(axis, np.radians(v)))
    # change of basis to Z up: R' = C R C^T, as quaternions
    cq = rotations.from_matrix(c)
    rot = rotations.multiply(rotations.multiply(cq, rot), rotations.conjugate(cq))
    local = local @ c.T * scale
    root = int(np.flatnonzero(np.array(parents) < 0)[0])
    return BVH(tuple(names), np.array(parents), file_offsets @ c.T * scale, file_ends @ c.T * scale,
               tuple(channels), frame_time, local[:, root].copy(), rotations.make_continuous(rot), values,
               local, file_offsets, file_ends, scale)


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
    for j, chans in enumerate(bvh.channels):  # other joints with position channels move too
        if j != root and bvh.joint_offsets is not None and any(c.lower().endswith("position") for c in chans):
            trans[:, j] = (bvh.joint_offsets[:, j] - bvh.offsets[j]) @ skeleton.rest[j, :3, :3]
    return Trajectories(frames=np.arange(1, F + 1), fps=bvh.fps,
                        rotations=rotations.make_continuous(local), translations=trans,
                        armature_to_world=np.eye(4))
