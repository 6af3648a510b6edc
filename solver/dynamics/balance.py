"""Balance: zero moment point, support polygon and minimum moment point (Oshita 2003, sec. 2.3.3
and eq. 2.11-2.12), on a horizontal ground at z = ground_height (Blender's Z up)."""

import math

import numpy as np

from . import spatial
from .inverse_dynamics import rnea
from .kinematics import body_accelerations, body_com


def zmp(model, data, q, v, a, f_ext=None, ground_height=0.0, gravity=None, exact=True):
    """Zero moment point (x, y) on the ground for the motion (q, v, a).

    exact=True: from the total rate of change of spatial momentum minus gravity and f_ext (the
    ground reaction wrench the motion needs, as RNEA's base wrench), segment rotations included.
    exact=False: Oshita's eq. 2.11-2.12 rewritten for Z up, treating each segment as a point mass
    at its centre of mass: x = sum m (x (z'' + g) - (z - h) x'') / sum m (z'' + g).
    """
    if exact:
        _, total = rnea(model, data, q, v, a, f_ext=f_ext, gravity=gravity, return_wrenches=True)
        n, f = total[0, :3], total[0, 3:]
        h = ground_height
        return np.array([(h * f[0] - n[1]) / f[2], (n[0] + h * f[1]) / f[2]])
    g = -(model.gravity if gravity is None else np.asarray(gravity, float))[2]
    c = body_com(model, data, q)
    vel, acc = body_accelerations(model, data, q, v, a)
    cdot = vel[:, 3:] + spatial.cross(vel[:, :3], c)
    cdd = acc[:, 3:] + spatial.cross(acc[:, :3], c) + spatial.cross(vel[:, :3], cdot)
    m = model.mass
    lift = m * (cdd[:, 2] + g)
    height = c[:, 2] - ground_height
    return np.array([(lift @ c[:, 0] - (m * height) @ cdd[:, 0]) / lift.sum(),
                     (lift @ c[:, 1] - (m * height) @ cdd[:, 1]) / lift.sum()])


def convex_hull(points):
    """Counter-clockwise convex hull (m, 2) of points (k, 2) by Andrew's monotone chain; collinear
    and duplicate points are dropped, so degenerate sets give 1 or 2 vertices."""
    # distinct points as (x, y) tuples, sorted by x then y
    pts = sorted(set(map(tuple, np.asarray(points, dtype=float).reshape(-1, 2).tolist())))
    if len(pts) <= 2:
        return np.array(pts, dtype=float).reshape(-1, 2)
    return np.array([pts[i] for i in monotone_chain(pts, range(len(pts)))])


def monotone_chain(points, order, tests=None):
    """Andrew's monotone chain: the counter-clockwise hull's indices into `points` (a list of
    (x, y), at least three) visited in `order` (their indices sorted by (x, y), no two points
    equal). With a `tests` list, every turn test it makes is appended as (o, a, b, outcome)."""
    def half(seq):
        out = []
        for p in seq:
            while len(out) >= 2:
                turned = _turn(points[out[-2]], points[out[-1]], points[p]) <= 1e-14
                if tests is not None:
                    tests.append((out[-2], out[-1], p, turned))
                if not turned:
                    break
                out.pop()
            out.append(p)
        return out

    order = list(order)
    lower, upper = half(order), half(order[::-1])
    return lower[:-1] + upper[:-1]


def _turn(o, a, b):
    return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])


def support_polygon(contact_points, ground_height=0.0, tolerance=0.01):
    """Convex hull (m, 2) of the contact points (k, 3, world) within `tolerance` of the ground:
    the feet's sole points and those of any other segment touching it (Oshita's support area)."""
    pts = np.asarray(contact_points, dtype=float).reshape(-1, 3)
    touching = pts[pts[:, 2] <= ground_height + tolerance]
    return convex_hull(touching[:, :2]) if len(touching) else np.zeros((0, 2))


def inside(polygon, point):
    """Whether a point (2,) lies in a counter-clockwise convex polygon (m, 2), boundary included."""
    polygon = np.asarray(polygon, float)
    if len(polygon) < 3:
        return len(polygon) > 0 and np.allclose(minimum_moment_point(polygon, point), point)
    px, py = np.asarray(point, float).ravel()[:2].tolist()
    return inside_xy(polygon.tolist(), px, py)


def inside_xy(pts, px, py):
    """inside() on plain floats: a counter-clockwise convex polygon as a list of at least three
    [x, y] vertices and the point's coordinates. The plain formula, on arrays: the point is left
    of every edge, all(cross(edge, point - edge start) >= 0); on floats it saves 5.7-7.5 % of a
    Dynamic Control bake with closest_boundary_xy (benchmarks/microopt.py, balance_zmp_mmp_floats)."""
    x0, y0 = pts[-1]
    for x1, y1 in pts:  # edge from the previous vertex: cross(edge, point - previous) >= 0
        if (x1 - x0) * (py - y0) - (y1 - y0) * (px - x0) < -1e-10:
            return False
        x0, y0 = x1, y1
    return True


def minimum_moment_point(polygon, zmp_point):
    """The point of the support polygon closest to the ZMP (the ZMP itself when inside): where the
    ground can take the body's moment best (Oshita's MMP)."""
    polygon = np.asarray(polygon, float).reshape(-1, 2)
    p = np.asarray(zmp_point, float)
    if len(polygon) == 0:
        raise ValueError("no support polygon: nothing touches the ground")
    if len(polygon) >= 3 and inside(polygon, p):
        return p.copy()
    return closest_boundary_point(polygon, p)


def closest_boundary_point(polygon, point):
    """The point of a polygon's boundary (m, 2) closest to a point (2,) (minimum_moment_point for
    a point known to lie outside, without testing it again)."""
    px, py = np.asarray(point, float).ravel()[:2].tolist()
    return np.array(closest_boundary_xy(np.asarray(polygon, float).reshape(-1, 2).tolist(), px, py))


def closest_boundary_xy(pts, px, py):
    """closest_boundary_point() on plain floats: the polygon as a list of [x, y] vertices, the
    point's coordinates; returns (x, y). The plain formula, on arrays: each edge's closest point
    a + clip((p - a).e / |e|^2, 0, 1) e, the nearest of them (on floats with inside_xy: 5.7-7.5 % of
    a Dynamic Control bake, benchmarks/microopt.py, balance_zmp_mmp_floats)."""
    # the closest point of each edge (vertex to next vertex; a single vertex is its own edge)
    best, out = None, None
    for (ax, ay), (bx, by) in zip(pts, pts[1:] + pts[:1]):
        ex, ey = bx - ax, by - ay
        length2 = ex * ex + ey * ey
        t = ((px - ax) * ex + (py - ay) * ey) / (length2 if length2 > 0 else 1.0)
        t = min(max(t, 0.0), 1.0)
        cx, cy = ax + t * ex, ay + t * ey
        dist = math.sqrt((cx - px) * (cx - px) + (cy - py) * (cy - py))
        if best is None or dist < best:
            best, out = dist, (cx, cy)
    return out
