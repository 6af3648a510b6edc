"""Primitives for grasping (Huang 1996 sec. 4.3.2): sphere, box, cylinder and frustum with signed
distances, and the fit of a mesh by principal axes and volume: the primitive whose volume is
closest to the mesh's own (over the ones that bound it) is the object's grasp shape."""

from dataclasses import dataclass

import numpy as np

from .sensors import Box, Sphere, length


@dataclass
class Cylinder:
    """Axis along the frame's local Z; `half` is half the height."""
    frame: np.ndarray
    radius: float
    half: float

    def distance(self, points):
        local = (np.asarray(points) - self.frame[:3, 3]) @ self.frame[:3, :3]
        radial = length(local[..., :2]) - self.radius
        axial = np.abs(local[..., 2]) - self.half
        out_r, out_a = np.maximum(radial, 0.0), np.maximum(axial, 0.0)
        return np.minimum(np.maximum(radial, axial), 0.0) + np.sqrt(out_r * out_r + out_a * out_a)

    def transformed(self, m):
        return Cylinder(m @ self.frame, self.radius, self.half)


@dataclass
class Frustum:
    """A truncated cone along local Z: radius r0 at z = -half, r1 at z = +half."""
    frame: np.ndarray
    r0: float
    r1: float
    half: float

    @property
    def radius(self):
        return 0.5 * (self.r0 + self.r1)

    def distance(self, points):
        # exact capped-cone distance (Quilez), in the (radial, axial) half plane, component-wise
        local = (np.asarray(points) - self.frame[:3, 3]) @ self.frame[:3, :3]
        radial, axial = length(local[..., :2]), local[..., 2]
        h, r1, r2 = self.half, self.r0, self.r1
        kx, ky = r2 - r1, 2.0 * h  # k2, the side from the bottom rim to the top one
        # to the nearer cap's disc, and to the side
        ca_r = radial - np.minimum(radial, np.where(axial < 0, r1, r2))
        ca_a = np.abs(axial) - h
        t = np.clip(((r2 - radial) * kx + (h - axial) * ky) / (kx * kx + ky * ky), 0.0, 1.0)
        cb_r = radial - r2 + t * kx
        cb_a = axial - h + t * ky
        dist = np.sqrt(np.minimum(ca_r * ca_r + ca_a * ca_a, cb_r * cb_r + cb_a * cb_a))
        return np.where((cb_r < 0) & (ca_a < 0), -dist, dist)

    def transformed(self, m):
        return Frustum(m @ self.frame, self.r0, self.r1, self.half)


def shape_frame(shape):
    if hasattr(shape, "frame"):
        return np.asarray(shape.frame, float)
    m = np.eye(4)
    m[:3, 3] = shape.centre
    return m


def dimensions(shape):
    """Full extents (3,) along the shape's local axes."""
    if isinstance(shape, Sphere):
        return np.full(3, 2 * shape.radius)
    if isinstance(shape, Box):
        return 2 * np.asarray(shape.half)
    if isinstance(shape, Cylinder):
        return np.array([2 * shape.radius, 2 * shape.radius, 2 * shape.half])
    r = max(shape.r0, shape.r1)
    return np.array([2 * r, 2 * r, 2 * shape.half])


def kind(shape):
    return {Sphere: "SPHERE", Box: "BOX", Cylinder: "CYLINDER", Frustum: "FRUSTUM"}[type(shape)]


def mesh_volume(vertices, triangles):
    v = np.asarray(vertices, float)[np.asarray(triangles, int)]
    return abs(float(np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2])).sum()) / 6.0)


def principal_frame(vertices, triangles):
    """Centre of the surface and principal axes (area weighted), right handed."""
    v = np.asarray(vertices, float)
    tri = v[np.asarray(triangles, int)]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    cent = tri.mean(axis=1)
    w = area / area.sum()
    c = w @ cent
    d = cent - c
    spread = sum((tri[:, k] - cent).T @ ((tri[:, k] - cent) * w[:, None]) for k in range(3)) / 12.0
    cov = (d * w[:, None]).T @ d + spread
    _, vecs = np.linalg.eigh(cov)
    axes = vecs[:, ::-1]
    if np.linalg.det(axes) < 0:
        axes[:, 2] *= -1
    f = np.eye(4)
    f[:3, :3] = axes
    f[:3, 3] = c
    return f


def fit_primitive(vertices, triangles):
    """The object's grasp primitive: for each candidate (sphere, box, cylinder along each
    principal axis, frustum along each principal axis) the bounding one fitted on the principal
    axes; the one whose volume is closest to the mesh's volume wins."""
    v = np.asarray(vertices, float)
    frame = principal_frame(v, triangles)
    local = (v - frame[:3, 3]) @ frame[:3, :3]
    mid = 0.5 * (local.max(0) + local.min(0))
    frame[:3, 3] = frame[:3, :3] @ mid + frame[:3, 3]
    local = local - mid
    volume = mesh_volume(v, triangles)
    half = np.abs(local).max(0)
    cands = [Sphere(frame[:3, 3].copy(), float(np.linalg.norm(local, axis=1).max())),
             Box(frame.copy(), half)]
    for ax in range(3):
        perm = [(ax + 1) % 3, (ax + 2) % 3, ax]
        f = frame.copy()
        f[:3, :3] = frame[:3, :3][:, perm]
        lz = local[:, perm]
        radial = np.linalg.norm(lz[:, :2], axis=1)
        h = float(np.abs(lz[:, 2]).max())
        cands.append(Cylinder(f, float(radial.max()), h))
        # frustum: radius at each end from the extreme slices, then grown to bound every vertex
        t = (lz[:, 2] + h) / (2 * h) if h > 0 else np.zeros(len(lz))
        a = np.vstack((1 - t, t)).T
        r0, r1 = np.linalg.lstsq(a, radial, rcond=None)[0]
        grow = float(np.max(radial - (a @ [r0, r1])))
        r0, r1 = max(r0 + grow, 0.0), max(r1 + grow, 0.0)
        cands.append(Frustum(f, float(r0), float(r1), h))
    vols = [prim_volume(c) for c in cands]
    # prefer the simpler shape unless a later one fits clearly better (numbers within 3 %)
    best = min(range(len(cands)), key=lambda i: (abs(vols[i] - volume) / max(volume, 1e-12), i))
    scores = [abs(x - volume) / max(volume, 1e-12) for x in vols]
    for i in range(len(cands)):
        if scores[i] <= scores[best] + 0.03:
            best = i
            break
    return cands[best]


def prim_volume(s):
    if isinstance(s, Sphere):
        return 4.0 / 3.0 * np.pi * s.radius ** 3
    if isinstance(s, Box):
        return float(np.prod(2 * np.asarray(s.half)))
    if isinstance(s, Cylinder):
        return np.pi * s.radius ** 2 * 2 * s.half
    return np.pi * 2 * s.half / 3.0 * (s.r0 ** 2 + s.r0 * s.r1 + s.r1 ** 2)


def mesh_of(shape, segments=32):
    """Vertices and triangles of a primitive (tests, previews)."""
    f = shape_frame(shape)
    if isinstance(shape, Sphere):
        u, v = np.meshgrid(np.linspace(0, np.pi, segments // 2 + 1)[1:-1], np.linspace(0, 2 * np.pi, segments + 1)[:-1])
        pts = np.stack((np.sin(u) * np.cos(v), np.sin(u) * np.sin(v), np.cos(u)), -1).reshape(-1, 3)
        pts = np.vstack((pts, [[0, 0, 1], [0, 0, -1]])) * shape.radius
        from scipy.spatial import ConvexHull
        hull = ConvexHull(pts)
        return pts + shape.centre, _outward(pts, hull.simplices)
    if isinstance(shape, Box):
        c = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float) * shape.half
    else:
        r0, r1 = (shape.radius, shape.radius) if isinstance(shape, Cylinder) else (shape.r0, shape.r1)
        a = np.linspace(0, 2 * np.pi, segments + 1)[:-1]
        ring = np.stack((np.cos(a), np.sin(a)), -1)
        c = np.vstack((np.column_stack((ring * r0, np.full(segments, -shape.half))),
                       np.column_stack((ring * r1, np.full(segments, shape.half)))))
    from scipy.spatial import ConvexHull
    hull = ConvexHull(c)
    tri = _outward(c, hull.simplices)
    return c @ f[:3, :3].T + f[:3, 3], tri


def _outward(pts, tri):
    tri = np.array(tri)
    c = pts.mean(0)
    n = np.cross(pts[tri[:, 1]] - pts[tri[:, 0]], pts[tri[:, 2]] - pts[tri[:, 0]])
    flip = np.einsum("ij,ij->i", n, pts[tri[:, 0]] - c) < 0
    tri[flip] = tri[flip][:, ::-1]
    return tri
