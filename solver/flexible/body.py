"""Dynamic free-form deformations in 3-D (thesis ch. 4): a body of point masses embedded in a
lattice, moved by generalised coordinates q = (translation, rotation, gamma_1..gamma_D).

Rotation: the orientation is a unit quaternion R_ref kept outside q; q holds an incremental
rotation vector phi about the current orientation, R = R_ref exp([phi]x), which the integrator
folds into R_ref (and renormalises) after every step, so phi stays at 0 and nothing locks.
At phi = 0 the rotation velocity is the body-frame angular velocity, so the generalised
velocity is u = (v_world, omega_body, gamma_dot).

A point with rest position X0 and mode displacements B_k (both in the body frame, from the
lattice weights W: X0 = W L, B_k = W d_k) is at
    x = t + R y,  y = X0 + sum_k gamma_k B_k                        (eq. 4.2 in 3-D)
and its Jacobian (eq. 4.6-4.8) is J = [I, -R [y]x, R B] = R G with G = [R^T, -[y]x, B]."""

import math

import numpy as np

from ..errors import HumanAnimError
from .ffd import lattice_weights, lattice_params


class FlexibleError(HumanAnimError):
    """The flexible character can't be simulated as set up (modes, lattice, masses)."""


def skew(v):
    v = np.asarray(v, float)
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def quat_matrix(q):
    w, x, y, z = q.tolist() if isinstance(q, np.ndarray) else q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def quat_from_rotvec(phi):
    x, y, z = phi.tolist() if isinstance(phi, np.ndarray) else phi
    angle = math.sqrt(x * x + y * y + z * z)
    if angle < 1e-12:
        return np.array([1.0, 0.5 * x, 0.5 * y, 0.5 * z])
    s = math.sin(0.5 * angle) / angle
    return np.array([math.cos(0.5 * angle), s * x, s * y, s * z])


def quat_multiply(a, b):
    aw, ax, ay, az = a.tolist() if isinstance(a, np.ndarray) else a
    bw, bx, by, bz = b.tolist() if isinstance(b, np.ndarray) else b
    return np.array([aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw])


def rotvec_matrix(phi):
    """exp([phi]x) (Rodrigues)."""
    angle = float(np.linalg.norm(phi))
    k = skew(phi)
    if angle < 1e-4:  # series: the closed form loses digits to cancellation
        return np.eye(3) + (1 - angle ** 2 / 6) * k + (0.5 - angle ** 2 / 24) * k @ k
    return np.eye(3) + np.sin(angle) / angle * k + 2 * np.sin(0.5 * angle) ** 2 / angle ** 2 * k @ k


def right_jacobian(phi):
    """J_r(phi): d exp([phi]x) = exp([phi]x) [J_r dphi]x."""
    angle = float(np.linalg.norm(phi))
    k = skew(phi)
    if angle < 1e-3:
        return np.eye(3) - (0.5 - angle ** 2 / 24) * k + (1 / 6 - angle ** 2 / 120) * k @ k
    return (np.eye(3) - 2 * np.sin(0.5 * angle) ** 2 / angle ** 2 * k
            + (angle - np.sin(angle)) / angle ** 3 * k @ k)


class FlexibleBody:
    """Point masses in a lattice with D deformation modes.

    rest_lattice (N, 3) and modes (D, N, 3) are in the body frame (metres); points are given by
    lattice parameters uvw (P, 3) in [0, 1]^3 with masses (P,). `collides` marks the points the
    ground acts on (default: all with mass)."""

    def __init__(self, dims, rest_lattice, modes, mode_names, uvw, masses, collides=None):
        self.dims = tuple(int(n) for n in dims)
        self.rest_lattice = np.asarray(rest_lattice, float).reshape(-1, 3)
        if len(self.rest_lattice) != np.prod(self.dims):
            raise FlexibleError(f"lattice of {self.dims} needs {np.prod(self.dims)} points, "
                                f"got {len(self.rest_lattice)}")
        self.modes = np.asarray(modes, float).reshape(len(modes), len(self.rest_lattice), 3)
        self.mode_names = list(mode_names)
        if len(self.mode_names) != len(self.modes):
            raise FlexibleError("one name per deformation mode is needed")
        self.uvw = np.atleast_2d(np.asarray(uvw, float))
        self.masses = np.asarray(masses, float).ravel()
        if len(self.masses) != len(self.uvw) or len(self.masses) == 0:
            raise FlexibleError("one mass per sample point is needed, and at least one point")
        if np.any(self.masses < 0) or self.masses.sum() <= 0:
            raise FlexibleError("point masses must be non-negative with a positive total")
        self.collides = (self.masses > 0) if collides is None else np.asarray(collides, bool)
        self.weights = lattice_weights(self.uvw, self.dims)            # W (P, N)
        self.X0 = self.weights @ self.rest_lattice                     # (P, 3)
        self.B = np.einsum("pn,dnc->dpc", self.weights, self.modes)    # (D, P, 3)
        self._B_flat = self.B.reshape(len(self.modes), 3 * len(self.masses))

    @classmethod
    def from_points(cls, dims, rest_lattice, modes, mode_names, points, masses, collides=None):
        """Points given in the body frame instead of lattice parameters."""
        rest = np.asarray(rest_lattice, float).reshape(-1, 3)
        return cls(dims, rest, modes, mode_names, lattice_params(points, rest, dims), masses, collides)

    @property
    def mode_count(self):
        return len(self.modes)

    @property
    def dof(self):
        return 6 + len(self.modes)

    @property
    def total_mass(self):
        return float(self.masses.sum())

    def local_points(self, gamma):
        """y (P, 3): points in the body frame for amplitudes gamma."""
        return self.X0 + (np.asarray(gamma, float) @ self._B_flat).reshape(self.X0.shape)

    def lattice_points(self, gamma):
        return self.rest_lattice + np.tensordot(np.asarray(gamma, float), self.modes, axes=1)

    def body_jacobian(self, y, rot):
        """G (P, 3, n): J_p = R G_p at phi = 0 (see the module docstring)."""
        P, D = len(y), self.mode_count
        G = np.empty((P, 3, 6 + D))
        G[:, :, 0:3] = rot.T
        G[:, :, 3:6] = -skew(y)
        G[:, :, 6:] = self.B.transpose(1, 2, 0)
        return G

    def jacobians(self, gamma, rot, phi=None):
        """World Jacobians J (P, 3, n) of every point (eq. 4.6-4.8), optionally at a rotation
        increment phi != 0 (J_phi = -R E [y]x J_r(phi)) for checks against finite differences."""
        y = self.local_points(gamma)
        if phi is None:
            return np.einsum("ij,pjk->pik", rot, self.body_jacobian(y, rot))
        E = rotvec_matrix(phi)
        RE = rot @ E
        P, D = len(y), self.mode_count
        J = np.empty((P, 3, 6 + D))
        J[:, :, 0:3] = np.eye(3)
        J[:, :, 3:6] = -np.einsum("ij,pjk,kl->pil", RE, skew(y), right_jacobian(phi))
        J[:, :, 6:] = np.einsum("ij,dpj->pid", RE, self.B)
        return J

    def positions(self, t, rot, gamma, phi=None):
        y = self.local_points(gamma)
        R = rot if phi is None else rot @ rotvec_matrix(phi)
        return np.asarray(t, float) + y @ R.T

    def mass_matrix(self, gamma, rot=None, phi=None):
        """M = sum m J^T J (eq. 4.10)."""
        rot = np.eye(3) if rot is None else rot
        J = self.jacobians(gamma, rot, phi)
        return np.einsum("p,pia,pib->ab", self.masses, J, J)

    def jacobian_derivatives(self, gamma, rot):
        """dJ/dq_j (n, P, 3, n) at phi = 0, analytically (eq. 4.14-4.19 in 3-D)."""
        y = self.local_points(gamma)
        P, D = len(y), self.mode_count
        n = 6 + D
        dJ = np.zeros((n, P, 3, n))
        eye = np.eye(3)
        for a in range(3):
            # d/dphi_a of the rotation columns: -R([e_a]x[y]x - 1/2 [y]x[e_a]x)
            ea = skew(eye[a])
            dJ[3 + a, :, :, 3:6] = -np.einsum("ij,pjk->pik", rot,
                                              np.einsum("jk,pkl->pjl", ea, skew(y))
                                              - 0.5 * np.einsum("pjk,kl->pjl", skew(y), ea))
            # d/dphi_a of the mode columns: R [e_a]x B_k
            dJ[3 + a, :, :, 6:] = np.einsum("ij,jk,dpk->pid", rot, ea, self.B)
        for k in range(D):
            # d/dgamma_k of the rotation columns: -R [B_k]x
            dJ[6 + k, :, :, 3:6] = -np.einsum("ij,pjk->pik", rot, skew(self.B[k]))
        return dJ

    def mass_matrix_derivatives(self, gamma, rot=None):
        """dM/dq_j (n, n, n) (eq. 4.13): sum m [(J^T dJ)^T + J^T dJ]."""
        rot = np.eye(3) if rot is None else rot
        J = self.jacobians(gamma, rot)
        dJ = self.jacobian_derivatives(gamma, rot)
        JtdJ = np.einsum("p,pia,jpib->jab", self.masses, J, dJ)
        return JtdJ + JtdJ.transpose(0, 2, 1)

    def lagrange_velocity_terms(self, gamma, rot, u):
        """The velocity part of eq. 4.21: 1/2 u^T dM/dq_k u - (sum_l dM/dq_l u_l) u."""
        dM = self.mass_matrix_derivatives(gamma, rot)
        return 0.5 * np.einsum("i,kij,j->k", u, dM, u) - np.einsum("lkj,l,j->k", dM, u, u)

    def velocity_terms(self, gamma, rot, u):
        """The same terms as -sum m J^T (dJ/dt u): the velocity-dependent acceleration of a point
        in the body frame is w x (w x y) + 2 w x y_dot, which costs O(P) instead of O(P n^2)."""
        y = self.local_points(gamma)
        G = self.body_jacobian(y, rot)
        c = self._coriolis(y, u)
        return -np.einsum("pia,pi->a", G, self.masses[:, None] * c)

    def _coriolis(self, y, u):
        w = u[3:6]
        ydot = (u[6:] @ self._B_flat).reshape(y.shape)
        return np.cross(w, np.cross(w, y)) + 2.0 * np.cross(w, ydot)

    def kinetic_energy(self, gamma, rot, u):
        return 0.5 * u @ self.mass_matrix(gamma, rot) @ u

    def modal_masses(self):
        """Diagonal of M's mode block at rest: what a natural frequency is measured against."""
        return np.einsum("p,dpc,dpc->d", self.masses, self.B, self.B)

    def extent(self):
        return self.X0[self.masses > 0].max(axis=0) - self.X0[self.masses > 0].min(axis=0)


def check_modes(body, correlation=0.995, weak=1e-6):
    """Problems with the deformation modes (thesis §4.10.3), each a sentence naming the modes:
    a mode that moves no mass, two modes that (nearly) duplicate each other, a mode that is a
    rigid motion or a combination of other modes. Measured in the mass metric at rest."""
    problems = []
    M = body.mass_matrix(np.zeros(body.mode_count))
    names = body.mode_names
    modal = np.diag(M)[6:]
    scale = body.total_mass * float(np.sum(body.extent() ** 2) + 1e-12)
    moving = [k for k in range(body.mode_count) if modal[k] > weak * scale]
    for k in range(body.mode_count):
        if k not in moving:
            problems.append(f"mode '{names[k]}' moves none of the mass points")
    flagged = set()
    for i_pos, i in enumerate(moving):
        for j in moving[i_pos + 1:]:
            c = M[6 + i, 6 + j] / np.sqrt(M[6 + i, 6 + i] * M[6 + j, 6 + j])
            if abs(c) > correlation:
                problems.append(f"modes '{names[i]}' and '{names[j]}' are near duplicates "
                                f"(correlation {c:+.4f})")
                flagged.update((i, j))
    # a mode that a rigid motion or the other modes reproduce: small residual after projection
    for k in moving:
        if k in flagged:
            continue
        others = [c for c in range(6)] + [6 + j for j in moving if j != k]
        A = M[np.ix_(others, others)]
        b = M[others, 6 + k]
        try:
            x = np.linalg.lstsq(A, b, rcond=None)[0]
        except np.linalg.LinAlgError:
            continue
        residual = (M[6 + k, 6 + k] - b @ x) / M[6 + k, 6 + k]
        if residual < 1.0 - correlation ** 2:
            problems.append(f"mode '{names[k]}' is nearly a rigid motion or a combination of the "
                            f"other modes (independent part {100 * max(residual, 0):.2f} %)")
    return problems
