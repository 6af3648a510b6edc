"""Generalised forces (thesis §4.6, §4.7, §4.9): gravity, springs, per-mode stiffness and
damping, and the ground as a penalty spring-damper with separate normal and friction damping
and a Coulomb cap |f_t| <= mu |f_n|, on planes of any slope."""

from dataclasses import dataclass, field

import numpy as np

GRAVITY = np.array([0.0, 0.0, -9.81])


@dataclass
class Plane:
    """A ground plane through `point` with upward `normal`; with `region_direction` it only
    exists where (x - region_point) . region_direction <= 0 (e.g. the top of a ledge), and a
    finite `thickness` makes it a slab, so a point that falls past its edge and is deep below
    it is not pushed back up through it."""
    point: tuple = (0.0, 0.0, 0.0)
    normal: tuple = (0.0, 0.0, 1.0)
    region_point: tuple = None
    region_direction: tuple = None
    thickness: float = float("inf")    # deeper points are beside the plane, not in it (a ledge's side)

    def __post_init__(self):
        self.point = np.asarray(self.point, float)
        n = np.asarray(self.normal, float)
        self.normal = n / np.linalg.norm(n)
        if self.region_direction is not None:
            self.region_point = np.asarray(self.region_point if self.region_point is not None else self.point, float)
            self.region_direction = np.asarray(self.region_direction, float)


@dataclass
class Ground:
    """Penalty ground. Stiffness and damping are per kilogram of the body, spread evenly over its
    colliding points, so the same settings hold a 1 kg pot and a 50 kg table alike (the thesis's
    grconst, grdam and frconst are per point)."""
    planes: list = field(default_factory=lambda: [Plane()])
    stiffness: float = 6000.0          # N/m per kg
    normal_damping: float = 80.0       # N s/m per kg
    friction_damping: float = 80.0     # N s/m per kg
    friction: float = 0.8              # Coulomb mu

    @classmethod
    def flat(cls, height=0.0, **kw):
        return cls(planes=[Plane((0, 0, height))], **kw)

    @classmethod
    def slope(cls, angle, axis=(1.0, 0.0, 0.0), **kw):
        """A plane through the origin rising along `axis` by `angle` radians."""
        axis = np.asarray(axis, float) / np.linalg.norm(axis)
        normal = np.array([-axis[0] * np.sin(angle), -axis[1] * np.sin(angle), np.cos(angle)])
        return cls(planes=[Plane((0, 0, 0), normal)], **kw)

    @classmethod
    def ledge(cls, height, edge, axis=(1.0, 0.0, 0.0), **kw):
        """Upper ground at `height` up to `edge` along `axis`, lower ground at 0 everywhere."""
        axis = np.asarray(axis, float)
        point = np.array([0.0, 0.0, height]) + edge * axis
        top = Plane((0, 0, height), (0, 0, 1), point, axis, thickness=min(0.1, 0.5 * height))
        return cls(planes=[top, Plane((0, 0, 0))], **kw)

    def per_point(self, body):
        n = max(int(np.count_nonzero(body.collides)), 1)
        scale = body.total_mass / n
        return self.stiffness * scale, self.normal_damping * scale, self.friction_damping * scale


@dataclass
class Spring:
    """A spring from a body point (lattice parameters uvw) to a world anchor: a point, or a
    function of time giving it (an animated object); damping acts on the point's velocity."""
    uvw: tuple
    anchor: tuple
    stiffness: float = 500.0
    damping: float = 10.0
    rest_length: float = 0.0
    anchor_object: str = ""


@dataclass
class ModeGains:
    """Per-mode potential V = 1/2 k gamma^2 and damping -c gamma_dot (thesis §4.7)."""
    stiffness: np.ndarray
    damping: np.ndarray

    @classmethod
    def from_frequency(cls, body, hertz, damping_ratio):
        """Gains that give each mode, alone at rest, the natural frequency `hertz` (Hz) and
        `damping_ratio` against its own modal mass."""
        m = body.modal_masses()
        w = 2 * np.pi * np.broadcast_to(np.asarray(hertz, float), m.shape)
        z = np.broadcast_to(np.asarray(damping_ratio, float), m.shape)
        return cls(m * w ** 2, 2 * z * w * m)


class Contacts:
    """Anchored penalty contacts: when a point enters the ground a spring-damper is attached
    between the point of entry and the point (Fig. 4.5); the anchor slides when the friction
    force would exceed the Coulomb cap."""

    def __init__(self, body, ground):
        self.ground = ground
        self.k, self.cn, self.ct = ground.per_point(body)
        self.mu = ground.friction
        self.collides = np.asarray(body.collides, bool)   # spring points ride along, not colliding
        P = len(self.collides)
        self.anchor = np.zeros((P, 3))
        self.anchored = np.zeros(P, bool)
        planes = ground.planes
        self.normals = np.array([p.normal for p in planes])                 # (L, 3)
        self.offsets = np.array([p.point @ p.normal for p in planes])       # (L,)
        bounded = [p for p in planes if p.region_direction is not None]
        self.bounded = bool(bounded)
        self.region_dirs = np.array([p.region_direction if p.region_direction is not None else np.zeros(3)
                                     for p in planes])
        self.region_offsets = np.array([p.region_point @ p.region_direction if p.region_direction is not None
                                        else 1.0 for p in planes])
        self.thickness = np.array([p.thickness for p in planes])
        self.single = len(planes) == 1 and not np.isfinite(self.thickness[0])
        self.all_collide = bool(self.collides.all())

    def reset(self):
        self.anchored[:] = False

    def forces(self, x, vel_fn):
        """Contact forces on the points x (P, 3). vel_fn(idx) gives world velocities of points
        idx. Returns None, or (idx, normals, sliding, forces) of the touching points (normals
        (3,) when there is one plane, else (c, 3); world forces (c, 3))."""
        if self.single:
            n = self.normals[0]
            s_all = x @ n - self.offsets[0]
            touch = s_all < 0
            if not self.all_collide:
                touch &= self.collides
        else:
            # the deepest plane a point is under, among the planes that exist where it is
            s_all = x @ self.normals.T - self.offsets
            if self.bounded:
                s_all[x @ self.region_dirs.T > self.region_offsets] = np.inf
            s_all[s_all < -self.thickness] = np.inf
            which = s_all.argmin(axis=1)
            s_all = s_all[np.arange(len(x)), which]
            touch = (s_all < 0) & self.collides
        idx = touch.nonzero()[0]
        if not idx.size:
            self.anchored[:] = False
            return None
        if self.single:
            new = touch & ~self.anchored
            if new.any():  # the point of entry: where it crossed the plane
                self.anchor[new] = x[new] - s_all[new, None] * n
        else:
            n = self.normals[which[idx]]
            new = touch & ~self.anchored
            if new.any():
                self.anchor[new] = x[new] - s_all[new, None] * self.normals[which[new]]
            # an anchor left on another plane: onto this one
            a = self.anchor[idx]
            a -= (((a - x[idx]) * n).sum(axis=1) + s_all[idx])[:, None] * n
            self.anchor[idx] = a
        self.anchored = touch
        # the spring from the anchor (on the plane) is -k (x - anchor): its normal part is the
        # penetration, its tangential part the stretch since the point of entry
        v = vel_fn(idx)
        f = -self.k * (x[idx] - self.anchor[idx]) - self.ct * v
        vn = v @ n if n.ndim == 1 else (v * n).sum(axis=1)
        f -= ((self.cn - self.ct) * vn)[:, None] * n
        fn = f @ n if n.ndim == 1 else (f * n).sum(axis=1)
        ft = f - fn[:, None] * n
        np.maximum(fn, 0.0, out=fn)                 # the ground only pushes
        cap = self.mu * fn
        sliding = (ft * ft).sum(axis=1) > cap * cap
        if sliding.any():
            ftn = np.sqrt((ft[sliding] ** 2).sum(axis=1))
            ft[sliding] *= (cap[sliding] / np.maximum(ftn, 1e-300))[:, None]
            # slide the anchor so the spring alone gives the capped force next time
            vt = v[sliding] - (vn[sliding, None] * n if n.ndim == 1 else vn[sliding, None] * n[sliding])
            nn = n if n.ndim == 1 else n[sliding]
            proj = x[idx[sliding]] - s_all[idx[sliding], None] * nn
            self.anchor[idx[sliding]] = proj + (ft[sliding] + self.ct * vt) / self.k
        return idx, n, sliding, fn[:, None] * n + ft
