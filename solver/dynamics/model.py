"""What the body is (`Model`) and scratch for one state (`Data`), as in Pinocchio's split.

The model is a tree of rigid bodies with a floating base (the skeleton's root, 6 DOF) and one
rotational joint per moving bone. Bones are merged into their parent's body when they cannot move
on their own: welded bones (no free axis) and massless subtrees (their free axes become
*kinematic*: they follow the desired motion exactly and carry no dynamics, which keeps the
articulated inertia of every joint positive definite). Bones outside the root's subtree (and the
root's ancestors) are not part of the dynamic body.

Coordinates
-----------
q (nq,) = [root position (3, world), root orientation (4, world, w x y z),
           one local rotation quaternion (4) per joint body, body order].
v (nv,) = [root angular velocity (3, root axes), root linear velocity (3, root axes),
           each joint body's local angular velocity on its free axes (x, y, z order)].
A joint with two free axes (clavicles, forearms, hands, feet) is a universal joint: its
orientation is R = R_i(a) R_k(b), the first free axis i (x, y, z order) fixed in the parent and
the second k fixed in the bone, so the locked axis never turns however the joint moves. Its
entries of v are the angle rates (da/dt, db/dt), stored on the slots of axes i and k; its angular
velocity in the bone's frame is da/dt R^T e_i + db/dt e_k, so the motion subspace column of axis i
turns with b (Data.joint_motion) and the joint adds the velocity product da/dt db/dt (s_i x s_k)
(kinematics.joint_velocity_products). The dynamics stay exact, for the coordinates are the two
angles themselves and integration adds to them (kinematics.integrate); restricting only the
angular velocity instead would let a sequence of turns reach the locked axis (the constraint
"no angular velocity about the bone's own locked axis" is not integrable).
Bodies are numbered breadth first (parents before children, each tree depth contiguous) so that
the algorithms can vectorise over a whole depth at once; `dof_joint`/`dof_axis` name each entry
of v. Joint velocities are angular velocities in the bone's own posed frame, so the motion
subspace of a one- or three-axis joint is the set of identity columns of its free axes.
"""

from dataclasses import dataclass, field

import numpy as np

from .. import rotations
from ..errors import RigError
from ..skeleton import Skeleton
from . import spatial

GRAVITY = np.array([0.0, 0.0, -9.81])
MASSLESS = 1e-9  # kg: a subtree lighter than this carries no dynamics


@dataclass(eq=False)
class Model:
    skeleton: Skeleton
    body_joint: np.ndarray  # (nb,) the skeleton joint whose frame is each body's frame
    parent: np.ndarray  # (nb,) parent body, -1 for the base
    tree: np.ndarray  # (nb, 4, 4) a body's joint frame at zero rotation, in its parent body's frame
    mass: np.ndarray  # (nb,) kg, merged bones and loads included
    com: np.ndarray  # (nb, 3) body frame
    inertia: np.ndarray  # (nb, 3, 3) about the centre of mass, body frame
    free: np.ndarray  # (nb, 3) bool free local rotation axes (all three for the base)
    joint_body: np.ndarray  # (J,) body carrying each bone, -1 when outside the dynamic body
    joint_offset: np.ndarray  # (J, 4, 4) each bone's frame in its body's frame
    joint_kind: tuple  # per bone: "base", "joint", "welded", "kinematic" or "outside"
    reference_basis: np.ndarray  # (J, 4, 4) pose of the bones that do not move on their own
    gravity: np.ndarray = field(default_factory=lambda: GRAVITY.copy())
    armature: float = 0.0  # kg m^2 added to each joint DOF's inertia (0: exact rigid bodies)
    loads: dict = field(default_factory=dict)  # joint index -> extra point mass (kg)

    def __post_init__(self):
        nb = len(self.body_joint)
        self.nb = nb
        self.nq = 3 + 4 * nb
        depth = np.zeros(nb, int)
        for b in range(1, nb):
            depth[b] = depth[self.parent[b]] + 1
        if np.any(np.diff(depth) < 0):
            raise ValueError("bodies must be ordered by depth")
        self.depth = depth
        # velocity layout: base 6 entries, then the free axes of each joint body
        v_index = np.full((nb, 6), -1)
        v_index[0] = np.arange(6)
        n = 6
        for b in range(1, nb):
            for axis in np.flatnonzero(self.free[b]):
                v_index[b, axis] = n
                n += 1
        self.nv = n
        v_index[v_index < 0] = n  # a dummy slot that always holds zero
        self.v_index = v_index
        flat = np.flatnonzero(v_index.ravel() < n)
        self.flat_dof = flat[np.argsort(v_index.ravel()[flat])]  # (nv,) position in a (nb, 6) array
        self.dof_body = self.flat_dof // 6
        self.dof_slot = self.flat_dof % 6  # 0-2 rotation about local x, y, z; 3-5 base translation
        self.dof_joint = self.body_joint[self.dof_body]
        names = self.skeleton.names
        self.dof_names = tuple(
            f"{names[j]}.{('rx', 'ry', 'rz', 'tx', 'ty', 'tz')[s]}" if b == 0 else f"{names[j]}.{'xyz'[s]}"
            for b, j, s in zip(self.dof_body, self.dof_joint, self.dof_slot))
        self.armature_v = np.full(n, float(self.armature))
        self.armature_v[:6] = 0.0  # the base is a free rigid body
        # ancestor-or-self matrix: velocities are A @ joint contributions, subtree sums are A.T @ x
        anc = np.zeros((nb, nb))
        for b in range(nb):
            k = b
            while k >= 0:
                anc[b, k] = 1.0
                k = self.parent[k]
        self.ancestors = anc
        self.subtree_sum = np.ascontiguousarray(anc.T)  # subtree sums: subtree_sum @ x
        dof_anc = anc[self.dof_body][:, self.dof_body] > 0  # [c, d]: d's body is c's body or above it
        self.dof_ancestor = dof_anc
        # [b, c]: body b lies in the subtree of DOF c's body (a wrench on b loads DOF c)
        self.dof_subtree = anc[:, self.dof_body].copy()
        self.dof_related = dof_anc | dof_anc.T
        self.spatial_inertia = spatial.body_spatial_inertia(self.mass, self.com, self.inertia)
        self.tree_rotation = self.tree[:, :3, :3].copy()
        # (nb, 16, 9): a quaternion's outer product (16) to the entries of tree_rotation @ R(q)
        q2r = spatial._Q2R.reshape(16, 3, 3)
        self.tree_q2r = np.einsum("bij,kjl->bkil", self.tree_rotation, q2r).reshape(nb, 16, 9)
        self._build_universal()
        self._build_levels(depth)
        self._build_doubling()
        self.free_mask = np.zeros((nb, 6, 3))
        self.free_mask[:, :, :] = self.free[:, None, :]
        self.axis_pad = np.where(self.free, 0.0, 1.0)  # makes padded 3x3 joint blocks invertible
        self.set_armature(self.armature_v)
        self.q_index = 3 + 4 * np.arange(nb)  # where each body's quaternion starts in q
        # gathers (v, 0, a, 0)[pair_index] -> (nb, 6, 2) per-body entries of v and a at once
        self.pair_index = np.stack((v_index, v_index + n + 1), axis=2)
        # world transforms from [R (9), skew(p) R (9), 0]: motion Xm = [[R, 0], [pR, R]] and
        # force Xf = [[R, pR], [0, R]]
        xm = np.full((6, 6), 18)
        xf = np.full((6, 6), 18)
        for r in range(3):
            for c in range(3):
                xm[r, c] = xm[3 + r, 3 + c] = xf[r, c] = xf[3 + r, 3 + c] = 3 * r + c
                xm[3 + r, c] = xf[r, 3 + c] = 9 + 3 * r + c
        self.motion_gather, self.force_gather = xm.ravel(), xf.ravel()

    def set_armature(self, values):
        """Armature (rotor inertia, kg m^2) per DOF (nv,) or one value for every joint DOF; the
        base's six entries stay zero."""
        arm = np.broadcast_to(np.asarray(values, float), (self.nv,)).copy()
        arm[:6] = 0.0
        self.armature_v = arm
        pad = self.axis_pad
        body, slot = self.dof_body[6:], self.dof_slot[6:]
        pad[body, slot] = arm[6:]

    def _build_universal(self):
        """Universal (two-axis) joints: their bodies, axes (parent-side i, bone-side k, locked j)
        and sigma = e_i x e_k . e_j (+1 or -1)."""
        two = [b for b in range(1, self.nb) if self.free[b].sum() == 2]
        self.universal_body = np.array(two, int)
        axes = np.array([list(np.flatnonzero(self.free[b])) + list(np.flatnonzero(~self.free[b])) for b in two],
                        int).reshape(-1, 3)
        self.universal_axes = axes
        self.universal_sigma = np.array([spatial._EPS[i, k, j] for i, k, j in axes]).reshape(-1)
        q_index = 3 + 4 * self.universal_body
        self.universal_q = (q_index[:, None] + np.arange(4)).reshape(-1)  # their quaternions' entries of q
        n = len(two)
        # entries of v holding da/dt and db/dt (v_index[body, axis])
        self.universal_v = (self.v_index[self.universal_body, axes[:, 0]], self.v_index[self.universal_body, axes[:, 1]])
        # (n_u, 16, 3): a quaternion's outer product to row i of its rotation matrix (R^T e_i)
        self.universal_row = spatial._Q2R.reshape(16, 3, 3)[:, axes[:, 0], :].transpose(1, 0, 2).copy()
        # flat entries of (n_u, 4) arrays: the i and k components of a quaternion
        self.universal_qi = 4 * np.arange(n) + 1 + axes[:, 0]
        self.universal_qk = 4 * np.arange(n) + 1 + axes[:, 1]

    def universal_angles(self, quats, drop_twist=False):
        """(a, b) (..., n_u) of universal joints' quaternions (..., n_u, 4): R = R_i(a) R_k(b),
        exact on the allowed set. Off it:

        - by default (a configuration a small step off the set, e.g. a Runge-Kutta stage), a is
          where R turns the bone-side axis about e_i (R e_k = cos a e_k + sigma sin a e_j on the
          set) and b how R turns e_i from there about e_k (R e_i = cos b e_i - sigma sin b
          R_i(a) e_j): smooth everywhere near the set;
        - with drop_twist (a retargeted rotation), the intrinsic Euler decomposition
          R_i(a) R_k(b) R_j(c) with the twist |c| <= pi / 2 about the locked axis dropped:
          R e_j = sigma sin b e_i + cos b (cos a e_j - sigma sin a e_k) gives (a, b) up to the
          other solution (a + pi, pi - b), and the one kept turns e_k the way R does
          (cos c >= 0). At |b| = pi / 2 a twist about j is a turn about i, and a takes it.
        """
        rot = spatial.quat_to_matrix(np.asarray(quats, float))
        e = np.eye(3)[self.universal_axes]  # (n_u, 3 [i k j], 3)
        # entries [..., n, row, column] of R on the axes [i, k, j]
        r = np.einsum("nax,...nxy,nby->...nab", e, rot, e)
        sigma = self.universal_sigma
        if not drop_twist:
            a = np.arctan2(sigma * r[..., 2, 1], r[..., 1, 1])
            turned_j = np.cos(a) * r[..., 2, 0] - sigma * np.sin(a) * r[..., 1, 0]  # R e_i . R_i(a) e_j
            return a, np.arctan2(-sigma * turned_j, r[..., 0, 0])
        ui, uk, uj = r[..., 0, 2], r[..., 1, 2], r[..., 2, 2]  # R e_j
        a = np.arctan2(-sigma * uk, uj)
        b = np.arctan2(sigma * ui, np.hypot(uj, uk))
        other = np.cos(a) * r[..., 1, 1] + sigma * np.sin(a) * r[..., 2, 1] < 0.0
        a = np.where(other, a - np.copysign(np.pi, a), a)  # a + pi, within (-pi, pi]
        b = np.where(other, np.copysign(np.pi, b) - b, b)  # pi - b, within (-pi, pi]
        return a, b

    def universal_quaternions(self, a, b):
        """Quaternions (..., n_u, 4) of R_i(a) R_k(b) (universal_angles' inverse)."""
        a, b = np.asarray(a, float), np.asarray(b, float)
        ca, sa, cb, sb = np.cos(0.5 * a), np.sin(0.5 * a), np.cos(0.5 * b), np.sin(0.5 * b)
        i, k, j = self.universal_axes.T
        out = np.zeros(a.shape + (4,))
        n = np.arange(len(i))
        out[..., 0] = ca * cb
        out[..., n, 1 + i] = sa * cb
        out[..., n, 1 + k] = ca * sb
        out[..., n, 1 + j] = self.universal_sigma * sa * sb  # e_i e_k = sigma e_j
        return out

    def project(self, q, drop_twist=False):
        """q (..., nq) with every universal joint's orientation on its allowed set (the others
        untouched; drop_twist as in universal_angles); a configuration already on it is returned
        unchanged to rounding."""
        q = np.array(q, dtype=float)
        if len(self.universal_body):
            quats = q[..., self.universal_q].reshape(q.shape[:-1] + (-1, 4))
            out = self.universal_quaternions(*self.universal_angles(quats, drop_twist))
            # the sign of the given quaternion (a wrapping past pi flips the computed one), so that
            # sums of rates taken at projected stages (forward_dynamics.rk4_step) stay consistent
            out *= np.where(np.einsum("...i,...i->...", out, quats) < 0.0, -1.0, 1.0)[..., None]
            q[..., self.universal_q] = out.reshape(q.shape[:-1] + (-1,))
        return q

    def _build_levels(self, depth):
        """Contiguous slices per depth and 0/1 maps summing children into their parents' slice."""
        self.levels = []
        for d in range(1, depth.max() + 1):
            idx = np.flatnonzero(depth == d)
            pidx = np.flatnonzero(depth == d - 1)
            sl = slice(idx[0], idx[-1] + 1)
            psl = slice(pidx[0], pidx[-1] + 1)
            to_parent = np.zeros((len(pidx), len(idx)))
            to_parent[self.parent[idx] - pidx[0], np.arange(len(idx))] = 1.0
            self.levels.append((sl, psl, to_parent))

    def _build_doubling(self):
        """Index maps for forward kinematics by pointer doubling: log2(depth) batched products
        instead of one per depth. Index nb is a virtual identity transform above the base."""
        nb = self.nb
        a = np.append(np.where(self.parent < 0, nb, self.parent), nb)
        self.doubling = []
        while np.any(a[:nb] < nb):
            self.doubling.append(a.copy())
            a = a[a]

    # ---- conversions between the skeleton's pose and the model's coordinates ----

    @property
    def root(self):
        return int(self.body_joint[0])

    def neutral(self):
        """The rest pose with the armature at the world origin."""
        q = np.zeros(self.nq)
        frame = self.root_rest_frame()
        q[:3] = frame[:3, 3]
        q[3:7] = rotations.from_matrix(frame[:3, :3])
        q[7::4] = 1.0
        return q

    def root_rest_frame(self, armature_to_world=None):
        """World frame of the root bone when its ancestors are in their reference pose."""
        sk = self.skeleton
        base = np.eye(4) if armature_to_world is None else np.asarray(armature_to_world, float)
        for a in reversed(sk.ancestors(self.root)):
            base = base @ sk.rest_local[a] @ self.reference_basis[a]
        return base @ sk.rest_local[self.root]

    def configuration(self, root_position, root_orientation, joint_rotations):
        """q from the root bone's world pose and every bone's local rotation (J, 4); the rotations
        of universal joints lose their twist about the locked axis (Model.project)."""
        joint_rotations = np.asarray(joint_rotations, dtype=float)
        q = np.empty(self.nq)
        q[:3] = root_position
        body_q = rotations.normalize(joint_rotations[self.body_joint])
        body_q[0] = rotations.normalize(root_orientation)
        q[3:] = body_q.ravel()
        return self.project(q, drop_twist=True)

    def configurations(self, root_positions, root_orientations, joint_rotations):
        """configuration() for every frame (F, nq) of a motion at once."""
        joint_rotations = np.asarray(joint_rotations, dtype=float)
        nf = len(joint_rotations)
        q = np.empty((nf, self.nq))
        q[:, :3] = root_positions
        body_q = rotations.normalize(joint_rotations[:, self.body_joint])
        body_q[:, 0] = rotations.normalize(root_orientations)
        q[:, 3:] = body_q.reshape(nf, -1)
        return self.project(q, drop_twist=True)

    def joint_rotations(self, q, reference=None):
        """Every bone's local rotation (J, 4): body joints from q, the others from `reference`
        (J, 4) or the model's reference pose. The root's entry is its world orientation."""
        if reference is None:
            reference = rotations.from_matrix(self.reference_basis[:, :3, :3])
        out = np.array(reference, dtype=float)
        out[self.body_joint] = np.asarray(q[3:]).reshape(self.nb, 4)
        return out

    def velocity(self, root_angular, root_linear, joint_angular):
        """v from the root's angular and linear velocity (root axes) and each bone's local
        angular velocity (J, 3); components on locked axes are dropped (for a universal joint
        the free components are taken as its angle rates: exact at b = 0)."""
        full = np.zeros((self.nb, 6))
        full[:, :3] = np.asarray(joint_angular, float)[self.body_joint]
        full[0, :3] = root_angular
        full[0, 3:] = root_linear
        return full.ravel()[self.flat_dof].copy()

    def expand(self, v):
        """(nb, 6) per-body local (angular, linear) entries of a velocity-like vector."""
        return np.append(v, 0.0)[self.v_index]  # v_index points locked entries at the appended 0

    def create_data(self):
        return Data(self)


class Data:
    """Scratch and cached kinematics for one configuration (see kinematics.update_frames)."""

    def __init__(self, model: Model):
        nb = model.nb
        self.model = model
        self.key = None  # the bytes of the q whose kinematics this holds (kinematics.update_frames)
        self.local = np.zeros((nb + 1, 4, 4))
        self.local[:nb] = model.tree
        self.local[nb] = np.eye(4)
        self.frames = np.zeros((nb, 4, 4))
        self.motion = np.zeros((nb, 6, 6))  # Xm: body (omega, v) at its origin -> world at origin
        # Xm with each universal joint's parent-side column turned (R^T e_i for e_i): the joint
        # motion subspace's columns on the free slots (the same array as motion without them)
        self.joint_motion = self.motion
        self.universal_cross = None  # (n_u, 6) s_i x s_k, kinematics.joint_velocity_products
        self.zero_column = np.zeros((nb, 1))
        self._force = None
        self._inertia = np.zeros((nb, 6, 6))
        self._composite = None
        self.subspace = None  # world motion subspace (nv, 6), kinematics.motion_subspace
        self.velocity = None  # (v bytes, velocity terms), inverse_dynamics.velocity_terms
        self.momentum_forces = None  # (their crm, crf(v) I v), inverse_dynamics._momentum_forces

    def set_force_transforms(self, parts):
        """The rotations and levers (nb, 19) of a new configuration (kinematics.update_frames):
        the force transforms and world inertias follow from them when first asked for (a
        configuration that only needs frames skips them)."""
        self._force = parts
        self._inertia = None
        self._composite = None

    @property
    def inertia(self):
        """World spatial inertia (nb, 6, 6) of each body about the origin."""
        if self._inertia is None:
            xf = self._force[:, self.model.force_gather].reshape(self.model.nb, 6, 6)
            self._inertia = xf @ self.model.spatial_inertia @ xf.swapaxes(1, 2)
        return self._inertia

    @property
    def composite(self):
        """World spatial inertia (nb, 6, 6) of each body's subtree (inertia_matrix.composite_inertias)."""
        if self._composite is None:
            nb = self.model.nb
            self._composite = self.model.ancestors.T.dot(self.inertia.reshape(nb, 36)).reshape(nb, 6, 6)
            self._composite.flags.writeable = False
        return self._composite


def _segment_loads(skeleton, loads):
    """Normalise {joint name or index: kg} to {index: kg}."""
    out = {}
    for key, kg in (loads or {}).items():
        j = skeleton.index(key) if isinstance(key, str) else int(key)
        if kg < 0:
            raise RigError(f"the load on {skeleton.names[j]!r} is negative")
        out[j] = out.get(j, 0.0) + float(kg)
    return out


def build_model(skeleton: Skeleton, reference_basis=None, loads=None, gravity=GRAVITY,
                armature=0.0, min_inertia=1e-6, kinematic_mass=MASSLESS):
    """The dynamic body of a skeleton.

    reference_basis (J, 4, 4): local pose of bones that cannot move on their own and the location
    channels of every bone (the dynamics treat bone translations other than the root's as
    constant); identity by default. loads: {bone: kg} point masses at the segment's centre of mass
    (loads carried in the hands). min_inertia (kg m^2): floor on every body's principal inertia so
    that zero-radius segments (point masses at a joint) keep invertible articulated inertias.
    kinematic_mass (kg): bones whose subtree (loads included) weighs no more than this carry no
    dynamics of their own; their mass is lumped into their parent's body in the reference pose and
    they follow the desired motion (massless helpers by default; the closed loop also passes the
    fingers this way, see closed_loop.Settings.kinematic_fraction).
    """
    sk = skeleton
    J = sk.joint_count
    basis = np.broadcast_to(np.eye(4), (J, 4, 4)).copy() if reference_basis is None \
        else np.array(reference_basis, dtype=float)
    loads = _segment_loads(sk, loads)
    root = sk.root
    inside = np.zeros(J, bool)
    inside[root] = True
    inside[sk.descendants(root)] = True
    seg_mass = np.where(inside, sk.mass, 0.0) + np.array([loads.get(j, 0.0) for j in range(J)])
    subtree = seg_mass.copy()
    for j in reversed(range(J)):
        if sk.parents[j] >= 0 and inside[j]:
            subtree[sk.parents[j]] += subtree[j]
    if subtree[root] <= MASSLESS:
        raise RigError("the body has no mass")

    rest_local = sk.rest_local
    kinds = ["outside"] * J
    body_of = np.full(J, -1)
    offset = np.broadcast_to(np.eye(4), (J, 4, 4)).copy()
    order, tree = [], []
    translation = np.broadcast_to(np.eye(4), (J, 4, 4)).copy()
    translation[:, :3, 3] = basis[:, :3, 3]
    for j in range(J):
        if not inside[j]:
            continue
        p = sk.parents[j]
        if j == root:
            kinds[j] = "base"
        elif sk.dof[j].any() and subtree[j] > max(kinematic_mass, MASSLESS):
            kinds[j] = "joint"
        else:
            kinds[j] = "kinematic" if sk.dof[j].any() else "welded"
        if kinds[j] in ("base", "joint"):
            body_of[j] = len(order)
            order.append(j)
            tree.append(np.eye(4) if j == root else offset[p] @ rest_local[j] @ translation[j])
        else:
            body_of[j] = body_of[p]
            offset[j] = offset[p] @ rest_local[j] @ basis[j]

    # breadth-first renumbering so each depth is a contiguous slice
    nb = len(order)
    parent_old = np.array([-1 if k == 0 else body_of[sk.parents[order[k]]] for k in range(nb)])
    depth = np.zeros(nb, int)
    for k in range(1, nb):
        depth[k] = depth[parent_old[k]] + 1
    perm = np.argsort(depth, kind="stable")
    new_of_old = np.empty(nb, int)
    new_of_old[perm] = np.arange(nb)
    body_joint = np.array(order)[perm]
    parent = np.array([-1 if p < 0 else new_of_old[p] for p in parent_old[perm]])
    tree = np.array(tree)[perm]
    body_of = np.where(body_of >= 0, new_of_old[np.maximum(body_of, 0)], -1)

    mass, com, inertia = _merge_inertia(sk, nb, body_of, offset, seg_mass, loads, min_inertia)
    free = sk.dof[body_joint].astype(bool).copy()
    free[0] = True
    return Model(skeleton=sk, body_joint=body_joint, parent=parent, tree=tree, mass=mass, com=com,
                 inertia=inertia, free=free, joint_body=body_of, joint_offset=offset,
                 joint_kind=tuple(kinds), reference_basis=basis,
                 gravity=np.asarray(gravity, float).copy(), armature=float(armature), loads=loads)


def _merge_inertia(sk, nb, body_of, offset, seg_mass, loads, min_inertia):
    """Each body's mass, centre of mass and inertia, summing its bones (parallel axis theorem)."""
    mass = np.zeros(nb)
    first = np.zeros((nb, 3))
    second = np.zeros((nb, 3, 3))  # inertia about the body origin
    for j in np.flatnonzero(body_of >= 0):
        b = body_of[j]
        rot, pos = offset[j, :3, :3], offset[j, :3, 3]
        parts = [(sk.mass[j], sk.com[j], sk.inertia[j])]
        if loads.get(j, 0.0) > 0.0:
            grip = sk.com[j] if sk.mass[j] > 0 else np.array([0.0, 0.5 * sk.lengths[j], 0.0])
            parts.append((loads[j], grip, np.zeros((3, 3))))
        for m, c, inertia in parts:
            if m <= 0.0:
                continue
            c = rot @ c + pos
            mass[b] += m
            first[b] += m * c
            second[b] += rot @ inertia @ rot.T + m * (c @ c * np.eye(3) - np.outer(c, c))
    com = np.divide(first, mass[:, None], out=np.zeros_like(first), where=mass[:, None] > 0)
    about_com = second - mass[:, None, None] * (np.einsum("bi,bi->b", com, com)[:, None, None] * np.eye(3)
                                                 - com[:, :, None] * com[:, None, :])
    about_com = 0.5 * (about_com + np.swapaxes(about_com, 1, 2))
    low = np.linalg.eigvalsh(about_com)[:, 0]
    about_com += np.maximum(min_inertia - low, 0.0)[:, None, None] * np.eye(3)
    return mass, com, about_com
