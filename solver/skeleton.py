"""The articulated body: joint tree, rest frames, rotational DOF, limits and segment inertia."""

from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np

from . import rotations
from .body_roles import RoleMap
from .errors import RigError


@dataclass
class Skeleton:
    """A tree of joints, one per bone, parents before children; SI units, Z up.

    Each joint owns the segment of its bone. Frames follow Blender: `rest[j]` is the bone's
    rest frame in armature space (head at the origin, Y along the bone, roll included),
    scaled to metres. A posed joint's frame is parent frame @ rest_local[j] @ basis[j],
    where basis is the pose bone's local translation and rotation.
    """

    names: tuple
    parents: np.ndarray  # (J,) int, -1 for a root
    rest: np.ndarray  # (J, 4, 4) rest frames in armature space, metres
    lengths: np.ndarray  # (J,) metres
    connected: np.ndarray  # (J,) bool: connected bones ignore their location channels
    dof: np.ndarray  # (J, 3) bool: free rotation about local x, y, z
    limits: np.ndarray  # (J, 3, 2) radians, (-inf, inf) where unlimited
    mass: np.ndarray  # (J,) kg
    com: np.ndarray  # (J, 3) centre of mass in the joint's frame, metres
    inertia: np.ndarray  # (J, 3, 3) about the centre of mass, in the joint's frame, kg m^2
    roles: RoleMap = field(default_factory=RoleMap)
    unit_scale: float = 1.0  # metres per armature unit

    def __post_init__(self):
        self.names = tuple(self.names)
        self.parents = np.asarray(self.parents, dtype=int)
        n = len(self.names)
        if n == 0:
            raise RigError("the armature has no bones")
        if np.any(self.parents >= np.arange(n)):
            raise RigError("joints must be ordered parents before children")
        self._index = {name: i for i, name in enumerate(self.names)}

    @property
    def joint_count(self):
        return len(self.names)

    def index(self, name):
        try:
            return self._index[name]
        except KeyError:
            raise RigError(f"no bone named {name!r}") from None

    def find(self, name):
        """Index of a bone, or None."""
        return self._index.get(name)

    def role_index(self, role):
        name = self.roles.bone(role)
        return None if name is None else self.index(name)

    @property
    def root(self):
        """The floating base: the pelvis when known, else the first root joint."""
        pelvis = self.role_index("pelvis")
        return 0 if pelvis is None else pelvis

    @cached_property
    def rest_local(self):
        """Rest frame of each joint relative to its parent's rest frame (armature space for roots);
        computed once (limb IK asks for it on every solve; a skeleton's rest frames never change)."""
        local = self.rest.copy()
        has_parent = self.parents >= 0
        parent_rest = self.rest[self.parents[has_parent]]
        local[has_parent] = np.linalg.solve(parent_rest, self.rest[has_parent])
        return local

    def children(self, j):
        return np.flatnonzero(self.parents == j)

    def descendants(self, j):
        out = []
        stack = list(self.children(j))
        while stack:
            k = stack.pop()
            out.append(k)
            stack.extend(self.children(k))
        return sorted(out)

    def ancestors(self, j):
        out = []
        j = self.parents[j]
        while j >= 0:
            out.append(j)
            j = self.parents[j]
        return out

    @property
    def total_mass(self):
        return float(self.mass.sum())

    def with_mass_model(self, mass, com, inertia):
        return replace(self, mass=np.asarray(mass, float), com=np.asarray(com, float),
                       inertia=np.asarray(inertia, float))

    def world_frames(self, basis, armature_to_world=None):
        """Forward kinematics of frames: basis (..., J, 4, 4) local pose transforms to
        world frames (..., J, 4, 4). `armature_to_world` is a rigid (4, 4) or (..., 4, 4)."""
        basis = np.asarray(basis, dtype=float)
        local = self.rest_local @ basis
        world = np.empty_like(local)
        base = np.eye(4) if armature_to_world is None else np.asarray(armature_to_world, float)
        for j, p in enumerate(self.parents):
            parent = base if p < 0 else world[..., p, :, :]
            world[..., j, :, :] = parent @ local[..., j, :, :]
        return world


def reach_of_made_up_tail(parents, heads, j, tolerance=0.005):
    """Where bone j reaches when its tail is an importer's guess, else None.

    A bone whose children all start at its own head (CMU's wrist: hand and thumb at the wrist,
    the fingers 3.7 cm further) gets a tail the file does not define: Blender 4.2's BVH importer
    continues the parent's line, 5.0's points it up (29 cm apart on the CMU wrists). The bone then
    reaches to the mean head of its nearest descendants that start away from its head (breadth
    first). parents (J,), heads (J, 3) in one frame; tolerance in the heads' units."""
    parents = np.asarray(parents)
    level = np.flatnonzero(parents == j)
    if len(level) == 0 or np.any(np.linalg.norm(heads[level] - heads[j], axis=1) > tolerance):
        return None  # a leaf's tail (an End Site) or one on its children: the file's
    while len(level):
        level = np.flatnonzero(np.isin(parents, level))
        away = np.linalg.norm(heads[level] - heads[j], axis=1) > tolerance
        if away.any():
            return heads[level[away]].mean(axis=0)
    return None


def compose(translation, quaternion):
    """Homogeneous transforms (..., 4, 4) from translations (..., 3) and quaternions (..., 4)."""
    translation = np.asarray(translation, dtype=float)
    m = np.zeros(translation.shape[:-1] + (4, 4))
    m[..., :3, :3] = rotations.to_matrix(quaternion)
    m[..., :3, 3] = translation
    m[..., 3, 3] = 1.0
    return m


def decompose(matrix):
    """Rigid transforms (..., 4, 4) to (translation, unit quaternion)."""
    matrix = np.asarray(matrix, dtype=float)
    return matrix[..., :3, 3].copy(), rotations.from_matrix(matrix[..., :3, :3])
