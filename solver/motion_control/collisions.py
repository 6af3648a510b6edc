"""Contact impulses: the colliders (another character's bones, a fist) and the ground under a
fallen body or a swing foot.

Colliders are continuous (swept): each collider sphere's path over the step, relative to each body
capsule (a bone's two contact spheres and the segment between them, ControlBody.capsules) moving at
its velocity, is tested for the first instant it touches the capsule (swept_contacts), so a fast
fist cannot pass through between two steps. At the first contact an approaching pair gets the
impulse that leaves it separating at restitution times its approach speed (all pairs at once,
projected Gauss-Seidel on J H^-1 J' + B B'/M, pgs), friction included; the collider is kinematic
(infinite mass, it keeps pushing) unless Collider.mass is finite (one impulse per contact). A swing
foot (not planted) is kept above the ground by impulses on its leg's DOFs (swing_ground); a fallen
body's every contact sphere gets speculative ground contacts.
"""

from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import cho_factor, cho_solve

from ..dynamics import kinematics
from ..dynamics.ground_contact import point_jacobians
from .body import inertia
from .vector_math import cross


# the ground's contact basis, rows (normal, t1, t2): up, then the tangents the colliders' rule gives
# an upward normal (t1 = n x x, t2 = n x t1), exactly
GROUND_BASIS = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])


@dataclass
class Collisions:
    """The contact impulses of one control loop, and what they leave for the next step."""

    settings: object  # ControlSettings (colliders, restitution, friction, contact_iterations, ...)
    ground: float  # m, the ground's height
    dt_frame: float  # s, the colliders' frame time
    wrench: np.ndarray = None  # (nb, 6) contact forces of the last step's collisions (kinematic colliders)
    spent: set = field(default_factory=set)  # finite-mass colliders that gave their impulse, still touching

    def collide(self, body, q, v, t, dt, ground, planted):
        """Impulses of the ground (when `ground`) and of the colliders on the velocities v (after the
        step's acceleration, before its position update); remembers the collider forces.

        Colliders are continuous (swept): each collider sphere's path over the step, relative to each
        body capsule (a bone's two contact spheres and the segment between them) moving at its
        velocity, is tested for the first instant it touches the capsule, so a fast fist cannot pass
        through the body between two steps. The impulse acts at that first contact with the relative
        velocity there (the collider's over the step: its displacement / dt). A collider of finite
        mass is one rigid body (its spheres share its mass) that gives one impulse per contact: it
        is spent until it has left the body (a thrown fist hits once; only a kinematic collider
        keeps pushing while it moves into the body)."""
        m, d = body.model, body.data
        self.wrench = None
        swing = None if ground else body.swing_spheres(planted)
        if not (ground or self.settings.colliders or swing is not None):
            return v  # standing on both planted feet, nothing to collide with: no sphere is asked
        kinematics.update_frames(m, d, q)
        bodies = body.spheres[0]
        radii = body.contacts.radii
        centres = kinematics.body_points(d, bodies, body.sphere_hom)
        vel = kinematics.body_velocities(m, d, q, v).take(bodies, axis=0)
        if ground or self.settings.colliders:
            sphere_vel = vel[:, 3:] + cross(vel[:, :3], centres)
            vz = sphere_vel[:, 2]
        else:  # a swing foot alone asks the spheres' vertical speed: v_z + (omega x centre)_z
            vz = vel[:, 5] + (vel[:, 0] * centres[:, 1] - vel[:, 1] * centres[:, 0])
        # the ground's rows, all at once: sphere, contact point (its bottom), target normal speed
        ground_ks, ground_points, ground_targets = np.zeros(0, int), np.zeros((0, 3)), np.zeros(0)
        if ground:
            gap = centres[:, 2] - radii - self.ground
            # speculative: every sphere that could reach the ground within the step
            ground_ks = np.flatnonzero(gap < np.maximum(-vz, 0.0) * dt + 0.01)
            g = gap[ground_ks]
            ground_targets = np.where(g > 0, -g / dt, -self.settings.fall_correction * g / dt)
            ground_points = centres[ground_ks]
            ground_points[:, 2] -= radii[ground_ks]
        elif swing is not None:  # standing: a foot that is not planted (a swing foot) may not pass below the ground
            gap = centres[:, 2] - radii - self.ground
            near = swing & (gap < np.maximum(-vz, 0.0) * dt)
            if near.any():
                v = self.swing_ground(body, q, v, dt, np.flatnonzero(near), centres, gap)
        rows, owners = (self._collider_rows(body, centres, radii, sphere_vel, t, dt) if self.settings.colliders
                        else ([], []))
        ng = len(ground_ks)
        if not ng and not rows:
            return v
        # contacts: the ground's first (ng), then the colliders' (contact ng + i is rows[i])
        ks = np.concatenate((ground_ks, [r[0] for r in rows])).astype(int)
        points = np.concatenate((ground_points, np.reshape([r[1] for r in rows], (-1, 3))))
        jac = point_jacobians(m, d, q, bodies[ks], points)  # (c, 3, nv)
        basis = np.empty((len(ks), 3, 3))  # (c, 3, 3) rows n, t1, t2
        basis[:ng] = GROUND_BASIS
        if rows:
            normals = np.array([r[2] for r in rows])
            t1 = cross(normals, [1.0, 0.0, 0.0])
            t1[np.linalg.norm(t1, axis=1) < 1e-6] = cross(normals, [0.0, 1.0, 0.0])[np.linalg.norm(t1, axis=1) < 1e-6]
            t1 /= np.linalg.norm(t1, axis=1)[:, None]
            basis[ng:] = np.stack((normals, t1, cross(normals, t1)), axis=1)
        jr = np.einsum("cij,cjn->cin", basis, jac).reshape(-1, m.nv)  # (3c, nv)
        rel0 = jr @ v
        targets = np.empty(len(ks))
        targets[:ng] = ground_targets
        if rows:  # a collider: bounce at restitution when approaching
            rel0[3 * ng:] -= np.einsum("cij,cj->ci", basis[ng:], np.array([r[3] for r in rows])).ravel()
            vn = rel0[3 * ng::3]
            targets[ng:] = np.where(vn < 0, -self.settings.restitution * vn, -np.inf)
        active = targets > -np.inf
        if not active.any():
            return v
        idx = np.flatnonzero(active)
        sel = np.flatnonzero(np.repeat(active, 3))
        jr, rel0 = jr[sel], rel0[sel]
        targets = targets[active]
        chol = cho_factor(inertia(m, d, q))
        hij = cho_solve(chol, jr.T)  # (nv, 3c)
        w = jr @ hij
        # a collider of finite mass M is one translating body: its rows couple through B B' / M
        rows_basis = basis[idx].reshape(-1, 3)  # (3c, 3)
        row_owner = np.repeat([-1 if i < ng else owners[i - ng] for i in idx], 3)
        for ci in set(row_owner[row_owner >= 0].tolist()):
            mass = float(self.settings.colliders[ci].mass)
            if np.isfinite(mass) and mass > 0.0:
                rs = np.flatnonzero(row_owner == ci)
                w[np.ix_(rs, rs)] += rows_basis[rs] @ rows_basis[rs].T / mass
        p = pgs(w, rel0, targets, self.settings.friction, self.settings.contact_iterations)
        v = v + hij @ p
        self.wrench = self._collider_wrench(m, bodies, rows, owners, idx, ng, basis, p, dt)
        return v

    def _collider_rows(self, body, centres, radii, sphere_vel, t, dt):
        """The colliders' rows, (sphere, point (3,), normal (3,), collider velocity (3,)) each, and
        the collider of each row. Finite-mass colliders that gave their impulse and are still
        touching are kept across steps (spent) and give no row."""
        rows, owners = [], []
        ia, ib = body.capsules
        for ci, col in enumerate(self.settings.colliders):
            p0, p1 = self.collider_at(col, t)[0], self.collider_at(col, t + dt)[0]
            rc = np.asarray(col.radii, float)
            hits = swept_contacts(centres[ia], centres[ib], radii[ia], 0.5 * (sphere_vel[ia] + sphere_vel[ib]) * dt,
                                   p0, p1, rc)
            if not hits:
                self.spent.discard(ci)
                continue
            if np.isfinite(col.mass) and ci in self.spent:  # a thrown body gave its impulse: spent while in contact
                continue
            vel_c = (p1 - p0) / dt
            for cap, c, axis_point, n in hits:
                k = ia[cap]
                rows.append((k, axis_point - radii[k] * n, n, vel_c[c]))
                owners.append(ci)
        return rows, owners

    def _collider_wrench(self, m, bodies, rows, owners, idx, ng, basis, p, dt):
        """The colliders' contact forces (nb, 6) for the next step's inverse dynamics, or None: a
        kinematic collider keeps pushing; a finite-mass one gave its whole momentum in the
        impulses `p` (like an instant Impulse) and is spent."""
        wrench = None
        for j, i in enumerate(idx):
            if i < ng:  # the ground
                continue
            ci = owners[i - ng]
            if np.isfinite(self.settings.colliders[ci].mass):
                self.spent.add(ci)
                continue
            force = basis[i].T @ p[3 * j:3 * j + 3] / dt
            k, x = rows[i - ng][:2]
            wrench = np.zeros((m.nb, 6)) if wrench is None else wrench
            wrench[bodies[k]] += np.r_[cross(x, force), force]
        return wrench

    def swing_ground(self, body, q, v, dt, ks, centres, gap):
        """Ground impulses on a swing foot's spheres acting on its leg's DOFs only (the leg's own
        inertia block): like the planted legs' projection, the foot is kept out of the ground
        without jarring the rest of the body (a landing step would otherwise kick the pelvis)."""
        m, d = body.model, body.data
        bodies = body.spheres[0]
        h = None
        for s, foot in enumerate(body.parts.feet):
            fb = m.joint_body[foot]
            mine = ks[m.ancestors[bodies[ks]][:, fb] != 0]
            if not len(mine):
                continue
            cols = np.asarray(body.parts.legs[s])
            points = centres[mine].copy()
            points[:, 2] -= body.contacts.radii[mine]
            jac = point_jacobians(m, d, q, bodies[mine], points)[:, :, cols]  # (c, 3, leg)
            jr = jac.reshape(-1, len(cols))  # rows x, y, z: z the normal
            jr = jr[np.r_[[[3 * i + 2, 3 * i, 3 * i + 1] for i in range(len(mine))]].ravel()]
            h = inertia(m, d, q) if h is None else h
            hl = h[np.ix_(cols, cols)]
            hij = cho_solve(cho_factor(hl), jr.T)
            w = jr @ hij
            g = gap[mine]
            targets = np.where(g > 0, -g / dt, -self.settings.fall_correction * g / dt)
            p = pgs(w, jr @ v[cols], targets, self.settings.friction, self.settings.contact_iterations)
            v = v.copy()
            v[cols] += hij @ p
        return v

    def collider_at(self, col, t):
        pos = np.asarray(col.positions, float)
        vel = np.asarray(col.velocities, float)
        x = np.clip(t / self.dt_frame, 0.0, len(pos) - 1)
        f0 = min(int(np.floor(x)), len(pos) - 1)
        f1 = min(f0 + 1, len(pos) - 1)
        w = x - f0
        return (1 - w) * pos[f0] + w * pos[f1], (1 - w) * vel[f0] + w * vel[f1]




def point_segment(p, a, b):
    """Closest points on segments a-b to points p (broadcast (..., 3))."""
    e = b - a
    den = np.maximum(np.einsum("...i,...i->...", e, e), 1e-18)
    u = np.clip(np.einsum("...i,...i->...", p - a, e) / den, 0.0, 1.0)
    return a + u[..., None] * e


_SWEEP_ITERATIONS = 24  # golden-section and bisection steps of the first contact (2^-24 of a step)


def swept_contacts(a, b, rb, move, p0, p1, rc):
    """First contacts of collider spheres moving p0 -> p1 (c, 3) (radii rc (c,)) with capsules a-b
    (n, 3) (radii rb (n,)) moving by `move` (n, 3) over the step: a list of (capsule, sphere,
    closest axis point (3,), unit normal (3,) from the collider to the body) at the earliest instant
    each collider sphere touches (pairs touching within 5 % of a step of it included).

    The distance of a point moving on a line to a segment is convex in time: golden-section search
    finds its minimum, then bisection the first instant it comes within the radii."""
    if len(p0) == 0 or len(a) == 0:
        return []
    reach = rb.max() + rc.max()
    lo = np.minimum(np.minimum(a, b).min(axis=0), np.minimum(a + move, b + move).min(axis=0)) - reach
    hi = np.maximum(np.maximum(a, b).max(axis=0), np.maximum(a + move, b + move).max(axis=0)) + reach
    near = np.flatnonzero(np.all((np.maximum(p0, p1) >= lo) & (np.minimum(p0, p1) <= hi), axis=1))
    if not len(near):
        return []
    # relative motion: the capsule held still, the collider sphere moving by its path minus the capsule's
    start = p0[near][None, :, :] - np.zeros((len(a), 1, 3))  # (n, c, 3)
    path = (p1 - p0)[near][None, :, :] - move[:, None, :]
    aa, bb = a[:, None, :], b[:, None, :]
    limit = rb[:, None] + rc[near][None, :]

    def dist(s):
        x = start + s[..., None] * path
        return np.linalg.norm(x - point_segment(x, aa, bb), axis=-1)

    shape = limit.shape
    lo_s, hi_s = np.zeros(shape), np.ones(shape)
    g = 0.5 * (np.sqrt(5.0) - 1.0)
    for _ in range(_SWEEP_ITERATIONS):  # the closest approach over the step
        m1, m2 = hi_s - g * (hi_s - lo_s), lo_s + g * (hi_s - lo_s)
        left = dist(m1) < dist(m2)
        hi_s = np.where(left, m2, hi_s)
        lo_s = np.where(left, lo_s, m1)
    s_min = 0.5 * (lo_s + hi_s)
    d0, d_min, d1 = dist(np.zeros(shape)), dist(s_min), dist(np.ones(shape))
    touch = (d0 <= limit) | (d_min <= limit) | (d1 <= limit)
    if not touch.any():
        return []
    s_min = np.where(d1 <= d_min, 1.0, s_min)
    lo_s, hi_s = np.zeros(shape), s_min.copy()
    for _ in range(_SWEEP_ITERATIONS):  # the first instant within reach, between the start and the minimum
        mid = 0.5 * (lo_s + hi_s)
        inside_ = dist(mid) <= limit
        hi_s = np.where(inside_, mid, hi_s)
        lo_s = np.where(inside_, lo_s, mid)
    s_hit = np.where(d0 <= limit, 0.0, hi_s)
    s_hit = np.where(touch, s_hit, np.inf)
    out = []
    for c in range(len(near)):
        first = s_hit[:, c].min()
        if not np.isfinite(first):
            continue
        for cap in np.flatnonzero(s_hit[:, c] <= first + 0.05):
            x = start[cap, c] + s_hit[cap, c] * path[cap, c]
            axis_point = point_segment(x, a[cap], b[cap])
            n = axis_point - x
            size = np.linalg.norm(n)
            n = n / size if size > 1e-9 else path[cap, c] / max(np.linalg.norm(path[cap, c]), 1e-12)
            out.append((cap, near[c], axis_point, n))
    return out


def pgs(w, rel, targets, mu, iterations):
    """Projected Gauss-Seidel on contacts of three rows (normal, two tangents): normal impulses
    >= 0 that bring each normal speed up to its target (complementary), friction impulses within
    mu times the normal one that stop the sliding.

    The plain formula is textbook PGS row by row: u_r = rel_r + W_r p (the row's speed with every
    impulse so far), p_r += (target_r - u_r) / W_rr, projected (p_n >= 0, |p_t| <= mu p_n). Here,
    contact by contact, its three speeds come from the impulses at once (one 3 x 3c product) and
    its rows are updated on plain floats through its own 3 x 3 block: the same sweeps, saving
    28 % of Dynamic Control's time with contacts (a fallen body's ground contacts, up to 39 at a
    step; a fist: benchmarks/microopt.py, collisions_pgs_contact_blocks). The 3 x 3c product is
    its rows' bound `dot` (a third of `@`'s call overhead, the same BLAS product), the impulses are
    also kept as a list of floats beside the array (read without a numpy call) and written back
    element by element, and the projections are comparisons, not max/min calls (a knocked-over
    bake makes ~10^6 of them): the same floats as max(0, x) and min(max(x, -cap), cap), bit for
    bit (the fallen body is sensitive to its contacts' last bits: docs/physics.md)."""
    n = len(targets)
    p = np.zeros(3 * n)
    floats = [0.0] * (3 * n)  # p's values, read on plain floats
    # each contact's three speeds from the impulses: its rows' bound dot (a third of `@`'s call)
    row_dots = [w[3 * c:3 * c + 3].dot for c in range(n)]
    blocks = [w[3 * c:3 * c + 3, 3 * c:3 * c + 3].tolist() for c in range(n)]
    rel_rows = np.asarray(rel, float).reshape(n, 3).tolist()
    targets = np.asarray(targets, float).tolist()
    for _ in range(iterations):
        change = 0.0
        for c in range(n):
            i = 3 * c
            s0, s1, s2 = row_dots[c](p).tolist()
            r0, r1, r2 = rel_rows[c]
            u0, u1, u2 = r0 + s0, r1 + s1, r2 + s2
            pn, p1, p2 = floats[i:i + 3]
            moved = False
            (d0, _, _), (w10, d1, _), (w20, w21, d2) = blocks[c]
            new = pn + (targets[c] - u0) / d0
            new = new if new > 0.0 else 0.0  # max(0, new)
            dp = new - pn
            if dp:
                pn = new
                u1 += w10 * dp
                u2 += w20 * dp
                moved = True
                dp = abs(dp)
                change = dp if dp > change else change
            cap = mu * pn
            new = p1 - u1 / d1
            new = -cap if new < -cap else new  # min(max(new, -cap), cap)
            new = cap if new > cap else new
            dp = new - p1
            if dp:
                p1 = new
                u2 += w21 * dp
                moved = True
                dp = abs(dp)
                change = dp if dp > change else change
            new = p2 - u2 / d2
            new = -cap if new < -cap else new
            new = cap if new > cap else new
            dp = new - p2
            if dp:
                p2 = new
                moved = True
                dp = abs(dp)
                change = dp if dp > change else change
            if moved:
                floats[i:i + 3] = pn, p1, p2
                p[i] = pn  # element by element: half a slice assignment's time
                p[i + 1] = p1
                p[i + 2] = p2
        if change < 1e-7:
            break
    return p
