"""The coarse cloth's dynamics (Oshita 2003 §4.4): elastic springs on the edges (eq. 4.1),
bending springs across adjacent faces, gravity, air drag and wind, damping; explicit RK4 with
substeps; Provot-style correction of elongated edges (§4.4.3); particles pinned to targets."""

import numpy as np
from scipy import sparse

from .fast import CornerSum, IndexDifference, rowdot
from .materials import AIR_DENSITY, as_vector
from .mesh import face_cross

# explicit RK4 is stable for |lambda dt| up to about 2.8 on the imaginary axis: keep a margin
STABLE_OMEGA_DT = 2.2
# Jacobi sweeps of the velocity filter after a correction (corrected edges stop stretching): one
# after a substep's correction removes most of it, three after the frame end's (the velocities the
# next frame starts from). On the benchmark's replays three after each substep too changed no
# stretch figure beyond its spread; with 3 Provot sweeps a substep, not 4, they cost 5 % of the frame
VELOCITY_SWEEPS = 1
VELOCITY_SWEEPS_END = 3
SLACK = 2e-3  # relative overshoot of a length limit the correction tolerates
RELAX = 1.5  # over-relaxation of the averaged (Jacobi) length corrections
STABLE_DAMPING_DT = 1.0  # damping shares the step's stability budget with the springs
# Chebyshev semi-iterative acceleration of the frame-end sweeps (Wang 2015, "A Chebyshev
# semi-iterative approach for accelerating projective and position-based dynamics"): the spectral
# radius estimate of the plain sweeps, and the sweep from which the acceleration starts. On the
# benchmark's replays 12 accelerated sweeps (rho 0.95) left the skirt's max mean stretch at 1.40-1.50 %
# and the coat's at 1.54-1.85 %, where 30 plain ones left 1.21-1.40 % and 1.95-2.18 %; rho 0.9 and
# 0.97 let a coat vertex end 1.6-1.9 mm inside (overshoot the particle passes could not undo)
CHEBYSHEV_RHO = 0.95
CHEBYSHEV_FROM = 2  # (the first two sweeps plain)


class ParticleSum:
    """A sum over items (springs, edges) into particles: for values (N, k) per item,
    out[first] += w_first values and out[second] += w_second values.

    The plain formula is np.add.at(out, first, w_first[:, None] * values) and the same for
    second; kept instead as a compiled CSR product (particles x items) whose entries per row are
    in a fixed order, particle by particle, items ascending (or `descending`), which saves 20-22 % of
    the time of the skirt on walking legs, collision and smoothing included (benchmarks/microopt.py,
    cloth_scatter_plan)."""

    def __init__(self, first, second, w_first, w_second, particles, descending=False):
        item = np.r_[np.arange(len(first)), np.arange(len(second))]
        particle = np.r_[first, second]
        order = np.lexsort((-item if descending else item, particle))
        weight = np.r_[w_first, w_second].astype(float)[order]
        indptr = np.r_[0, np.cumsum(np.bincount(particle, minlength=particles))]
        self.matrix = sparse.csr_matrix((weight, item[order].astype(np.int32), indptr.astype(np.int32)),
                                        shape=(particles, len(first)))

    def into(self, values, out):
        """The sums of `values` (N, k) written into `out` (particles, k); returns out."""
        out[...] = self.matrix @ values
        return out


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
        p_count = len(self.mass)
        self._limit = mesh.rest_length * (1.0 + params.stretch_limit)
        self._floor = mesh.rest_length * (1.0 - params.compress_limit) if params.compress_limit > 0 else \
            np.zeros(len(e0))
        self._movable_edge = (self.inv_mass[e0] + self.inv_mass[e1]) > 0.0
        # the sweeps' limits, open ([0, inf)) on edges no correction can move: never off
        self._floor_m = np.where(self._movable_edge, self._floor, 0.0)
        self._limit_m = np.where(self._movable_edge, self._limit, np.inf)
        wsum = np.where(self._movable_edge, self.inv_mass[e0] + self.inv_mass[e1], 1.0)
        self._share0, self._share1 = self.inv_mass[e0] / wsum, self.inv_mass[e1] / wsum
        # a correction along each edge, shared by the inverse masses: +share0 at the first
        # particle, -share1 at the second, over-relaxed by RELAX (a particle's move is the sum of
        # its edges' over their count); the count: the edges given that move each particle
        self._move = ParticleSum(e0, e1, RELAX * self._share0, -RELAX * self._share1, p_count)
        self._count = ParticleSum(e0, e1, self._share0 != 0.0, self._share1 != 0.0, p_count)
        self._edge_diff = IndexDifference(e0, e1)
        self._times_off = np.zeros(len(e0))  # per edge, the sweeps in which it was off
        self._floor_off = self._floor_m * (1.0 - SLACK)
        self._limit_off = self._limit_m * (1.0 + SLACK)
        # the sweeps' buffers: each edge's correction and whether it is off, each particle's
        # summed moves, count of edges off, its scale and step
        self._rows_d, self._rows_off = np.empty((len(e0), 3)), np.empty(len(e0))
        self._sweep_moves, self._sweep_count = np.empty((p_count, 3)), np.empty((p_count, 1))
        self._sweep_scale, self._sweep_step = np.empty((p_count, 1)), np.empty((p_count, 3))
        self._tether_data = self._tethers()
        self._corner_sum = CornerSum(mesh.faces, p_count)
        self._prepare()

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
        # a fixed start vector: ARPACK's random one made the capped stiffness (and so the whole
        # simulation of a garment over 200 particles) differ from run to run in the 3rd digit
        return float(eigsh(a, k=1, which="LA", return_eigenvectors=False, tol=1e-3, v0=np.ones(a.shape[0]))[0])

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
        self._scale_springs()
        return self.capped

    # ---- forces -------------------------------------------------------------------------
    def _prepare(self):
        """Edges and bending pairs as one set of springs, scaled by the inverse masses, so an
        evaluation is a handful of vectorised operations and one bincount (the stiffness apart:
        _scale_springs)."""
        mesh, p = self.mesh, self.params
        self._s0, self._s1 = np.r_[self._e0, self._b0], np.r_[self._e1, self._b1]
        self._srest = np.r_[mesh.rest_length, mesh.bend_rest]
        # a spring's force (on its first particle) goes +f to the first, -f to the second, each
        # divided by its mass (pinned ones: 0)
        self._acc = ParticleSum(self._s0, self._s1, self.inv_mass[self._s0], -self.inv_mass[self._s1],
                                len(self.mass), descending=True)
        self._free_f = self.free.astype(float)[:, None]
        # gravity and air damping act on the free particles: free_f (g - c v) as g_f - c_f v
        self._gravity_f = self._free_f * self.gravity
        self._air_f = self._free_f * p.air_damping
        self._windy = bool(np.any(self.wind != 0.0))
        self._pin_idx = np.flatnonzero(self.pinned)
        # the springs' vectors (rows of x) and the edges' relative velocities (rows of v) from
        # the stacked state [x; v] (2P, 3) at once
        p_count = len(self.mass)
        self._state_diff = IndexDifference(np.r_[self._s0, p_count + self._e0], np.r_[self._s1, p_count + self._e1])
        self._springs = len(self._s0)
        self._drag_of = 0.5 * AIR_DENSITY * p.drag * mesh.area * self.inv_mass
        self._edges = len(self._e0)
        self._scale_springs()

    def _scale_springs(self):
        """k / L of eq. 4.1 per spring (edges, then bending pairs) at the current stiffness."""
        self._sk = np.r_[np.full(len(self._e0), self.stretch), np.full(len(self._b0), self.bend)] / self._srest

    def spring_forces(self, x, v):
        """Per-edge forces on the first particle, eq. 4.1 with a dashpot: (E, 3)."""
        mesh = self.mesh
        d = x[self._e1] - x[self._e0]
        length = np.sqrt(rowdot(d, d))
        stretch = (length - mesh.rest_length) / mesh.rest_length  # |f| = k |d|/L (|d| - L), along d
        dv = v[self._e1] - v[self._e0]
        along = rowdot(dv, d) / np.maximum(length * length, 1e-18)
        return (self.stretch * stretch + self.damping * along)[:, None] * d

    def derivative(self, y, normals=None):
        """d/dt of the state y = [x, v] (2, P, 3): [v, accelerations]. The springs' vectors and
        the edges' relative velocities are differences of the stacked state's rows."""
        p = self.params
        x, v = y[0], y[1]
        both = self._state_diff(y.reshape(-1, 3))
        d = both[:self._springs]
        length = np.sqrt(rowdot(d, d))
        coef = self._sk * (length - self._srest)  # eq. 4.1 (bending springs alike)
        e = self._edges
        if self.damping > 0.0:
            le = length[:e]
            coef[:e] += self.damping * rowdot(both[self._springs:], d[:e]) / (le * le + 1e-18)
        out = np.empty_like(y)
        out[0] = v
        acc = self._acc.into(d * coef[:, None], out[1])
        acc += self._gravity_f - self._air_f * v
        if p.drag > 0.0:  # air pushes against the motion across the cloth: 1/2 rho Cd A |vn| vn
            n = self.particle_normals(x) if normals is None else normals
            vn = rowdot(v - self.wind if self._windy else v, n)
            w = self._drag_of * np.abs(vn)
            w *= vn
            acc -= w[:, None] * n
        return out

    def particle_normals(self, x):
        n = face_cross(x, self.mesh.faces)  # area-weighted face normals
        out = self._corner_sum @ np.repeat(n, 3, axis=0)
        return out / np.maximum(np.sqrt(rowdot(out, out)), 1e-12)[:, None]

    # ---- integration ----------------------------------------------------------------------
    def rk4_step(self, x, v, dt, pin_x0, pin_x1):
        """One RK4 step of length dt; pinned particles move linearly from pin_x0 to pin_x1.
        Positions and velocities advance together as one state [x, v] (2, P, 3)."""
        pins = self._pin_idx
        pin_v = (pin_x1 - pin_x0) / dt
        y0 = np.array((x, v))
        y0[0, pins] = pin_x0
        y0[1, pins] = pin_v
        n = self.particle_normals(y0[0]) if self.params.drag > 0.0 else None
        h = 0.5 * dt
        k1 = self.derivative(y0, n)
        y = y0 + h * k1
        pin_mid = 0.5 * (pin_x0 + pin_x1)
        y[0, pins] = pin_mid
        k2 = self.derivative(y, n)
        y = y0 + h * k2
        y[0, pins] = pin_mid
        k3 = self.derivative(y, n)
        y = y0 + dt * k3
        y[0, pins] = pin_x1
        k4 = self.derivative(y, n)
        k2 *= 2.0
        k2 += k1
        k3 *= 2.0
        k2 += k3
        k2 += k4
        k2 *= dt / 6.0
        k2 += y0
        k2[0, pins] = pin_x1
        k2[1, pins] = pin_v
        return k2[0], k2[1]

    def limit_elongation(self, x, v, iterations=None, frame_end=False):
        """Provot's correction (§4.4.3): the particles of an edge longer than (1 + limit) L are
        moved towards each other (inverse-mass weighted, pinned ones stay) back to that length,
        and the part of their relative velocity that stretches the edge further is removed.
        Shortened edges are left to the smoothing, unless shorter than (1 - compress_limit) L.

        All edges beyond a limit are corrected together (Jacobi): each particle takes the mean
        of its edges' corrections, over-relaxed by RELAX, for up to `iterations` sweeps (until
        none is beyond); the `frame_end` pass (the frame that is shown) sweeps Chebyshev-
        accelerated (CHEBYSHEV_RHO) and filters the velocities more thoroughly. Before that,
        tethers to the pins remove the stretch that accumulates along a hanging garment (which
        local corrections undo only slowly). Returns (x, v, number of edges corrected)."""
        p = self.params
        x, v = x.copy(), v.copy()
        floor, limit, low_off, high_off = self._floor_m, self._limit_m, self._floor_off, self._limit_off
        self._tether(x, v)
        rows_d, rows_off, diff = self._rows_d, self._rows_off, self._edge_diff
        moves, count, scale, step = self._sweep_moves, self._sweep_count, self._sweep_scale, self._sweep_step
        times_off = self._times_off
        times_off.fill(0.0)
        # the accelerated sweeps keep x_{k-1}: three buffers of their own, swapped, not copied
        prev, spare = (np.empty_like(x), np.empty_like(x)) if frame_end else (None, None)
        rho2, omega = CHEBYSHEV_RHO ** 2, 1.0
        for k in range(max(1, iterations or p.constraint_iterations)):
            d = diff(x)
            length = np.sqrt(rowdot(d, d))
            over = length - np.clip(length, floor, limit)
            # off: beyond a limit by more than SLACK of it (|over| > SLACK clip(length)), i.e.
            # outside [floor (1 - SLACK), limit (1 + SLACK)]; 1.0 / 0.0 in the sweep's 4th column
            np.not_equal(np.clip(length, low_off, high_off), length, out=rows_off)
            # (tested every 4th sweep only: a sweep with no edge off moves nothing)
            if not k & 3 and not rows_off.any():
                if k == 0:
                    return x, v, 0
                break
            times_off += rows_off
            over /= length
            over *= rows_off
            np.multiply(d, over[:, None], out=rows_d)
            self._move.into(rows_d, moves)  # each particle's summed moves (RELAX included)
            self._count.into(rows_off[:, None], count)  # and its edges off
            np.maximum(count, 1.0, out=scale)
            if frame_end:
                new = np.divide(moves, scale, out=spare)
                new += x  # the plain sweep's x_hat
                if k >= CHEBYSHEV_FROM:  # x_{k+1} = omega (x_hat - x_{k-1}) + x_{k-1}
                    omega = 2.0 / (2.0 - rho2) if k == CHEBYSHEV_FROM else 4.0 / (4.0 - rho2 * omega)
                    new -= prev
                    new *= omega
                    new += prev
                spare, prev, x = prev, x, new
            else:
                np.divide(moves, scale, out=step)
                x += step
        corrected = times_off > 0.0
        # corrected edges stop stretching (squeezed ones stop shortening)
        d = diff(x)
        length = np.sqrt(rowdot(d, d))
        u = d / np.maximum(length, 1e-12)[:, None]
        stretched = length > self.mesh.rest_length
        stretched &= corrected
        squeezed = corrected ^ stretched
        # a stretching edge's rate may only go down to 0, a squeezed one's up to 0, the others
        # stay: the clip bounds
        low = np.where(squeezed, -np.inf, 0.0)
        high = np.where(stretched, np.inf, 0.0)
        reach = self._count.into(corrected[:, None].astype(float), np.empty_like(count))
        np.maximum(reach, 1.0, out=reach)
        for _ in range(VELOCITY_SWEEPS_END if frame_end else VELOCITY_SWEEPS):
            rate = np.clip(rowdot(diff(v), u), low, high)  # (low <= high everywhere)
            v += self._move.into(rate[:, None] * u, step) / reach
        return x, v, int(np.count_nonzero(corrected))

    def _tethers(self):
        """Each free particle's nearest pin along the mesh and the rest length of that path
        (scipy's Dijkstra over the edges); empty without pins."""
        from scipy.sparse.csgraph import dijkstra
        pins = np.flatnonzero(self.pinned)
        if len(pins) == 0:
            return None
        n = len(self.mass)
        graph = sparse.csr_matrix((self.mesh.rest_length, (self._e0, self._e1)), shape=(n, n))
        dist, _, source = dijkstra(graph, directed=False, indices=pins, return_predecessors=True, min_only=True)
        free = np.flatnonzero(self.free & np.isfinite(dist) & (source >= 0))
        return free, source[free], dist[free] * (1.0 + self.params.stretch_limit)

    def _tether(self, x, v):
        """Accumulated stretch along a hanging garment, which the local corrections remove only
        slowly: no particle may be farther from its pin than the rest length of the path to it
        along the mesh (in place; the outward velocity is removed too)."""
        if self._tether_data is None:
            return
        i, anchor, reach = self._tether_data
        d = x.take(i, axis=0)
        d -= x.take(anchor, axis=0)
        length = np.sqrt(rowdot(d, d))
        over = length > reach
        if not over.any():
            return
        i, d, length, reach = i[over], d[over], length[over], reach[over]
        u = d / length[:, None]
        x[i] -= ((length - reach)[:, None]) * u
        out = np.maximum(rowdot(v[i] - v[anchor[over]], u), 0.0)
        v[i] -= out[:, None] * u

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
        kinetic = 0.5 * np.sum(self.mass[self.free] * rowdot(v[self.free], v[self.free]))
        grav = -np.sum(self.mass[self.free] * (x[self.free] @ self.gravity))
        return kinetic + u + grav
