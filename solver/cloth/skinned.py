"""Collision with the character's skinned mesh at a cost that hardly grows with its size.

A skinned body's surface moves, piece by piece, nearly rigidly with its bones. So the search
structure is built once, in each bone's own frame at a reference pose (the first simulated
frame), and never rebuilt: every triangle belongs to the bone that weighs most on its corners;
per bone, a grid whose cells bound the distance to the bone's triangles from below and list the
nearest ones. A query point is carried into the frames of the bones near it; far cells give a
lower bound; the listed triangles' bounding spheres, as the body is at the query's time, drop
the rows and candidates that cannot be near; the rest are evaluated exactly on the skinned
triangles (the frame's start and end poses interpolated), with the side from the pseudo-normal
at the nearest point, checked in the mesh's rest pose for points found inside (a skinned mesh
folds into itself at bent joints). See docs/cloth.md for the measurements behind this choice.
"""

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ..vectors import cross
from .collision import closest_on_segments, closest_on_triangles
from .fast import dot

SLACK = 0.03  # metres a carried point may be from its place where skinning blends bones
REACH = 0.05  # metres: the default max_distance of queries, and the grids' margin beyond it
NEAR = 0.02  # metres: phi is exact below this (beyond the thickness); farther, possibly a lower bound
DEEP = 0.02  # metres: a point found farther inside is taken to be outside (see SkinnedBody)
LOCAL_SEARCH = True
FOLD_CHECK = True  # points found inside are checked at the reference pose (SkinnedBody._outside_at_reference)
MAX_CELLS = 2_000_000  # the grids' cells over all bones, at most (their spacing grows to fit)


class SkinnedBody:
    """A triangle mesh skinned to bones, moving linearly within a frame.

    triangles (T, 3); reference vertices (V, 3) and bone world matrices (J, 4, 4) at one pose;
    weights (V, J) of the bones on the vertices. `set_motion(v0, bones0, v1, bones1, dt)` gives
    the frame's start and end poses; `query(points, s)` as MeshBody.query.

    Per bone, a grid in its reference-pose frame over its triangles plus a margin; per cell, a
    lower bound of the distance to the bone's triangles (the nearest centroid's distance minus
    the triangles' reach) and the cell's `neighbours` nearest triangles. A query point goes into
    the frames of the bones whose bounding capsule it is near; a cell whose bound is beyond the
    query's reach ends the search there; otherwise its candidates are evaluated exactly."""

    def __init__(self, triangles, reference, bones, weights, neighbours=12, spacing=None, rest=None):
        self.triangles = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
        reference = np.asarray(reference, float)
        bones = _rigid(bones)
        weights = np.asarray(weights, float)
        self.k = neighbours
        t = self.triangles
        owner = weights[t].sum(axis=1).argmax(axis=1)  # (T,) the bone weighing most on the triangle
        used = np.unique(owner)
        self.bones = used  # the bones that own triangles
        slot = np.full(len(bones), -1)
        slot[used] = np.arange(len(used))
        self.slot_of_tri = slot_of_tri = slot[owner]
        # the second bone weighing most on each triangle's corners (the owner where that bone
        # owns no triangles or has no weight there): where skinning blends two bones
        tri_weight = weights[t].sum(axis=1)
        tri_weight[np.arange(len(t)), owner] = -1.0
        second = tri_weight.argmax(axis=1)
        second = np.where((tri_weight.max(axis=1) > 0.0) & (slot[second] >= 0), second, owner)
        self.blend_slots = np.column_stack([slot_of_tri, slot[second]])
        corners = reference[t]
        centroid = corners.mean(axis=1)
        spread = np.sqrt(((corners - centroid[:, None]) ** 2).sum(axis=2)).max(axis=1)  # each triangle's reach
        self.reach = float(spread.max())
        inv = np.linalg.inv(bones[owner])
        centroid_local = np.einsum("tij,tj->ti", inv[:, :3, :3], centroid) + inv[:, :3, 3]
        corner_local = np.einsum("tij,tkj->tki", inv[:, :3, :3], corners) + inv[:, None, :3, 3]
        margin = REACH + SLACK
        groups = [np.flatnonzero(slot_of_tri == i) for i in range(len(used))]
        lo = np.array([corner_local[g].reshape(-1, 3).min(axis=0) for g in groups]) - margin
        hi = np.array([corner_local[g].reshape(-1, 3).max(axis=0) for g in groups]) + margin
        if spacing is None:  # about the triangles' size, coarser if the cells would be too many
            edge = np.linalg.norm(corners[:, 1] - corners[:, 0], axis=1)
            spacing = max(0.75 * float(np.median(edge)), (np.prod(hi - lo, axis=1).sum() / MAX_CELLS) ** (1 / 3))
        self.spacing = h = spacing
        shape = np.ceil((hi - lo) / h).astype(np.int64) + 1
        self.lo, self.shape = lo, shape
        self.start = np.r_[0, np.cumsum(np.prod(shape, axis=1))[:-1]]
        cells = int(np.prod(shape, axis=1).sum())
        self.bound = np.full(cells, np.inf, dtype=np.float32)
        self.row_of = np.full(cells, -1, dtype=np.int32)  # a cell's row in `candidates` (-1: none)
        candidates = []
        for i, g in enumerate(groups):
            axes = [lo[i, d] + h * np.arange(shape[i, d]) for d in range(3)]
            centres = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
            tree = cKDTree(centroid_local[g])
            k = min(neighbours, len(g))
            # a point in the cell is within half a diagonal of its centre
            reach = spread[g]
            d1, _ = tree.query(centres, k=1)
            lower = d1 - reach.max() - 0.5 * np.sqrt(3.0) * h
            band = np.flatnonzero(lower < NEAR + SLACK)  # (the cells whose candidates are looked at)
            dist, idx = tree.query(centres[band], k=k)
            dist, idx = dist.reshape(len(band), k), idx.reshape(len(band), k)
            # tighter where the candidates tell: the nearest candidate's own reach, the others'
            # beyond the K-th at most the bone's largest
            lower[band] = np.minimum((dist - reach[idx]).min(axis=1), dist[:, -1] - reach.max()) - 0.5 * np.sqrt(3.0) * h
            self.bound[self.start[i]:self.start[i] + len(centres)] = lower
            found = sum(len(c) for c in candidates)
            self.row_of[self.start[i] + band] = found + np.arange(len(band))
            rows = np.full((len(band), neighbours), -1, dtype=np.int32)
            rows[:, :k] = g[idx]
            candidates.append(rows)
        self.candidates = np.concatenate(candidates)
        # a capsule around each bone's triangles, fixed in the bone (a segment along the bone's
        # axis over its triangles' extent, and a radius holding every corner): the bones a query
        # point can reach are those whose capsule it is near
        ends, radius = [], []
        for g in groups:
            c = corner_local[g].reshape(-1, 3)
            ends.append(([0.0, c[:, 1].min(), 0.0], [0.0, c[:, 1].max(), 0.0]))
            radius.append(np.sqrt(c[:, 0] ** 2 + c[:, 2] ** 2).max())
        self.ends_local = np.array(ends)  # (B, 2, 3)
        self.radius = np.array(radius)
        self.across, self.ring = _topology(t, len(reference))
        # closed parts (a body of separate pieces is their union: the smallest phi over them)
        self.part_of = closed_parts(t, len(reference))
        self.v0 = self.v1 = None
        self._at = None
        # the unfolded pose the side of points found inside is checked at (_outside_at_reference):
        # the mesh's rest pose when given (rest vertices (V, 3), bone matrices (J, 4, 4)), where a
        # body is modelled, else the reference pose
        rest_vertices, rest_bones = (reference, bones) if rest is None else rest
        rest_vertices = np.asarray(rest_vertices, float)
        self.rest_frames = _rigid(rest_bones)[used]
        self._rest_vertices = lambda idx: rest_vertices[idx]
        self._rest_tree = cKDTree(rest_vertices[t].mean(axis=1))

    def set_motion(self, v0, bones0, v1=None, bones1=None, dt=1.0):
        """The skinned vertices and the bones' world matrices at the frame's start and end."""
        self.v0 = np.asarray(v0, float)
        self.v1 = self.v0 if v1 is None else np.asarray(v1, float)
        b0 = _rigid(np.asarray(bones0, float)[self.bones])
        b1 = b0 if bones1 is None else _rigid(np.asarray(bones1, float)[self.bones])
        self.b0, self.b1 = b0, b1
        self.dt = dt
        self.motions = getattr(self, "motions", 0) + 1
        self._at = None
        self._v_at = None

    def _pose(self, s):
        """Per bone at time s, the map from world to its reference-pose frame as one (3, 3B)
        rotation block and a (3B,) offset: points @ block + offset are every point's coordinates
        in every bone's frame at once."""
        if self._at is not None and self._at[0] == s:
            return self._at[1]
        m = self.b0 + s * (self.b1 - self.b0)  # (nearly rigid over a frame's short motion)
        rot = m[:, :3, :3].transpose(0, 2, 1)  # the inverse rotation (orthonormal frames)
        offset = -np.einsum("bij,bj->bi", rot, m[:, :3, 3])
        block = rot.transpose(2, 0, 1).reshape(3, -1)  # column 3 b + i: row i of bone b's inverse
        self._at = (s, (block, offset.ravel()))
        return self._at[1]

    def query(self, points, s=1.0, max_distance=REACH):
        """(phi (N,), outward unit normal (N, 3), surface velocity (N, 3)). phi is exact below
        NEAR; beyond, a lower bound (at most max_distance, which is at most REACH)."""
        points = np.asarray(points, float)
        n = len(points)
        phi = np.full(n, float(max_distance))
        normal = np.zeros((n, 3))
        normal[:, 2] = 1.0
        velocity = np.zeros((n, 3))
        if n == 0:
            return phi, normal, velocity
        block, offset = self._pose(s)
        local = (points @ block + offset).reshape(n, -1, 3)  # (N, B, 3) in every bone's frame
        # the distance to each bone's capsule: along its y axis, clipped to the triangles' extent
        y = np.clip(local[:, :, 1], self.ends_local[:, 0, 1], self.ends_local[:, 1, 1])
        gap = local - 0.0
        gap[:, :, 1] -= y
        near = dot(gap, gap) < (self.radius + max_distance + SLACK)[None] ** 2
        rows, bone = np.nonzero(near)  # (point, bone) pairs
        if len(rows) == 0:
            return phi, normal, velocity
        local = local[rows, bone]
        cell = np.rint((local - self.lo[bone]) / self.spacing).astype(np.int64)
        shape = self.shape[bone]
        inside = np.all((cell >= 0) & (cell < shape), axis=1)  # (outside the grid: beyond reach)
        flat = self.start[bone] + (cell[:, 0] * shape[:, 1] + cell[:, 1]) * shape[:, 2] + cell[:, 2]
        flat = np.where(inside, flat, 0)
        # a row whose cell is far from the bone's triangles gives a lower bound (the cell's,
        # less what skinning may have moved them); the others are evaluated exactly
        lower = np.where(inside, self.bound[flat] - SLACK, np.inf)
        far = lower >= NEAR
        if far.any():
            np.minimum.at(phi, rows[far], np.minimum(lower[far], max_distance))
        keep = ~far
        rows, flat, local, bone = rows[keep], flat[keep], local[keep], bone[keep]
        if len(rows) == 0:
            return phi, normal, velocity
        idx = self.candidates[self.row_of[flat]].astype(np.int64)
        valid = idx >= 0
        ids = np.where(valid, idx, 0)
        rows, ids, valid, lower = self._spheres(points, rows, ids, valid, s)
        far = lower >= NEAR  # every candidate's bounding sphere beyond NEAR: a lower bound
        if far.any():
            np.minimum.at(phi, rows[far], np.minimum(lower[far], max_distance))
            keep = ~far
            rows, ids, valid, local, bone = rows[keep], ids[keep], valid[keep], local[keep], bone[keep]
        if len(rows) == 0:
            return phi, normal, velocity
        signed, nrm, vel, unsigned, tri = self._exact(points[rows], ids, valid, s, max_distance)
        if FOLD_CHECK:
            inside = np.flatnonzero(signed < 0.0)
            if len(inside):
                fold = inside[self._outside_at_reference(points[rows[inside]], tri[inside], s)]
                signed[fold] = np.minimum(unsigned[fold], max_distance)
                nrm[fold] = -nrm[fold]
        # per point and closed part, the row with the nearest surface; per point, the part with
        # the smallest phi (the union), unless a far row's bound is below it
        part = self.part_of[tri]
        order = np.lexsort((unsigned, part, rows))
        first = np.r_[True, (rows[order][1:] != rows[order][:-1]) | (part[order][1:] != part[order][:-1])]
        pick = order[first]
        order = pick[np.lexsort((signed[pick], rows[pick]))]
        pick = order[np.r_[True, rows[order][1:] != rows[order][:-1]]]
        out = rows[pick]
        take = signed[pick] <= phi[out]
        out, pick = out[take], pick[take]
        phi[out], normal[out], velocity[out] = signed[pick], nrm[pick], vel[pick]
        return phi, normal, velocity

    def _spheres(self, points, rows, ids, valid, s):
        """The cheap stage before the exact one: each candidate triangle's bounding sphere at
        time s (its centroid and the farthest corner from it) bounds its distance from below,
        |p - c| - r, and from above, |p - c| + r. Per row, the candidates whose lower bound is
        beyond the smallest upper bound cannot hold the nearest point: dropped, the rest sorted
        nearest first and cut to the largest count any row keeps. Returns (rows, ids, valid,
        each row's lower bound over its candidates)."""
        corners = self._vertices(s)(self.triangles[ids])  # (M, C, 3, 3)
        centre = corners.sum(axis=2) / 3.0
        spoke = corners - centre[:, :, None, :]
        r = np.sqrt(dot(spoke, spoke).max(axis=2))
        d = points[rows][:, None, :] - centre
        d = np.sqrt(dot(d, d))
        lower = np.where(valid, d - r, np.inf)
        upper = np.where(valid, d + r, np.inf).min(axis=1)
        order = np.argsort(lower, axis=1)
        lower = np.take_along_axis(lower, order, axis=1)
        keep = lower <= upper[:, None]
        width = max(1, int(keep.sum(axis=1).max())) if len(keep) else 1
        ids = np.take_along_axis(ids, order[:, :width], axis=1)
        valid = keep[:, :width]
        return rows, ids, valid, lower[:, 0]

    def _exact(self, p, ids, valid, s, max_distance):
        """Signed distances of points p (M, 3) to their candidate triangles ids (M, C) on the
        skinned mesh at time s: the nearest; its side from the angle-weighted pseudo-normal of
        the nearest point's feature (face, edge or vertex: exact for a closed mesh, Baerentzen and
        Aanaes 2005), made from the skinned triangles around it. (phi, normal, velocity, distance, triangle)."""
        v = self._vertices(s)
        best, t_best, b, dk, found = self._nearest_searched(p, ids, valid, v)
        pseudo = self._pseudo_normal(t_best, b, v)
        # inside only within DEEP of the surface: cloth collided every substep is never deeper
        # (it enters by what the body moves in a substep), while a skinned mesh folded or cut
        # into itself around a bent joint shows "inside" sides far out in the air
        sign = np.where((dot(dk, pseudo) < 0.0) & (best < DEEP), -1.0, 1.0)
        phi = np.minimum(sign * best, max_distance)
        far = best[:, None] > 1e-9
        pk = pseudo / np.maximum(np.sqrt(dot(pseudo, pseudo)), 1e-18)[:, None]
        normal = np.where(far, sign[:, None] * dk / np.maximum(best, 1e-12)[:, None], pk)
        normal[~found] = (0.0, 0.0, 1.0)
        phi[~found] = max_distance
        c = self.triangles[t_best]
        velocity = np.einsum("ij,ijk->ik", np.where(found[:, None], b, 0.0), (self.v1[c] - self.v0[c]) / self.dt)
        return phi, normal, velocity, best, t_best

    def _nearest_searched(self, p, ids, valid, v):
        """The nearest of the candidate triangles (vertices v(indices)), then one step of local
        search where the nearest point is on a candidate's edge or corner: the triangles around
        its corners (where skinning blends bones the cell's candidates can miss the nearest,
        never by far; inside a face the nearest is a local minimum). (distance, triangle,
        barycentric, p minus the point, found)."""
        best, t_best, b, dk = _nearest(p, ids, valid, self.triangles, v)
        found = np.isfinite(best)
        zero = b <= 1e-12
        count = zero.sum(axis=1)
        if LOCAL_SEARCH:
            for h, around in self._neighbours(t_best, zero, count, found):
                best2, t2, b2, d2 = _nearest(p[h], np.maximum(around, 0), around >= 0, self.triangles, v)
                better = best2 < best[h]
                k = h[better]
                best[k], t_best[k], b[k], dk[k] = best2[better], t2[better], b2[better], d2[better]
        return best, t_best, b, dk, found

    def _outside_at_reference(self, p, tri, s):
        """Whether points p found inside the skinned mesh (their nearest triangle tri) are outside
        it in the rest pose, carried there by each of the two bones weighing most on that
        triangle. A skinned mesh folds or cuts into itself around a bent joint; near such a fold
        the nearest face can face away from a point that is outside the body (winding number 0).
        Carried back with a bone into the unfolded rest pose, where the mesh is a clean closed
        surface and the pseudo-normal's side is exact, such a point is outside. A point inside
        the body stays inside when carried by one of its bones at least (where skinning blends
        two bones, carried by the other one it can land outside: the shoulder's skin of an arm
        raised from the rest pose's, carried by the arm): only points outside with both are."""
        block, offset = self._pose(s)
        frames = block.reshape(3, -1, 3)  # [k, b, i]: row i of bone b's inverse, column k
        out = np.ones(len(p), dtype=bool)
        for column in (0, 1):
            bone = self.blend_slots[tri, column]
            h = np.flatnonzero(out & ((column == 0) | (bone != self.blend_slots[tri, 0])))
            if len(h) == 0:
                continue
            bone = bone[h]
            local = np.einsum("mk,kmi->mi", p[h], frames[:, bone, :]) + offset.reshape(-1, 3)[bone]
            frame = self.rest_frames[bone]
            q = np.einsum("mij,mj->mi", frame[:, :3, :3], local) + frame[:, :3, 3]
            k = min(self.k, self._rest_tree.n)
            _, idx = self._rest_tree.query(q, k=k)
            idx = idx.reshape(len(q), k)
            v = self._rest_vertices
            best, t_best, b, dk, found = self._nearest_searched(q, idx, np.ones(idx.shape, dtype=bool), v)
            out[h] = found & (dot(dk, self._pseudo_normal(t_best, b, v)) > 0.0)
        return out

    def _neighbours(self, tri, zero, count, found):
        """Where the nearest point is on an edge or a corner of triangle `tri`, the triangles
        around its three corners (those across the feature alone miss some). Yields (rows,
        triangles (m, n), -1 padded)."""
        h = np.flatnonzero(found & (count >= 1))
        if len(h):
            yield h, self.ring[self.triangles[tri[h]]].reshape(len(h), -1)

    def _vertices(self, s):
        """A gather of the skinned vertices at time s (all of them interpolated once per time:
        a few hundred thousand floats cost less than interpolating the candidates' corners)."""
        if self._v_at is None or self._v_at[0] != s:
            v = self.v0 if self.v1 is self.v0 else self.v0 + s * (self.v1 - self.v0)
            self._v_at = (s, v)
        v = self._v_at[1]
        return lambda idx: v[idx]

    def _pseudo_normal(self, tri_id, bary, v):
        """Angle-weighted normal at the closest point's feature of triangles tri_id, given its
        barycentric coordinates: the face's normal inside it, the two faces' across an edge,
        the incident faces' weighted by their angles at a vertex."""
        zero = bary <= 1e-9
        count = zero.sum(axis=1)
        out = _face_normals(v(self.triangles[tri_id]))  # inside a face
        edge = np.flatnonzero(count == 1)
        if len(edge):  # the edge opposite the zero coordinate: its other face
            k = zero[edge].argmax(axis=1)
            other = self.across[tri_id[edge], k]
            out[edge] += np.where((other >= 0)[:, None], _face_normals(v(self.triangles[np.maximum(other, 0)])), 0.0)
        vert = np.flatnonzero(count >= 2)
        if len(vert):
            k = (~zero[vert]).argmax(axis=1)  # the corner with the weight
            vid = self.triangles[tri_id[vert], k]
            ring = self.ring[vid]  # (m, D) incident faces, -1 padded
            faces = self.triangles[np.maximum(ring, 0)]  # (m, D, 3)
            pts = v(faces)
            fn = _face_normals(pts)
            # the angle at vid in each incident face
            at = (faces == vid[:, None, None]).argmax(axis=2)
            here = np.take_along_axis(pts, at[..., None, None], axis=2)[:, :, 0]
            nxt = np.take_along_axis(pts, ((at + 1) % 3)[..., None, None], axis=2)[:, :, 0] - here
            prv = np.take_along_axis(pts, ((at + 2) % 3)[..., None, None], axis=2)[:, :, 0] - here
            cosang = dot(nxt, prv) / np.maximum(np.sqrt(dot(nxt, nxt) * dot(prv, prv)), 1e-30)
            angle = np.arccos(np.clip(cosang, -1.0, 1.0)) * (ring >= 0)
            out[vert] = np.einsum("md,mdk->mk", angle, fn)
        return out


def closed_parts(triangles, vertex_count):
    """The connected part (0, 1, ...) of each triangle."""
    t = np.asarray(triangles, dtype=np.int64)
    graph = coo_matrix((np.ones(2 * len(t)), (t[:, :2].ravel(), t[:, 1:].ravel())), shape=(vertex_count, vertex_count))
    return connected_components(graph, directed=False)[1][t[:, 0]]


def _nearest(p, ids, valid, triangles, v):
    """Per point p (M, 3), the nearest of its candidate triangles ids (M, C) (valid (M, C)) with
    vertices v(indices): (distance (M,), triangle (M,), barycentric (M, 3), p minus the point)."""
    tri = v(triangles[ids])  # (M, C, 3, 3)
    q, bary = closest_on_triangles(p[:, None, :], tri[:, :, 0], tri[:, :, 1], tri[:, :, 2])
    d = p[:, None, :] - q
    dist = np.where(valid, np.sqrt(dot(d, d)), np.inf)
    nearest = np.argmin(dist, axis=1)
    r = np.arange(len(p))
    return dist[r, nearest], ids[r, nearest], bary[r, nearest], d[r, nearest]


def _rigid(matrices):
    """The bones' frames without their scale (unit axes): distances in a bone's frame are
    metres, as in the world."""
    m = np.array(matrices, float)
    m[:, :3, :3] /= np.linalg.norm(m[:, :3, :3], axis=1, keepdims=True)
    return m


def _face_normals(tri):
    fn = cross(tri[..., 1, :] - tri[..., 0, :], tri[..., 2, :] - tri[..., 0, :])
    return fn / np.maximum(np.sqrt(dot(fn, fn)), 1e-30)[..., None]


def _topology(triangles, vertex_count):
    """For each triangle's corner k, the triangle across the edge opposite it (-1: none), and
    for each vertex its incident triangles ((V, D), -1 padded)."""
    t = triangles
    count = len(t)
    # edge opposite corner k: corners (k+1, k+2)
    a = np.concatenate([t[:, 1], t[:, 2], t[:, 0]])
    b = np.concatenate([t[:, 2], t[:, 0], t[:, 1]])
    owner = np.tile(np.arange(count), 3)
    corner = np.repeat(np.arange(3), count)
    key = np.minimum(a, b) * vertex_count + np.maximum(a, b)
    order = np.argsort(key, kind="stable")
    ks = key[order]
    across = np.full((count, 3), -1, dtype=np.int64)
    same = np.flatnonzero(ks[1:] == ks[:-1])
    i, j = order[same], order[same + 1]
    across[owner[i], corner[i]] = owner[j]
    across[owner[j], corner[j]] = owner[i]
    flat = t.ravel()
    tri_of = np.repeat(np.arange(count), 3)
    order = np.argsort(flat, kind="stable")
    degree = np.bincount(flat, minlength=vertex_count)
    start = np.r_[0, np.cumsum(degree)[:-1]]
    slot = np.arange(len(flat)) - start[flat[order]]
    ring = np.full((vertex_count, max(1, degree.max())), -1, dtype=np.int64)
    ring[flat[order], slot] = tri_of[order]
    return across, ring
