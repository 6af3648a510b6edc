"""Geometric smoothing of the coarse cloth (Oshita 2003 §4.3), run after each simulated frame:

1. particle normal control: each particle's normal is the average of its faces' normals weighted
   by the elastic force each face applies to it (eq. 4.2-4.4);
2. PN triangles: a cubic Bezier triangle per coarse face from its corners and normals (§4.3.1);
3. edge length control: each patch is split into four at its edge midpoints; the midpoint of a
   shortened edge moves along its normal by h (eq. 4.5) so that the edge's curve regains its rest
   length, h found by bisection from the initial guess of eq. 4.6 (§4.3.3);
4. tessellation of the four sub-patches (PN triangles again) to a chosen level.

Everything shared by two faces (edge curves, midpoints and their normals) is computed once per
edge, so the fine surface is watertight and passes through every particle.
"""

from dataclasses import dataclass

import numpy as np

from .fast import CornerSum, dot
from .mesh import face_normals

# Gauss-Legendre nodes and weights on [0, 1] for the length of a cubic curve
_GL_X, _GL_W = np.polynomial.legendre.leggauss(5)
GL_T, GL_W = 0.5 * (_GL_X + 1.0), 0.5 * _GL_W


def _unit(v):
    return v / np.maximum(np.sqrt(dot(v, v)), 1e-18)[..., None]


# ---- particle normals -------------------------------------------------------------------------

def _corner_tables(mesh):
    """Per face corner: the particle, the next and previous ones, the rest lengths of the two
    sides at the corner, and the (P, 3F) sum over corners (cached on the mesh)."""
    tables = getattr(mesh, "_corner_tables", None)
    if tables is None:
        f = mesh.faces
        la = mesh.rest_length[mesh.face_edges]  # side (corner, next)
        lc = np.roll(la, 1, axis=1)  # side (previous, corner)
        gather = CornerSum(f, len(mesh.rest))
        tables = (f, np.roll(f, -1, axis=1), np.roll(f, 1, axis=1), la, lc, gather)
        mesh._corner_tables = tables
    return tables


def elastic_face_forces(mesh, x, k_elastic):
    """|f_i^j| (F, 3): magnitude of the elastic force face j applies to each of its corners,
    f_i^j = f_ia + f_ib (eq. 4.4), each spring force from eq. 4.1."""
    f, nxt, prv, la, lc, _ = _corner_tables(mesh)
    pa = x[f]
    db, dc = x[nxt] - pa, x[prv] - pa
    lb, lcc = np.sqrt(np.einsum("fcj,fcj->fc", db, db)), np.sqrt(np.einsum("fcj,fcj->fc", dc, dc))
    force = ((lb - la) / la)[..., None] * db + ((lcc - lc) / lc)[..., None] * dc
    return k_elastic * np.sqrt(np.einsum("fcj,fcj->fc", force, force))


def controlled_normals(mesh, x, k_elastic=1.0, control=True):
    """Particle normals (P, 3): eq. 4.3 with the weights of eq. 4.2-4.4 (control=True), or the
    plain average of the adjacent face normals (Gouraud, control=False). A particle under no
    elastic force at all takes the plain average (the weights carry a tiny uniform part). The
    division by the sum of the weights in eq. 4.3 cancels in the unit vector."""
    n, _ = face_normals(x, mesh.faces)
    gather = _corner_tables(mesh)[-1]
    if control:
        w = elastic_face_forces(mesh, x, k_elastic)
        w = w + 1e-9 * (1.0 + w.max())
        out = gather @ (w.reshape(-1, 1) * np.repeat(n, 3, axis=0))
    else:
        out = gather @ np.repeat(n, 3, axis=0)
    return _unit(out)


# ---- PN triangles ---------------------------------------------------------------------------

def edge_controls(p0, n0, p1, n1):
    """Inner control points of the PN edge curve p0 -> p1 (depends on the edge alone)."""
    d = p1 - p0
    c1 = (2.0 * p0 + p1 - dot(d, n0)[..., None] * n0) / 3.0
    c2 = (2.0 * p1 + p0 + dot(d, n1)[..., None] * n1) / 3.0
    return c1, c2


def pn_patch(p, n):
    """Control points (..., 10, 3) of PN triangles with corners p (..., 3, 3) and normals n.
    Order: b300 b030 b003 b210 b120 b021 b012 b102 b201 b111 (corner 0 weight w, 1 u, 2 v)."""
    p1, p2, p3 = p[..., 0, :], p[..., 1, :], p[..., 2, :]
    n1, n2, n3 = n[..., 0, :], n[..., 1, :], n[..., 2, :]
    b210, b120 = edge_controls(p1, n1, p2, n2)
    b021, b012 = edge_controls(p2, n2, p3, n3)
    b102, b201 = edge_controls(p3, n3, p1, n1)
    e = (b210 + b120 + b021 + b012 + b102 + b201) / 6.0
    v = (p1 + p2 + p3) / 3.0
    b111 = e + (e - v) / 2.0
    return np.stack([p1, p2, p3, b210, b120, b021, b012, b102, b201, b111], axis=-2)


def bernstein(bary):
    """Cubic Bernstein weights (G, 10) at barycentric points (G, 3) = (w, u, v)."""
    w, u, v = bary[:, 0], bary[:, 1], bary[:, 2]
    return np.stack([w ** 3, u ** 3, v ** 3, 3 * w * w * u, 3 * w * u * u, 3 * u * u * v, 3 * u * v * v,
                     3 * w * v * v, 3 * w * w * v, 6 * w * u * v], axis=1)


def pn_mid_normal(p0, n0, p1, n1):
    """The PN triangles' quadratic normal at the middle of edge p0-p1: (n0 + n1 + n110) / 4."""
    d = p1 - p0
    vij = 2.0 * dot(d, n0 + n1) / np.maximum(dot(d, d), 1e-18)
    n110 = _unit(n0 + n1 - vij[..., None] * d)
    return _unit(n0 + n1 + n110)


def cubic_point(p0, c1, c2, p1, t):
    s = 1.0 - t
    return s ** 3 * p0 + 3 * s * s * t * c1 + 3 * s * t * t * c2 + t ** 3 * p1


# B'(t) = D[t] . (p0, c1, c2, p1) at the Gauss-Legendre nodes
_T = GL_T[:, None]
DERIV = 3.0 * np.hstack([-(1 - _T) ** 2, (1 - _T) ** 2 - 2 * (1 - _T) * _T, 2 * (1 - _T) * _T - _T ** 2, _T ** 2])


def cubic_length(p0, c1, c2, p1):
    """Length of cubic Bezier curves (..., 3) by 5-point Gauss-Legendre on |B'(t)|."""
    shape = p0.shape
    if c1.shape == shape and c2.shape == shape and p1.shape == shape:  # B' as one 2-D product
        speed = (DERIV @ np.array((p0, c1, c2, p1)).reshape(4, -1)).reshape(len(DERIV), -1, 3)
        return (np.sqrt(np.einsum("tnj,tnj->nt", speed, speed)) @ GL_W).reshape(shape[:-1])
    ctrl = np.stack([p0, c1, c2, p1], axis=-2)  # (..., 4, 3)
    return _speed_length(DERIV @ ctrl)


def _speed_length(velocity):
    return np.sqrt(np.einsum("...tj,...tj->...t", velocity, velocity)) @ GL_W


def pn_curve_length(p0, n0, p1, n1):
    c1, c2 = edge_controls(p0, n0, p1, n1)
    return cubic_length(p0, c1, c2, p1)


def split_curve_length(p0, n0, pm, nm, p1, n1):
    """Length of an edge split at a midpoint pm (normal nm) into two PN curves."""
    return pn_curve_length(p0, n0, pm, nm) + pn_curve_length(pm, nm, p1, n1)


def _split_speed(p0, n0, m, nm, p1, n1):
    """B'(t) of the two halves at the quadrature nodes as V0 + h V1 for a midpoint m + h nm:
    the PN control points are affine in h, so each bisection step is one fused evaluation.
    V1 is B' of the control points' rates in h (from edge_controls: the inner points next to
    the midpoint move by (2 + nm.nm)/3 nm, the outer ones by the part of nm across their
    end's normal, over 3)."""
    c1, c2 = edge_controls(p0, n0, m, nm)
    c3, c4 = edge_controls(m, nm, p1, n1)
    k = len(m)
    # (halves, control points, M x 3): each half's B' at the nodes is one 2-D product
    ctrl = np.array((p0, c1, c2, m, m, c3, c4, p1)).reshape(2, 4, 3 * k)
    inner = ((2.0 + dot(nm, nm)) / 3.0)[:, None] * nm
    zero = np.zeros_like(nm)
    rate = np.array((zero, (nm - dot(nm, n0)[:, None] * n0) / 3.0, inner, nm,
                     nm, inner, (nm - dot(nm, n1)[:, None] * n1) / 3.0, zero)).reshape(2, 4, 3 * k)
    return (DERIV @ ctrl).reshape(2, -1, k, 3), (DERIV @ rate).reshape(2, -1, k, 3)  # (2, T, M, 3) each


# ---- edge length control ------------------------------------------------------------------

GROW = 8  # bracket doublings evaluated together
HALVING_BITS = 4  # bisection halvings done in one pass (2^bits - 1 lengths per edge)
_DOUBLINGS = 2.0 ** np.arange(GROW)
_FRACTIONS = {b: (np.arange(1, 1 << b) / (1 << b))[:, None] for b in range(1, HALVING_BITS + 1)}
_GL_BOTH = np.concatenate([GL_W, GL_W])  # the quadrature weights of both halves' nodes

def edge_midpoints(p0, n0, p1, n1, rest, k_guess=1.0, iterations=8):
    """Midpoints (E, 3), their normals, h (E,) and whether each edge was shortened: §4.3.3.

    The midpoint of the PN edge curve moves along its normal by h >= 0 so that the two halves'
    PN curves (through the moved midpoint) are as long as the rest length. Bisection: the bracket
    starts at the initial guess of eq. 4.6, h0 = k (L - |p_i - p_j|), and grows until it holds
    the root; a fixed number of halvings follows, for all shortened edges at once (8: the bracket,
    a doubling wide, to 1/256 of it; on the benchmark's skirt the split curves' lengths then stay
    within 0.03 % of the rest length, 0.007 % with 10, which cost a third pass of the halvings)."""
    c1, c2 = edge_controls(p0, n0, p1, n1)
    mid = p0 + p1
    mid += 3.0 * (c1 + c2)
    mid *= 0.125  # the curve at t = 1/2
    nm = pn_mid_normal(p0, n0, p1, n1)
    h = np.zeros(len(rest))
    short = cubic_length(p0, c1, c2, p1) < rest
    if not short.any():
        return mid, nm, h, short
    i = np.flatnonzero(short)
    a0, b0, a1, b1, m, n, target = p0[i], n0[i], p1[i], n1[i], mid[i], nm[i], rest[i]
    v0, v1 = _split_speed(a0, b0, m, n, a1, b1)
    # |v0 + h v1|^2 = A + h (B + h C) at every quadrature node: each bisection step is one pass.
    # Laid out (nodes of both halves, edges): a pass over K trial h per edge works on (K, nodes,
    # edges) arrays whose rows are long and contiguous (numpy's inner loops run over the edges)
    count = len(i)
    qa = np.einsum("htaj,htaj->hta", v0, v0).reshape(-1, count)
    qb = np.einsum("htaj,htaj->hta", v0, v1).reshape(-1, count)
    qb *= 2.0
    qc = np.einsum("htaj,htaj->hta", v1, v1).reshape(-1, count)

    def lengths(hh):  # hh (K, M) -> the split curves' lengths (K, M)
        hh = hh[:, None, :]
        s = hh * qc
        s += qb
        s *= hh
        s += qa  # A + h (B + h C)
        np.maximum(s, 0.0, out=s)
        np.sqrt(s, out=s)
        return _GL_BOTH @ s

    chord = a1 - a0
    chord = np.sqrt(dot(chord, chord))
    h0 = np.maximum(k_guess * (target - chord), 1e-6 * target)  # eq. 4.6
    # grow the bracket from h0, doubling, until the curve at hi is long enough: the first
    # GROW doublings evaluated at once, the rare longer searches one doubling at a time
    cand = _DOUBLINGS[:, None] * h0  # (GROW, M)
    long_enough = lengths(cand) >= target
    j = np.where(long_enough.any(axis=0), long_enough.argmax(axis=0), GROW)
    cols = np.arange(count)
    hi = np.where(j < GROW, cand[np.minimum(j, GROW - 1), cols], 2.0 * cand[-1])
    lo = np.where(j > 0, cand[np.maximum(j - 1, 0), cols], 0.0)
    lo = np.where(j == GROW, cand[-1], lo)
    for _ in range(40 - GROW if j.max() == GROW else 0):  # (the others' hi is long enough)
        low = lengths(hi[None])[0] < target
        if not low.any():
            break
        lo = np.where(low, hi, lo)
        hi = np.where(low, 2.0 * hi, hi)
    # the halvings, several at a time: the length grows with h, so `bits` halvings of [lo, hi]
    # end in the one of its 2^bits equal parts where the length crosses the target, found by
    # evaluating all their inner ends at once (one pass instead of `bits` passes)
    done = 0
    while done < iterations:
        bits = min(HALVING_BITS, iterations - done)
        parts = 1 << bits
        width = hi - lo
        hh = _FRACTIONS[bits] * width
        hh += lo  # (parts - 1, M)
        below = (lengths(hh) < target).sum(axis=0)
        lo, hi = lo + width * (below / parts), lo + width * ((below + 1) / parts)
        done += bits
    h[i] = 0.5 * (lo + hi)
    mid[i] = m + h[i, None] * n
    return mid, nm, h, short


# ---- tessellation -------------------------------------------------------------------------

@dataclass
class Tessellation:
    """Fine mesh layout: each coarse face is a grid of n = 2 m segments per side, split into the
    four sub-patches (three corner ones and the middle one); n^2 triangles per coarse face."""

    level: int  # m: segments per sub-patch side
    vertex_count: int
    faces: np.ndarray  # (F n^2, 3) fine triangles
    vertex_of: np.ndarray  # (F, G) fine vertex of each grid point of each coarse face
    patch_of: np.ndarray  # (G,) sub-patch 0..3 of each grid point
    weights: np.ndarray  # (G, 10) Bernstein weights of each grid point in its sub-patch
    edge_vertices: np.ndarray  # (E, n + 1) fine vertices along each coarse edge, first to second particle
    full_weights: np.ndarray = None  # (G, 40): each grid point's weights on the 4 x 10 control points


def _grid(n):
    return [(i, j) for j in range(n + 1) for i in range(n + 1 - j)]  # i along corner 1, j along corner 2


def tessellation(mesh, level):
    if level < 1:
        raise ValueError("the smoothing level is at least 1")
    m, f_count = level, len(mesh.faces)
    n = 2 * m
    grid = _grid(n)
    g_index = {ij: g for g, ij in enumerate(grid)}
    bary = np.array([((n - i - j) / n, i / n, j / n) for i, j in grid])
    patch, local = [], []
    for i, j in grid:
        W, U, V = n - i - j, i, j
        if W >= m:
            patch.append(0), local.append(((W - m) / m, U / m, V / m))
        elif U >= m:
            patch.append(1), local.append((W / m, (U - m) / m, V / m))
        elif V >= m:
            patch.append(2), local.append((W / m, U / m, (V - m) / m))
        else:
            patch.append(3), local.append((1 - V / m, 1 - W / m, 1 - U / m))
    p_count, e_count = mesh.particle_count, len(mesh.edges)
    inner = [g for g, (i, j) in enumerate(grid) if i > 0 and j > 0 and i + j < n]
    vertex_of = np.empty((f_count, len(grid)), dtype=np.int64)
    edge_vertices = np.empty((e_count, n + 1), dtype=np.int64)
    edge_vertices[:, 0], edge_vertices[:, -1] = mesh.edges[:, 0], mesh.edges[:, 1]
    edge_vertices[:, 1:-1] = p_count + np.arange(e_count)[:, None] * (n - 1) + np.arange(n - 1)[None]
    base_inner = p_count + e_count * (n - 1)
    corner_grid = (g_index[(0, 0)], g_index[(n, 0)], g_index[(0, n)])
    for f, face in enumerate(mesh.faces):
        for c, g in enumerate(corner_grid):
            vertex_of[f, g] = face[c]
        # sides: (corner0 -> corner1) along i, (corner1 -> corner2), (corner2 -> corner0)
        sides = [[g_index[(t, 0)] for t in range(n + 1)],
                 [g_index[(n - t, t)] for t in range(n + 1)],
                 [g_index[(0, n - t)] for t in range(n + 1)]]
        for s, cells in enumerate(sides):
            e = mesh.face_edges[f, s]
            along = edge_vertices[e] if mesh.edges[e, 0] == face[s] else edge_vertices[e][::-1]
            vertex_of[f, cells] = along
        vertex_of[f, inner] = base_inner + f * len(inner) + np.arange(len(inner))
    tris = []
    for j in range(n):
        for i in range(n - j):
            tris.append((g_index[(i, j)], g_index[(i + 1, j)], g_index[(i, j + 1)]))
            if i + j < n - 1:
                tris.append((g_index[(i + 1, j)], g_index[(i + 1, j + 1)], g_index[(i, j + 1)]))
    tris = np.array(tris)
    faces = vertex_of[:, tris].reshape(-1, 3)
    del bary
    weights = bernstein(np.array(local))
    full = np.zeros((len(grid), 40))
    for g, k in enumerate(patch):
        full[g, 10 * k:10 * k + 10] = weights[g]
    return Tessellation(level, base_inner + f_count * len(inner), faces, vertex_of, np.array(patch),
                        weights, edge_vertices, full)


SUB_PATCHES = np.array([[0, 3, 5], [3, 1, 4], [5, 4, 2], [3, 4, 5]])  # of a face's 6 points: corners a b c,
# then the midpoints of ab, bc, ca; the corner patches at a, b, c and the middle one


def surface_operator(full_weights):
    """The fine points of a face as one linear map. A PN control point is a fixed combination of
    the patch's corners p_i and of w_ij n_i, w_ij = (p_j - p_i) . n_i, for the directed sides
    (i, j) of the sub-patches: b_ij = (2 p_i + p_j - w_ij n_i) / 3 on the sides, b111 = E + (E -
    V) / 2 inside. So every fine point of a face is op @ [6 points; the w_ij n_i] with op fixed
    by the tessellation. Returns (op (G, 6 + Q), pair firsts I (Q,), pair seconds J (Q,))."""
    pairs = []
    for a, b, c in SUB_PATCHES:
        for i, j in ((a, b), (b, a), (b, c), (c, b), (c, a), (a, c)):
            if (i, j) not in pairs:
                pairs.append((int(i), int(j)))
    q = len(pairs)
    control = np.zeros((4, 10, 6 + q))
    for k, (a, b, c) in enumerate(SUB_PATCHES):
        def side(i, j):
            row = np.zeros(6 + q)
            row[i] += 2.0 / 3.0
            row[j] += 1.0 / 3.0
            row[6 + pairs.index((i, j))] = -1.0 / 3.0
            return row
        rows = [np.eye(6 + q)[a], np.eye(6 + q)[b], np.eye(6 + q)[c],
                side(a, b), side(b, a), side(b, c), side(c, b), side(c, a), side(a, c)]
        e = np.mean(rows[3:9], axis=0)
        v = np.mean(rows[:3], axis=0)
        rows.append(e + (e - v) / 2.0)
        control[k] = rows
    op = full_weights @ control.reshape(40, 6 + q)
    pairs = np.array(pairs)
    return op, pairs[:, 0], pairs[:, 1]


class Smoother:
    """The fine cloth surface from the particles: `surface(x)` -> fine vertices (V, 3)."""

    def __init__(self, mesh, level=2, k_elastic=1.0, normal_control=True, edge_control=True, k_guess=1.0,
                 iterations=8):
        self.mesh, self.k_elastic = mesh, k_elastic
        self.normal_control, self.edge_control = normal_control, edge_control
        self.k_guess, self.iterations = k_guess, iterations
        self.tess = tessellation(mesh, level)
        self.faces = self.tess.faces
        self.vertex_count = self.tess.vertex_count
        self.last = {}
        # everything that depends on the topology alone: the linear map from each face's six
        # points and its w_ij n_i terms to its fine points, indices into [particles; midpoints]
        # of the six points and of the pairs' ends, and one source row per fine vertex
        t, p = self.tess, mesh.particle_count
        self._op, pi, pj = surface_operator(t.full_weights)
        six = np.concatenate([mesh.faces, p + mesh.face_edges], axis=1)  # (F, 6)
        self._six, self._pi, self._pj = six, six[:, pi], six[:, pj]
        f_count, g_count = t.vertex_of.shape
        src = np.empty(self.vertex_count, dtype=np.int64)
        src[t.vertex_of.T.ravel()] = np.arange(g_count * f_count)  # rows of the (G, F) result
        self._src = src[p:]
        self._e0, self._e1 = mesh.edges[:, 0], mesh.edges[:, 1]

    def surface(self, x):
        mesh = self.mesh
        normals = controlled_normals(mesh, x, self.k_elastic, self.normal_control)
        e0, e1 = self._e0, self._e1
        if self.edge_control:
            mid, mid_n, h, short = edge_midpoints(x[e0], normals[e0], x[e1], normals[e1], mesh.rest_length,
                                                  self.k_guess, self.iterations)
        else:
            c1, c2 = edge_controls(x[e0], normals[e0], x[e1], normals[e1])
            mid = cubic_point(x[e0], c1, c2, x[e1], 0.5)
            mid_n = pn_mid_normal(x[e0], normals[e0], x[e1], normals[e1])
            h, short = np.zeros(len(e0)), np.zeros(len(e0), dtype=bool)
        self.last = {"normals": normals, "mid": mid, "mid_normals": mid_n, "h": h, "short": short}
        pts = np.concatenate((x, mid))  # particles, then edge midpoints
        nrm = np.concatenate((normals, mid_n))
        ni = nrm.take(self._pi, axis=0)  # (F, Q, 3)
        d = pts.take(self._pj, axis=0)
        d -= pts.take(self._pi, axis=0)
        ni *= np.einsum("fqj,fqj->fq", d, ni)[..., None]  # w_ij n_i
        terms = np.concatenate((pts.take(self._six, axis=0), ni), axis=1)  # (F, 6 + Q, 3)
        fine = self._op @ terms.transpose(1, 0, 2).reshape(terms.shape[1], -1)  # (G, 3F): one product
        return np.concatenate((x, fine.reshape(-1, 3).take(self._src, axis=0)))  # exactly through the particles

    def edge_curve_lengths(self, x=None):
        """Length of every coarse edge's curve on the last surface (two PN halves), (E,)."""
        mesh, last = self.mesh, self.last
        if x is None:
            raise ValueError("pass the particle positions the last surface was made from")
        e0, e1 = mesh.edges[:, 0], mesh.edges[:, 1]
        n = last["normals"]
        return split_curve_length(x[e0], n[e0], last["mid"], last["mid_normals"], x[e1], n[e1])
