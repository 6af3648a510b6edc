"""Cloth against the moving body (Oshita 2003 §4.4.4).

A body is a signed distance to its surface (negative inside) with an outward direction and the
surface's velocity, queried at a time s in [0, 1] within the current frame (the body moves
linearly from its pose at the frame's start to its pose at the frame's end):

- CapsuleBody: capsules fitted to bones. Queries are dense (points x capsules) in numpy, which
  for a body's 10-20 capsules is faster than any tree.
- MeshBody: the character's skinned triangle mesh. Per closed part of the mesh (one for a
  single skin, one per limb for a body made of pieces), a scipy cKDTree over the triangle
  centroids, built once per substep at the body's pose then, gives each point near the part's
  bounding box its K nearest triangles within reach; exact point-triangle distances follow,
  vectorised, and the side from the (pseudo-)normal at the nearest point. The body is the union
  of its parts (the smallest signed distance).

`resolve_contacts` applies the thesis's two cases: a particle inside (or closer than the
thickness) is moved to the surface; a face whose corners are outside but whose interior cuts
the body is moved out whole, by its deepest point. Contacting particles keep only the
tangential part of their velocity relative to the body.
"""

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ..vectors import cross
from .fast import Product, dot, rowdot


def closest_on_segments(p, a, b):
    """Closest points on segments ab to points p (broadcasting): (q, t)."""
    ab = b - a
    denom = np.maximum(np.einsum("...i,...i->...", ab, ab), 1e-18)
    t = np.clip(np.einsum("...i,...i->...", p - a, ab) / denom, 0.0, 1.0)
    return a + t[..., None] * ab, t


BROAD_PHASE_FROM = 256  # points in a capsule query from which far capsules are skipped first


class CapsuleBody:
    """Capsules: segments a-b with radii, moving linearly within a frame."""

    # without max_distance, queries report exact distances up to this far (the collision's
    # 1-Lipschitz bounds cull faces and fine vertices farther out than an edge: capsule
    # distances are as cheap far as near)
    REACH = 0.15

    def __init__(self, radius, names=None):
        self.radius = np.asarray(radius, float)
        self.names = list(names) if names is not None else [str(i) for i in range(len(self.radius))]
        self.a0 = self.b0 = self.a1 = self.b1 = None
        self.dt = 1.0
        self._at = {}

    def set_motion(self, a0, b0, a1=None, b1=None, dt=1.0):
        self.a0, self.b0 = np.asarray(a0, float), np.asarray(b0, float)
        self.a1 = self.a0 if a1 is None else np.asarray(a1, float)
        self.b1 = self.b0 if b1 is None else np.asarray(b1, float)
        self.dt = dt
        self.motions = getattr(self, "motions", 0) + 1  # tells cached queries from a past frame
        va, vb = (self.a1 - self.a0) / self.dt, (self.b1 - self.b0) / self.dt
        self._velocity = va, vb - va
        self._at = {}

    def _pose(self, s):
        """What the queries at time s share (a frame's queries come at a few times only), packed
        in one array per capsule so a query takes the nearest capsule's data in one call:
        columns a (3), velocity of a (3), ab (3), velocity of b minus a's (3), radius (so [a |
        va] + t [ab | dv] is the closest point and its velocity in one product); the capsules'
        boxes (lo | hi, (C, 6)); [2 ab | -2 a] (3, 2C) and [-2 a.ab | a.a] (2C,) for one product
        and one sum giving [2 (p - a).ab | |p - a|^2 - |p|^2]; and the rows 1 / (2 |ab|^2),
        |ab|^2, radius (3, C)."""
        pose = self._at.get(s)
        if pose is None:
            a = self.a0 + s * (self.a1 - self.a0)
            b = self.b0 + s * (self.b1 - self.b0)
            ab = b - a
            r = self.radius[:, None]
            va, dv = self._velocity
            ab2 = np.maximum(rowdot(ab, ab), 1e-18)
            packed = np.column_stack([a, va, ab, dv, self.radius])
            axes = np.concatenate((2.0 * ab, -2.0 * a)).T.copy()
            bias = np.concatenate((-2.0 * rowdot(a, ab), rowdot(a, a)))
            rows = np.array([0.5 / ab2, ab2, self.radius])
            pose = (packed, np.minimum(a, b) - r, np.maximum(a, b) + r, axes, bias, rows)
            if len(self._at) > 8:
                self._at.clear()
            self._at[s] = pose
        return pose

    def query(self, points, s=1.0, max_distance=None, second=False):
        """(phi (N,), outward unit normal (N, 3), surface velocity (N, 3)). Only capsules whose
        box comes within max_distance (default REACH) of the points' box are tested; points
        beyond them all report phi = max_distance (a lower bound). All points against all
        capsules in one broadcast. With `second`, also a lower bound of each point's distance
        to the other capsules (the second smallest phi)."""
        md = self.REACH if max_distance is None else max_distance
        packed, box_lo, box_hi, axes, bias, rows = self._pose(s)
        n = len(points)
        c = len(packed)
        if n > BROAD_PHASE_FROM:  # a few points: testing every capsule costs less than choosing
            lo, hi = points.min(axis=0), points.max(axis=0)
            lo -= md
            hi += md
            near = np.flatnonzero(np.logical_and.reduce((box_lo <= hi) & (box_hi >= lo), axis=1))
            c = len(near)
        if c == 0:
            normal = np.zeros((n, 3))
            normal[:, 2] = 1.0
            out = np.full(n, float(md)), normal, np.zeros((n, 3))
            return out + (np.full(n, float(md)),) if second else out
        if c < len(packed):
            packed, rows = packed.take(near, axis=0), rows.take(near, axis=1)
            both = np.concatenate((near, near + len(box_lo)))
            axes, bias = axes.take(both, axis=1), bias.take(both)
        # distances to all segments from (N, C) products: with s = (p - a).ab and t = s / |ab|^2
        # clipped to [0, 1], |p - a - t ab|^2 = |p - a|^2 + t (t |ab|^2 - 2 s)
        prod = points @ axes
        prod += bias  # [2 s | |p - a|^2 - |p|^2]
        two_s = prod[:, :c]
        t = two_s * rows[0]
        np.clip(t, 0.0, 1.0, out=t)
        w = t * rows[1]
        w -= two_s
        w *= t
        dist = prod[:, c:]
        dist += w
        dist += rowdot(points, points)[:, None]
        np.maximum(dist, 0.0, out=dist)
        np.sqrt(dist, out=dist)  # to the axes
        gap = dist - rows[2]  # to the surfaces
        k = gap.argmin(axis=1)
        flat = k + _row_starts(n, c)
        phi = gap.take(flat)
        if second:  # (the expanded form's rounding is far below a micrometre)
            if c > 1:
                gap.put(flat, np.inf)
                other = gap.min(axis=1)
                other -= 1e-6
                np.minimum(other, md, out=other)
            else:
                other = np.full(n, float(md))
        # the nearest axis point and its velocity: [a | va] + t [ab | dv] of the nearest capsule
        pk = packed.take(k, axis=0)
        near_point = pk[:, 6:12] * t.take(flat)[:, None]
        near_point += pk[:, 0:6]
        normal = points - near_point[:, :3]
        axis_distance = dist.take(flat)
        if axis_distance.min() > 1e-4:  # (the expanded distance is exact to ~1e-12 relative here)
            normal /= axis_distance[:, None]
        else:  # near the axis, the direct length; a point on the axis: any direction across it
            axis_distance = np.sqrt(rowdot(normal, normal))
            normal /= np.maximum(axis_distance, 1e-12)[:, None]
            on_axis = axis_distance <= 1e-9
            across = np.cross(pk[on_axis, 6:9], [0.0, 0.0, 1.0])
            across[np.linalg.norm(across, axis=1) < 1e-9] = (1.0, 0.0, 0.0)
            normal[on_axis] = across / np.linalg.norm(across, axis=1)[:, None]
        np.minimum(phi, md, out=phi)
        velocity = near_point[:, 3:]
        return (phi, normal, velocity, other) if second else (phi, normal, velocity)


_STARTS = {}


def _row_starts(n, c):
    """c * arange(n): the flat index of each row's first entry in an (n, c) array (cached)."""
    key = (n, c)
    out = _STARTS.get(key)
    if out is None:
        if len(_STARTS) > 256:
            _STARTS.clear()
        out = _STARTS[key] = c * np.arange(n)
    return out


def closest_on_triangles(p, a, b, c):
    """Closest points on triangles abc to points p (all (..., 3)): (q, barycentric (..., 3))."""
    ab, ac = b - a, c - a
    n = cross(ab, ac)
    nn = np.maximum(dot(n, n), 1e-30)
    ap = p - a
    beta = dot(cross(ap, ac), n) / nn
    gamma = dot(cross(ab, ap), n) / nn
    alpha = 1.0 - beta - gamma
    inside = (alpha >= 0.0) & (beta >= 0.0) & (gamma >= 0.0)
    q = a + beta[..., None] * ab + gamma[..., None] * ac
    bary = np.stack([alpha, beta, gamma], axis=-1)
    if inside.all():
        return q, bary
    best = np.where(inside, 0.0, np.inf)
    for start, end, i, j in ((a, b, 0, 1), (b, c, 1, 2), (c, a, 2, 0)):
        qe, t = closest_on_segments(p, start, end)
        pe = p - qe
        de = dot(pe, pe)
        take = ~inside & (de < best)
        best = np.where(take, de, best)
        q = np.where(take[..., None], qe, q)
        be = np.zeros(bary.shape)
        be[..., i], be[..., j] = 1.0 - t, t
        bary = np.where(take[..., None], be, bary)
    return q, bary


PART_GAP = 1.0e4  # metres between the parts' lifted copies in the joint tree (beyond any reach)
TREE_MARGIN = 0.1  # metres added around the first query's need when a pose's joint tree is built


class MeshBody:
    """A skinned triangle mesh (one or several closed parts), moving linearly within a frame."""

    def __init__(self, triangles, vertex_count, neighbours=8):
        self.triangles = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
        self.k = neighbours
        t = self.triangles
        rows = np.repeat(t[:, 0], 2)
        cols = t[:, 1:].ravel()
        graph = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(vertex_count, vertex_count))
        _, label = connected_components(graph, directed=False)
        part = label[t[:, 0]]
        self.parts = [np.flatnonzero(part == p) for p in np.unique(part)]
        self.part_vertices = [np.unique(t[p]) for p in self.parts]
        # the parts' vertices back to back, for their bounding boxes in two reductions
        self._part_verts = np.concatenate(self.part_vertices)
        self._part_starts = np.cumsum([0] + [len(v) for v in self.part_vertices[:-1]])
        self._part_of = np.empty(len(t), dtype=np.int64)
        for i, tris in enumerate(self.parts):
            self._part_of[tris] = i
        self._tri_order = np.concatenate(self.parts)  # triangles part by part
        self._tri_starts = np.cumsum([0] + [len(p) for p in self.parts[:-1]])
        self.v0 = self.v1 = None
        self._pose = None

    def set_motion(self, v0, v1=None, dt=1.0):
        """The pose at the frame's start and end."""
        self.v0 = np.asarray(v0, float)
        self.v1 = self.v0 if v1 is None else np.asarray(v1, float)
        self.dt = dt
        self.motions = getattr(self, "motions", 0) + 1  # tells cached queries from a past frame
        self._pose = None

    def pose_at(self, s):
        """The body at time s: vertices, unit face normals, per-part bounding boxes (P, 3) and
        the tree of the parts queried so far (built when a query first comes near a part: the
        body moves several centimetres within a frame, so trees are per substep)."""
        if self._pose is not None and self._pose["s"] == s:
            return self._pose
        v = self.v0 + s * (self.v1 - self.v0)
        tri = v[self.triangles]
        fn = cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        fn /= np.maximum(np.sqrt(dot(fn, fn)), 1e-18)[:, None]
        pv = v[self._part_verts]
        lo = np.minimum.reduceat(pv, self._part_starts, axis=0)
        hi = np.maximum.reduceat(pv, self._part_starts, axis=0)
        self._pose = {"s": s, "v": v, "tri": tri, "fn": fn, "lo": lo, "hi": hi, "tree": None, "centroids": None}
        return self._pose

    def _reach(self, pose):
        """Per part, how far from its centroid a triangle can hold the closest point (the
        largest over the part's triangles); the centroids too. Once per pose."""
        if pose["centroids"] is None:
            tri = pose["tri"]
            centroids = tri.mean(axis=1)
            spread = np.sqrt(((tri - centroids[:, None]) ** 2).sum(axis=2).max(axis=1))
            pose["centroids"] = centroids
            pose["reach"] = np.maximum.reduceat(spread[self._tri_order], self._tri_starts)
        return pose["reach"]

    def _joint_tree(self, pose, need_lo, need_hi):
        """A cKDTree over the centroids of the triangles (of all parts) in a box holding
        [need_lo, need_hi], each part lifted to its own height PART_GAP apart along a 4th axis:
        a query from a point lifted to part i's height finds part i's triangles only, so one
        query over (point, part) pairs gives what a tree per part gave, in one call. The tree
        is kept for the pose while later queries need no more than its box (it gets TREE_MARGIN
        around the first query's need: face samples and the fine surface stay near the
        particles). Returns (tree, global triangle id of each tree slot)."""
        old = pose["tree"]
        if old is not None and (need_lo >= old[2]).all() and (need_hi <= old[3]).all():
            return old[0], old[1]
        box_lo, box_hi = need_lo - TREE_MARGIN, need_hi + TREE_MARGIN
        if old is not None:
            box_lo, box_hi = np.minimum(box_lo, old[2]), np.maximum(box_hi, old[3])
        c = pose["centroids"]
        ids = np.flatnonzero(np.all((c >= box_lo) & (c <= box_hi), axis=1))
        lifted = np.column_stack([c[ids], PART_GAP * self._part_of[ids]])
        pose["tree"] = (cKDTree(lifted), ids, box_lo, box_hi)
        return pose["tree"][0], ids

    def _candidates(self, pose, points, max_distance):
        """Broad phase: per part near the points (box test, all parts at once), the K nearest
        triangles of that part within reach (one joint-tree query for all point-part pairs).
        (rows (M,), global triangle ids (M, K), valid (M, K)), rows grouped by part in part
        order, as a query per part would give them."""
        md = max_distance
        near = np.all((points[:, None, :] >= pose["lo"] - md) & (points[:, None, :] <= pose["hi"] + md), axis=2)
        wanted = near.any(axis=0)
        if not wanted.any():
            return None
        reach = self._reach(pose)
        bound = md + reach[wanted].max()
        # every centroid within `bound` of a point is in the tree's box
        tree, ids = self._joint_tree(pose, points.min(axis=0) - bound, points.max(axis=0) + bound)
        part, rows = np.nonzero(near.T)  # part-major: as the per-part loop concatenated them
        k = self.k
        query = np.column_stack([points[rows], PART_GAP * part])
        dist, idx = tree.query(query, k=k, distance_upper_bound=bound)
        dist, idx = dist.reshape(len(rows), k), idx.reshape(len(rows), k)
        # a tree per part was queried within that part's own reach: the nearest within the
        # largest reach that are also within the part's are exactly those (a prefix)
        valid = dist < (md + reach[part])[:, None]
        found = valid[:, 0]
        if not found.any():
            return None
        idx, valid = idx[found], valid[found]
        return rows[found], ids[np.where(valid, idx, 0)], valid

    def query(self, points, s=1.0, max_distance=0.05):
        """As CapsuleBody.query; points with no triangle within max_distance report phi =
        max_distance (a lower bound of their distance, enough to know they are outside). The
        candidates of every part near a point are evaluated in one batch; the point's phi is
        the smallest signed distance over the parts (the union)."""
        points = np.asarray(points, float)
        n = len(points)
        phi = np.full(n, float(max_distance))
        normal = np.zeros((n, 3))
        normal[:, 2] = 1.0
        velocity = np.zeros((n, 3))
        if n == 0:
            return phi, normal, velocity
        pose = self.pose_at(s)
        cand = self._candidates(pose, points, max_distance)
        if cand is None:
            return phi, normal, velocity
        rows, ids, valid = cand
        tri = pose["tri"][ids]  # (M, K, 3, 3)
        p = points[rows][:, None, :]
        q, bary = closest_on_triangles(p, tri[:, :, 0], tri[:, :, 1], tri[:, :, 2])
        d = p - q
        dist = np.where(valid, np.sqrt(dot(d, d)), np.inf)
        fn = pose["fn"][ids]
        nearest = np.argmin(dist, axis=1)
        r = np.arange(len(rows))
        best = dist[r, nearest]
        # pseudo-normal: the normals of all candidates (of this part) sharing the nearest point
        # (an edge or a vertex), so the side is right where faces meet
        tie = valid & (dist <= best[:, None] + 1e-7 + 1e-4 * best[:, None])
        pseudo = np.einsum("ij,ijk->ik", tie.astype(float), fn)
        dk = d[r, nearest]
        sign = np.where(dot(dk, pseudo) < 0.0, -1.0, 1.0)
        signed = sign * best
        # the smallest signed distance per point over its parts, if below max_distance
        order = np.lexsort((signed, rows))
        first = np.r_[True, rows[order][1:] != rows[order][:-1]]
        pick = order[first]
        pick = pick[signed[pick] < max_distance]
        if len(pick) == 0:
            return phi, normal, velocity
        out = rows[pick]
        b = best[pick]
        phi[out] = signed[pick]
        pk = pseudo[pick] / np.maximum(np.sqrt(dot(pseudo[pick], pseudo[pick])), 1e-18)[:, None]
        far = b[:, None] > 1e-9
        normal[out] = np.where(far, sign[pick][:, None] * dk[pick] / np.maximum(b, 1e-12)[:, None], pk)
        vel = (self.v1 - self.v0) / self.dt
        corners = self.triangles[ids[pick, nearest[pick]]]  # (m, 3)
        velocity[out] = np.einsum("ij,ijk->ik", bary[pick, nearest[pick]], vel[corners])
        return phi, normal, velocity


def query_bodies(bodies, points, s):
    """The union of several bodies: the smallest phi wins."""
    if len(bodies) == 1:
        return bodies[0].query(points, s)
    phi = np.full(len(points), np.inf)
    normal = np.zeros((len(points), 3))
    velocity = np.zeros((len(points), 3))
    for body in bodies:
        ph, n, v = body.query(points, s)
        take = ph < phi
        phi = np.where(take, ph, phi)
        normal[take], velocity[take] = n[take], v[take]
    return phi, normal, velocity


# points inside each face tested for the face-intersection case: centroid, edge midpoints, and
# points between the centroid and the corners (barycentric weights)
FACE_SAMPLES = np.array([
    [1 / 3, 1 / 3, 1 / 3],
    [0.5, 0.5, 0.0], [0.0, 0.5, 0.5], [0.5, 0.0, 0.5],
    [2 / 3, 1 / 6, 1 / 6], [1 / 6, 2 / 3, 1 / 6], [1 / 6, 1 / 6, 2 / 3],
])


def _keep_tangential(v, hit, normal, surface_velocity, friction):
    vh = v[hit]
    rel = vh - surface_velocity
    rel_n = rowdot(rel, normal)[:, None] * normal
    if friction == 0.0:  # (the same, without the tangential part's round trip)
        vh -= rel_n
        v[hit] = vh
    else:
        v[hit] = surface_velocity + (1.0 - friction) * (rel - rel_n)


def resolve_particles(x, v, bodies, s, thickness, movable, friction=0.0, passes=4, rows=None, phi=None):
    """Vertex case (Fig. 4.6 a, c): particles inside the body (or within the thickness) move to
    the surface; returns the number moved and every particle's phi at its final position. A
    particle pushed out of one part of the body into an overlapping part is pushed again (up to
    `passes` times). With `rows` (and `phi`, known for the others), only those particles are
    queried: the others have not moved since their phi was found.

    Against capsules alone, a point pushed along its nearest capsule's normal stays at the
    thickness from it, and the other capsules can come no closer than their distance before
    minus the push (phi is 1-Lipschitz): only points that can land in another capsule are
    queried again."""
    capsules = len(bodies) == 1 and isinstance(bodies[0], CapsuleBody)

    def ask(points):
        if capsules:
            return bodies[0].query(points, s, second=True)
        return query_bodies(bodies, points, s) + (None,)

    if rows is None:
        phi, normal, vs, other = ask(x)
        rows = np.flatnonzero((phi < thickness) & movable)
        ph, n, vel = phi[rows], normal[rows], vs[rows]
        other = None if other is None else other[rows]
    else:
        ph, n, vel, other = ask(x[rows])
        phi[rows] = ph
        hit = (ph < thickness) & movable[rows]
        rows, ph, n, vel = rows[hit], ph[hit], n[hit], vel[hit]
        other = None if other is None else other[hit]
    moved = len(rows)
    before = None  # the normal of each row's previous push
    for _ in range(passes):
        if len(rows) == 0:
            break
        push = thickness - ph
        x[rows] += _push(push, n, before)
        _keep_tangential(v, rows, n, vel, friction)
        if other is not None:
            clear = other - push >= thickness
            phi[rows[clear]] = thickness
            if clear.all():
                break
            keep = ~clear
            rows, before = rows[keep], n[keep]
        else:
            before = n
        ph, n, vel, other = ask(x[rows])
        phi[rows] = ph
        again = ph < thickness - 1e-9
        if again.any():
            rows, ph, n, vel, before = rows[again], ph[again], n[again], vel[again], before[again]
            other = None if other is None else other[again]
        else:
            break
    return moved, phi


CREASE_COSINE = -0.95  # normals more opposed than this: a slot, not a crease (pushed along n alone)


def _push(depth, normal, before):
    """The move out of the body by `depth` along `normal`; for a point pushed out of one part
    into another (its previous push's normal `before`, opposing this one's: the crease where two
    capsules meet), the move that also keeps it out of the first part to first order: along the
    crease, a n + b n_before with the move's part along n_before 0, so alternate pushes need not
    zigzag along a narrow crease (a fine vertex took 16 passes there and stayed inside)."""
    if before is None:
        return depth[:, None] * normal
    c = rowdot(normal, before)
    c = np.where((c < 0.0) & (c > CREASE_COSINE), c, 0.0)  # elsewhere along n alone
    b = depth / (1.0 - c * c)
    return b[:, None] * normal - (c * b)[:, None] * before


_NONE = np.zeros(0, dtype=np.int64)
_SAMPLE_REACH = 1.0 - FACE_SAMPLES  # (S, 3)
_PREVIOUS = np.array([2, 0, 1])  # each face corner's previous one


_SAMPLE_MAPS = {}


def _sample_map(faces, particles):
    """The face samples of every face as one compiled product: (F S, particles) CSR whose row f S
    + s holds FACE_SAMPLES[s] at face f's corners (cached per face list)."""
    key = (faces.tobytes(), faces.shape, particles)
    out = _SAMPLE_MAPS.get(key)
    if out is None:
        from scipy.sparse import csr_matrix
        f_count, s_count = len(faces), len(FACE_SAMPLES)
        rows = np.repeat(np.arange(f_count * s_count), 3)
        cols = np.repeat(faces, s_count, axis=0).ravel()
        vals = np.tile(FACE_SAMPLES.ravel(), f_count)
        matrix = csr_matrix((vals, (rows, cols)), shape=(f_count * s_count, particles))
        matrix.sum_duplicates()
        if len(_SAMPLE_MAPS) > 8:
            _SAMPLE_MAPS.clear()
        out = _SAMPLE_MAPS[key] = Product(matrix, 3)
    return out


def resolve_faces(x, v, faces, bodies, s, thickness, movable, corner_phi, friction=0.0):
    """Face case (Fig. 4.6 b, d): a face whose interior cuts the body while its corners are out
    is moved out whole by its deepest point. (The number of faces moved, the particles moved.)"""
    tri = x.take(faces, axis=0)  # (F, 3, 3)
    side = tri - tri.take(_PREVIOUS, axis=1)
    edge = np.sqrt(np.einsum("fkj,fkj->fk", side, side).max(axis=1))
    # phi is 1-Lipschitz: the sample w.c is within (1 - w_k) times the longest edge of corner k,
    # so a sample whose bound max_k(phi_k - (1 - w_k) edge) is beyond the thickness can't be inside
    # (nor any sample of a face whose farthest-out corner is beyond its longest edge)
    bound = np.multiply.outer(edge, _SAMPLE_REACH)  # (F, S, 3)
    np.subtract(corner_phi.take(faces)[:, None, :], bound, out=bound)
    test = np.flatnonzero(bound.max(axis=2).ravel() < thickness)  # (face, sample) as f S + s
    if len(test) == 0:
        return 0, _NONE
    samples = _sample_map(faces, len(x))(x).take(test, axis=0)
    ph, nrm, vel = query_bodies(bodies, samples, s)
    s_count = len(FACE_SAMPLES)
    depth = np.full(len(faces) * s_count, -np.inf)
    depth.put(test, thickness - ph)
    depth = depth.reshape(-1, s_count)
    deepest = depth.argmax(axis=1)
    d = depth.max(axis=1)
    f_idx = np.flatnonzero(d > 1e-9)
    if len(f_idx) == 0:
        return 0, _NONE
    deepest, d = deepest.take(f_idx), d.take(f_idx)
    k = np.searchsorted(test, f_idx * s_count + deepest)  # each face's deepest sample among the tested
    n_k, v_k = nrm.take(k, axis=0), vel.take(k, axis=0)
    corners = faces.take(f_idx, axis=0).ravel()
    ok = movable.take(corners)
    face_of = np.repeat(np.arange(len(f_idx)), 3)[ok]
    corners = corners[ok]
    if len(corners) == 0:
        return 0, _NONE
    # a particle in several cut faces takes the largest push (the push is d along a unit normal)
    order = np.lexsort((d[face_of], corners))
    ranked = corners[order]
    last = np.ones(len(ranked), dtype=bool)
    np.not_equal(ranked[1:], ranked[:-1], out=last[:-1])
    pick = order[last]
    moved, f = corners[pick], face_of[pick]
    x[moved] += d[f, None] * n_k[f]
    _keep_tangential(v, moved, n_k[f], v_k[f], friction)
    return len(f_idx), moved


def resolve_contacts(x, v, faces, bodies, s, thickness, movable, friction=0.0, pushable=None, again=True):
    """Both cases, then the vertex case again (a face push may carry a corner into another part);
    returns (particles moved, faces moved). `pushable` (default: `movable`) are the particles the
    vertex case may move: pinned ones too, so a hand pressing on a waistband pushes it aside for
    that step rather than sinking into it (the pin takes it back when the hand leaves). With
    `faces` None, the vertex case alone; with `again` False, no second vertex case (for a caller
    whose own particle pass follows)."""
    if not bodies:
        return 0, 0
    pushable = movable if pushable is None else pushable
    n_p, phi = resolve_particles(x, v, bodies, s, thickness, pushable, friction)
    if faces is None:
        return n_p, 0
    n_f, moved = resolve_faces(x, v, faces, bodies, s, thickness, movable, phi, friction)
    if n_f and again:  # only the corners the faces moved can be inside again
        n_p += resolve_particles(x, v, bodies, s, thickness, pushable, friction, rows=moved, phi=phi)[0]
    return n_p, n_f


def penetration(points, bodies, s=1.0):
    """How deep each point is inside the body (0 outside), metres."""
    phi, _, _ = query_bodies(bodies, points, s)
    return np.maximum(-phi, 0.0)
