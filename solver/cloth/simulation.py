"""A garment over a frame range: dynamics, collisions and smoothing per frame, with timings."""

import time

import numpy as np

from .collision import penetration, query_bodies, resolve_contacts, resolve_particles
from .dynamics import ClothDynamics
from .fast import rowdot
from .mesh import ClothError, edge_lengths
from .smoothing import Smoother, _grid

# the per-phase timings are CPU time of this process: on a shared machine wall-clock time counts
# the other processes' share too (the simulation runs on one thread)
_clock = time.process_time
# pushes of the frame's last collision pass (and the fine surface's) per particle, at most: a
# particle wedged where two capsules meet is pushed out of one into the other, then along their
# crease (collision._push), which takes two passes there; more where three parts meet (only
# particles still inside are queried again)
FRAME_END_PASSES = 16


def _settle_parts(sweeps):
    """The frame-end Provot sweeps in parts, each followed by a particle pass (see _settle): a
    third, then the rest (on the benchmark's replays, with 30 plain sweeps, 5 + 25, 15 + 15, 20 +
    10 and 10 + 10 + 10 kept less margin under the 2 % mean stretch than 10 + 20)."""
    first = max(1, round(sweeps / 3))
    return (first, sweeps - first) if first < sweeps else (sweeps,)


class ClothSimulation:
    """Advance with `step(pin_targets, dt)` after setting the bodies' motion for the frame
    (`body.set_motion(start pose, end pose, dt)`); `surface()` gives the smoothed fine mesh."""

    def __init__(self, mesh, params, pinned=(), bodies=(), level=2, fps=30.0, positions=None,
                 normal_control=True, edge_control=True, surface_collision=True):
        self.mesh, self.params = mesh, params
        self.dynamics = ClothDynamics(mesh, params, pinned)
        self.pins = np.flatnonzero(self.dynamics.pinned)
        self.movable = self.dynamics.free
        self._everyone = np.ones(len(self.movable), dtype=bool)
        self.bodies = list(bodies)
        self.substeps = max(1, int(params.substeps))
        self.dynamics.limit_stiffness(1.0 / (fps * self.substeps))
        self.x = np.array(mesh.rest if positions is None else positions, dtype=float)
        self.v = np.zeros_like(self.x)
        self.smoother = Smoother(mesh, level, params.stretch, normal_control, edge_control)
        self.timing = {"integration": 0.0, "collision": 0.0, "smoothing": 0.0}
        self.frames = 0
        self.contacts = {"particles": 0, "faces": 0}
        self.corrected_edges = 0
        self.surface_collision = surface_collision
        self.surface_pushed = 0
        self._phi_end = None  # (positions, phi) after a frame's last collision pass
        # each fine vertex's nearest corner particle (of a face it lies on): the Lipschitz bound
        # phi(q) >= phi(corner) - |q - corner| tells which fine vertices can reach the body
        tess = self.smoother.tess
        n = 2 * tess.level
        grid = np.array([(n - i - j, i, j) for i, j in _grid(n)])
        corner = mesh.faces[:, np.argmax(grid, axis=1)]  # (F, G)
        ref = np.empty(tess.vertex_count, dtype=np.int64)
        ref[tess.vertex_of.ravel()] = corner.ravel()
        self._fine_ref = ref[mesh.particle_count:]

    def step(self, pin_targets=None, dt=1.0 / 30.0):
        """One frame of length dt: pinned particles reach `pin_targets` (K, 3) at its end."""
        dyn, n = self.dynamics, self.substeps
        h = dt / n
        start = self.x[self.pins].copy()
        end = start if pin_targets is None else np.asarray(pin_targets, float)
        x, v = self.x, self.v
        for k in range(n):
            t0 = _clock()
            pa, pb = start + (end - start) * (k / n), start + (end - start) * ((k + 1) / n)
            x, v = dyn.rk4_step(x, v, h, pa, pb)
            x, v, corrected = dyn.limit_elongation(x, v)
            t1 = _clock()
            n_p, n_f = self._contacts(x, v, (k + 1) / n, k == n - 1)
            t2 = _clock()
            self.timing["integration"] += t1 - t0
            self.timing["collision"] += t2 - t1
            self.corrected_edges += corrected
            self.contacts["particles"] += n_p
            self.contacts["faces"] += n_f
        x, v = self._settle(x, v)
        if not (np.isfinite(x).all() and np.isfinite(v).all()):
            raise ClothError("the cloth simulation became unstable: use more substeps or softer settings")
        self.x, self.v = x, v
        self.frames += 1
        return x

    def _contacts(self, x, v, s, last):
        """The body's pushes at time s of the frame (in place): the particle case at every
        substep, the face case (a face cutting the body between corners that are out) at the
        frame's last one only. A face pushed out at an earlier substep is moved again by the next
        substep's springs and sweeps anyway; on the benchmark's replays (six trajectories each,
        1e-9 m apart at the start) it cost 9 % of the frame and left the stretch no lower (max
        mean stretch, skirt: 1.41-1.70 % at every substep, 1.21-1.40 % at the last; the tests'
        walk and hop 1.08 / 1.18 % and 1.00 / 1.02 %; coat 1.87-2.46 % and 1.95-2.18 %), nothing
        deeper. The corners a face pushes may land in another part of the body: the frame end's
        particle passes, next, take them out. Returns (particles moved, faces moved)."""
        p = self.params
        return resolve_contacts(x, v, self.mesh.faces if last else None, self.bodies, s, p.thickness, self.movable,
                                p.friction, self._everyone, again=False)

    def _settle(self, x, v):
        """The frame that is shown: the body's pushes may have stretched or squeezed edges, so the
        lengths are restored thoroughly (final_iterations Provot sweeps, Chebyshev-accelerated:
        12 of them hold the benchmark's coat closer to its rest size than 30 plain ones did, see
        dynamics.CHEBYSHEV_RHO) and the particles kept out
        of the body. Collisions are resolved inside these sweeps too, as position-based dynamics
        does: sweeps that ignore the body drag particles into it, and a particle pass after all of
        them pushes such a particle far from where its edges want it (on the benchmark's walk a
        skirt particle dragged 32 mm into the raised thigh went 40 mm back towards the pinned
        waist, squeezing its edges to 0.7 L: the mean shortening passed 2 %). So a particle pass
        follows the first third of the sweeps too; the rest work from outside the body."""
        dyn, sweeps = self.dynamics, self.params.final_iterations
        for part in (_settle_parts(sweeps) if self.bodies else (sweeps,)):
            t0 = _clock()
            x, v, _ = dyn.limit_elongation(x, v, part, frame_end=True)
            t1 = _clock()
            if self.bodies:
                phi = resolve_particles(x, v, self.bodies, 1.0, self.params.thickness, self._everyone,
                                        self.params.friction, passes=FRAME_END_PASSES)[1]
            self.timing["integration"] += t1 - t0
            self.timing["collision"] += _clock() - t1
        if self.bodies:
            self._phi_end = (x.copy(), self._motions(), phi)
        return x, v

    def surface(self):
        """The smoothed fine surface of the current particles. Its curved patches can bulge into
        the body between particles that are all outside (the thesis notes it); with
        `surface_collision` such fine vertices are pushed back out to the thickness."""
        t0 = _clock()
        out = self.smoother.surface(self.x)
        t1 = _clock()
        self.timing["smoothing"] += t1 - t0
        if self.bodies and self.surface_collision:
            self._push_surface_out(out)
            self.timing["collision"] += _clock() - t1
        return out

    def _phi_now(self):
        """phi of the current particles at the frame's end (from its last collision pass when
        they have not moved since)."""
        known = self._phi_end
        if (known is not None and known[0].shape == self.x.shape and known[1] == self._motions()
                and np.array_equal(known[0], self.x)):
            return known[2]
        return query_bodies(self.bodies, self.x, 1.0)[0]

    def _motions(self):
        return [getattr(b, "motions", None) for b in self.bodies]

    def _push_surface_out(self, fine):
        """Fine vertices inside the body go back out to the thickness; only those that can reach
        the body are tested (phi is 1-Lipschitz: phi(q) >= phi(c) - |q - c| for the particle c
        at the nearest corner of q's face)."""
        p = self.mesh.particle_count
        phi = self._phi_now()
        ref = self._fine_ref
        d = fine[p:] - self.x.take(ref, axis=0)
        bound = phi.take(ref) - np.sqrt(rowdot(d, d))
        idx = np.flatnonzero(bound < self.params.thickness)
        if len(idx) == 0:
            return
        idx += p  # the particles are already out
        pts = fine[idx]
        pushed, _ = resolve_particles(pts, np.zeros_like(pts), self.bodies, 1.0, self.params.thickness,
                                      np.ones(len(idx), dtype=bool), passes=FRAME_END_PASSES)
        fine[idx] = pts
        self.surface_pushed += pushed

    def stretch(self):
        """Mean edge length over rest length, minus 1 (elongation handled: ~0)."""
        return float(np.mean(edge_lengths(self.mesh, self.x) / self.mesh.rest_length) - 1.0)

    def depth_inside(self, points=None):
        if points is None:
            return np.maximum(-self._phi_now(), 0.0)
        return penetration(points, self.bodies, 1.0)

    def ms_per_frame(self):
        f = max(self.frames, 1)
        out = {k + "_ms": 1000.0 * t / f for k, t in self.timing.items()}
        out["total_ms"] = sum(out.values())
        return out
