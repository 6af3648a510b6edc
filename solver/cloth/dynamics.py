"""The coarse cloth's dynamics (Oshita 2003 §4.4): elastic springs on the edges (eq. 4.1),
bending springs across adjacent faces, gravity, air drag and wind, damping; explicit RK4 with
substeps; Provot-style correction of elongated edges (§4.4.3); particles pinned to targets."""

import numpy as np
from scipy import sparse

from .materials import AIR_DENSITY, as_vector
from .mesh import face_normals

# explicit RK4 is stable for |lambda dt| up to about 2.8 on the imaginary axis: keep a margin
STABLE_OMEGA_DT = 2.2
STABLE_DAMPING_DT = 1.0  # damping shares the step's stability budget with the springs


class ClothDynamics:
    """Forces and integration of the particles; `pinned` particles follow given targets."""

    def __init__(self, mesh, params, pinned=()):
        self.mesh, self.params = mesh, params
        p = mesh.particle_count
        self.pinned = np.zeros(p, dtype=bool)
        self.pinned[np.asarray(pinned, dtype=np.int64)] = True
        self.free = ~self.pinned
        self.mass = np.maximum(params.density * mesh.area, 1e-6)
        self.inv_mass = np.where(self.pinned, 0.0, 1.0 / self.mass)
        self.gravity = as_vector(params.gravity)
        self.wind = as_vector(params.wind)
        e0, e1 = mesh.edges[:, 0], mesh.edges[:, 1]
        self._e0, self._e1 = e0, e1
        self._b0, self._b1 = mesh.bend_pairs[:, 0], mesh.bend_pairs[:, 1]
        self.stretch, self.bend, self.damping = params.stretch, params.bend, params.damping
        self.capped = False
        self.relax, self.avg_power = 1.0, 1.0
        p_count, b = len(self.mass), len(self._b0)
        self._bend_incidence = sparse.csr_matrix(
            (np.r_[np.ones(b), -np.ones(b)], (np.r_[self._b0, self._b1], np.r_[np.arange(b), np.arange(b)])),
            shape=(p_count, b))
        e = len(self._e0)
        self._at0 = sparse.csr_matrix((np.ones(e), (self._e0, np.arange(e))), shape=(p_count, e))
        self._at1 = sparse.csr_matrix((np.ones(e), (self._e1, np.arange(e))), shape=(p_count, e))
        self._colours = self._edge_colouring()
        f = len(mesh.faces)
        self._face_incidence = sparse.csr_matrix(
            (np.ones(3 * f), (mesh.faces.ravel(), np.repeat(np.arange(f), 3))), shape=(p_count, f))

    def _edge_colouring(self):
        """Groups of edges with no particle in common (greedy colouring), with each end's share
        of a correction (inverse mass; pinned ends take none) and the length limit."""
        e0, e1, w = self._e0, self._e1, self.inv_mass
        wsum = w[e0] + w[e1]
        movable = wsum > 0.0
        self._share0 = np.where(movable, w[e0] / np.where(movable, wsum, 1.0), 0.0)
        self._share1 = np.where(movable, w[e1] / np.where(movable, wsum, 1.0), 0.0)
        limit = self.mesh.rest_length * (1.0 + self.params.stretch_limit)
        colour = np.full(len(e0), -1)
        used = [set() for _ in range(len(w))]
        for e in np.flatnonzero(movable):
            c = 0
            while c in used[e0[e]] or c in used[e1[e]]:
                c += 1
            colour[e] = c
            used[e0[e]].add(c)
            used[e1[e]].add(c)
        groups = []
        for c in range(colour.max() + 1):
            g = np.flatnonzero(colour == c)
            groups.append((g, e0[g], e1[g], self._share0[g][:, None], self._share1[g][:, None], limit[g]))
        return groups

    def unit_stiffness_eigenvalue(self, pairs, rest_length):
        """Largest eigenvalue of M^-1/2 K M^-1/2 for springs of unit stiffness on `pairs` at rest
        (free particles only): the squared highest angular frequency per N/m."""
        x = self.mesh.rest
        d = (x[pairs[:, 1]] - x[pairs[:, 0]]) / rest_length[:, None]
        block = d[:, :, None] * d[:, None, :]  # (S, 3, 3)
        p = len(x)
        rows, cols, vals = [], [], []
        for a, b, sign in ((0, 0, 1.0), (1, 1, 1.0), (0, 1, -1.0), (1, 0, -1.0)):
            r = 3 * pairs[:, a][:, None, None] + np.arange(3)[None, :, None]
            c = 3 * pairs[:, b][:, None, None] + np.arange(3)[None, None, :]
            rows.append(np.broadcast_to(r, block.shape).ravel())
            cols.append(np.broadcast_to(c, block.shape).ravel())
            vals.append((sign * block).ravel())
        k = sparse.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(3 * p, 3 * p))
        free = np.flatnonzero(np.repeat(self.free, 3))
        scale = 1.0 / np.sqrt(np.repeat(self.mass, 3)[free])
        a = sparse.diags(scale) @ k[free][:, free] @ sparse.diags(scale)
        if a.shape[0] <= 600:
            return float(np.linalg.eigvalsh(a.toarray()).max())
        from scipy.sparse.linalg import eigsh
        return float(eigsh(a, k=1, which="LA", return_eigenvectors=False, tol=1e-3)[0])

    def limit_stiffness(self, dt):
        """Explicit RK4 is stable only while the highest frequency times the step stays below
        about 2.8: scale the springs (and the edge damping) down to that limit, with a margin,
        when the material asks for more. Elongation is a constraint (§4.4.3), so soft springs
        keep the garment's size; the thesis makes the same trade. True if anything was capped."""
        p = self.params
        if not self.free.any():
            return False
        lam_e = self.unit_stiffness_eigenvalue(self.mesh.edges, self.mesh.rest_length)
        lam_b = (self.unit_stiffness_eigenvalue(self.mesh.bend_pairs, self.mesh.bend_rest)
                 if len(self.mesh.bend_pairs) else 0.0)
        lam = p.stretch * lam_e + p.bend * lam_b  # an upper bound of the sum's eigenvalue
        scale = min(1.0, (STABLE_OMEGA_DT / dt) ** 2 / max(lam, 1e-12))
        self.stretch, self.bend = p.stretch * scale, p.bend * scale
        self.damping = min(p.damping, STABLE_DAMPING_DT / (dt * lam_e))
        self.capped = scale < 1.0 or self.damping < p.damping
        return self.capped

    # ---- forces -------------------------------------------------------------------------
    def spring_forces(self, x, v):
        """Per-edge forces on the first particle, eq. 4.1 with a dashpot: (E, 3)."""
        mesh = self.mesh
        d = x[self._e1] - x[self._e0]
        length = np.sqrt(np.einsum("ij,ij->i", d, d))
        stretch = (length - mesh.rest_length) / mesh.rest_length  # |f| = k |d|/L (|d| - L), along d
        dv = v[self._e1] - v[self._e0]
        along = np.einsum("ij,ij->i", dv, d) / np.maximum(length * length, 1e-18)
        return (self.stretch * stretch + self.damping * along)[:, None] * d

    def accelerations(self, x, v):
        mesh, p = self.mesh, self.params
        f_edge = self.spring_forces(x, v)
        force = mesh.incidence @ f_edge
        if len(self._b0):
            d = x[self._b1] - x[self._b0]
            length = np.sqrt(np.einsum("ij,ij->i", d, d))
            fb = (self.bend * (length - mesh.bend_rest) / mesh.bend_rest)[:, None] * d
            force += self._bend_incidence @ fb
        rel = v - self.wind
        if p.drag > 0.0:  # air pushes against the motion across the cloth: 1/2 rho Cd A |vn| vn
            n = self.particle_normals(x)
            vn = np.einsum("ij,ij->i", rel, n)
            force -= (0.5 * AIR_DENSITY * p.drag * mesh.area * np.abs(vn) * vn)[:, None] * n
        acc = force * self.inv_mass[:, None] + self.gravity - p.air_damping * v
        acc[self.pinned] = 0.0
        return acc

    def particle_normals(self, x):
        n, area = face_normals(x, self.mesh.faces)
        out = self._face_incidence @ (n * area[:, None])
        return out / np.maximum(np.linalg.norm(out, axis=1), 1e-12)[:, None]

    # ---- integration ----------------------------------------------------------------------
    def rk4_step(self, x, v, dt, pin_x0, pin_x1):
        """One RK4 step of length dt; pinned particles move linearly from pin_x0 to pin_x1."""
        pins = self.pinned
        pin_v = (pin_x1 - pin_x0) / dt

        def state_at(xs, vs, s):
            xs, vs = xs.copy(), vs.copy()
            xs[pins] = pin_x0 + s * (pin_x1 - pin_x0)
            vs[pins] = pin_v
            return xs, vs

        x0, v0 = state_at(x, v, 0.0)
        a1 = self.accelerations(x0, v0)
        x2, v2 = state_at(x0 + 0.5 * dt * v0, v0 + 0.5 * dt * a1, 0.5)
        a2 = self.accelerations(x2, v2)
        x3, v3 = state_at(x0 + 0.5 * dt * v2, v0 + 0.5 * dt * a2, 0.5)
        a3 = self.accelerations(x3, v3)
        x4, v4 = state_at(x0 + dt * v3, v0 + dt * a3, 1.0)
        a4 = self.accelerations(x4, v4)
        x_new = x0 + dt / 6.0 * (v0 + 2.0 * v2 + 2.0 * v3 + v4)
        v_new = v0 + dt / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4)
        x_new[pins], v_new[pins] = pin_x1, pin_v
        return x_new, v_new

    def limit_elongation(self, x, v):
        """Provot's correction (§4.4.3): an edge longer than (1 + limit) L has its particles moved
        towards each other (inverse-mass weighted; pinned ones stay), and the part of their
        relative velocity that stretches it further is removed. Shortened edges are left alone:
        the smoothing keeps their curves at length. Gauss-Seidel over groups of edges that share
        no particle (an edge colouring), so each group is one vectorised pass; sweeps stop when
        no edge is over the limit. Returns (x, v, number of edges corrected)."""
        p = self.params
        x, v = x.copy(), v.copy()
        e0, e1 = self._e0, self._e1
        limit = self.mesh.rest_length * (1.0 + p.stretch_limit)
        corrected = np.zeros(len(e0), dtype=bool)
        for _ in range(max(1, p.constraint_iterations)):
            d = x[e1] - x[e0]
            over = np.einsum("ij,ij->i", d, d) > limit * limit
            if not over.any():
                break
            corrected |= over
            for group, a, b, s0, s1, lim in self._colours:
                d = x[b] - x[a]
                length = np.sqrt(np.einsum("ij,ij->i", d, d))
                excess = np.maximum(length - lim, 0.0) / np.maximum(length, 1e-12)
                dx = excess[:, None] * d
                x[a] += s0 * dx
                x[b] -= s1 * dx
        if corrected.any():  # one sweep: no corrected edge keeps stretching
            for group, a, b, s0, s1, lim in self._colours:
                on = corrected[group]
                if not on.any():
                    continue
                d = x[b] - x[a]
                unit = d / np.maximum(np.sqrt(np.einsum("ij,ij->i", d, d)), 1e-12)[:, None]
                rate = np.where(on, np.maximum(np.einsum("ij,ij->i", v[b] - v[a], unit), 0.0), 0.0)
                dv = rate[:, None] * unit
                v[a] += s0 * dv
                v[b] -= s1 * dv
        return x, v, int(corrected.sum())

    # ---- energy (for tests and diagnostics) -------------------------------------------------
    def energy(self, x, v):
        """Kinetic + spring potential (of eq. 4.1's force) + gravity potential, joules."""
        mesh = self.mesh

        def spring(k, length, rest):  # integral of k s/L (s - L) ds from L
            return k / rest * (length ** 3 / 3.0 - rest * length ** 2 / 2.0 + rest ** 3 / 6.0)

        le = np.linalg.norm(x[self._e1] - x[self._e0], axis=1)
        lb = np.linalg.norm(x[self._b1] - x[self._b0], axis=1)
        # the bending springs are linear in (l - L)/L times d: the same integral shape
        u = spring(self.stretch, le, mesh.rest_length).sum() + spring(self.bend, lb, mesh.bend_rest).sum()
        kinetic = 0.5 * np.sum(self.mass[self.free] * np.einsum("ij,ij->i", v[self.free], v[self.free]))
        grav = -np.sum(self.mass[self.free] * (x[self.free] @ self.gravity))
        return kinetic + u + grav
