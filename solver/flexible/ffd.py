"""Free-form deformation bases (thesis eq. 4.1): Bernstein polynomials for up to four lattice
points per axis, as in the thesis, and clamped uniform cubic B-splines for larger lattices (C2,
convex hull kept because the clamped basis is a partition of unity with non-negative weights)."""

from math import comb

import numpy as np

BERNSTEIN_MAX_POINTS = 4


def bernstein(count, s):
    """(len(s), count) weights of the degree count-1 Bernstein basis at parameters s in [0, 1]."""
    s = np.clip(np.asarray(s, float), 0.0, 1.0)[:, None]
    n = count - 1
    i = np.arange(count)[None, :]
    coeff = np.array([comb(n, k) for k in range(count)], float)[None, :]
    return coeff * (1.0 - s) ** (n - i) * s ** i


def bspline(count, s, degree=3):
    """(len(s), count) weights of a clamped uniform B-spline basis (Cox-de Boor)."""
    s = np.clip(np.asarray(s, float), 0.0, 1.0)
    p = min(degree, count - 1)
    inner = np.linspace(0.0, 1.0, count - p + 1)
    knots = np.concatenate([np.zeros(p), inner, np.ones(p)])
    # degree 0: the span that holds s (the last span is closed at 1)
    basis = np.zeros((len(s), len(knots) - 1))
    span = np.searchsorted(knots, s, side="right") - 1
    span = np.clip(span, p, count - 1)
    basis[np.arange(len(s)), span] = 1.0
    for d in range(1, p + 1):
        new = np.zeros((len(s), len(knots) - 1 - d))
        for i in range(len(knots) - 1 - d):
            left = knots[i + d] - knots[i]
            right = knots[i + d + 1] - knots[i + 1]
            if left > 0:
                new[:, i] += (s - knots[i]) / left * basis[:, i]
            if right > 0:
                new[:, i] += (knots[i + d + 1] - s) / right * basis[:, i + 1]
        basis = new
    return basis[:, :count]


def axis_basis(count, s):
    if count <= BERNSTEIN_MAX_POINTS:
        return bernstein(count, s)
    return bspline(count, s)


def basis_name(dims):
    return "Bernstein" if max(dims) <= BERNSTEIN_MAX_POINTS else "cubic B-spline (Bernstein on axes of <= 4 points)"


def lattice_weights(uvw, dims):
    """(P, nu*nv*nw) tensor-product weights of points at lattice parameters uvw (P, 3) in [0, 1]^3.

    Lattice points are ordered as in Blender: index = u + nu * (v + nv * w)."""
    uvw = np.atleast_2d(np.asarray(uvw, float))
    nu, nv, nw = dims
    bu, bv, bw = (axis_basis(n, uvw[:, k]) for k, n in enumerate(dims))
    w = bw[:, :, None, None] * bv[:, None, :, None] * bu[:, None, None, :]
    return w.reshape(len(uvw), nu * nv * nw)


def grid_points(dims, size=(1.0, 1.0, 1.0), origin=(0.0, 0.0, 0.0)):
    """(nu*nv*nw, 3) evenly spaced lattice points, Blender order, spanning `size` from `origin`."""
    nu, nv, nw = dims
    axes = [np.linspace(0.0, 1.0, n) if n > 1 else np.array([0.5]) for n in dims]
    w, v, u = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
    uvw = np.stack([u.ravel(), v.ravel(), w.ravel()], axis=1)
    return np.asarray(origin, float) + uvw * np.asarray(size, float)


def lattice_params(points, rest, dims=None):
    """Lattice parameters of points (in the lattice's frame), so that the rest lattice's FFD
    maps them back onto themselves. Along each axis the rest FFD is the 1-D map
    s -> sum_i B_i(s) x_i of the lattice's coordinates on that axis: the identity (scaled) for
    Bernstein bases on even spacing, but not for clamped B-splines, so it is inverted numerically
    (it is monotone)."""
    points = np.atleast_2d(np.asarray(points, float))
    rest = np.asarray(rest, float)
    lo, hi = rest.min(axis=0), rest.max(axis=0)
    span = np.where(hi - lo > 1e-12, hi - lo, 1.0)
    out = (points - lo) / span
    if dims is None:
        return out
    grid = rest.reshape(dims[2], dims[1], dims[0], 3)
    for axis, count in enumerate(dims):
        if count <= BERNSTEIN_MAX_POINTS or hi[axis] - lo[axis] <= 1e-12:
            continue
        coords = np.moveaxis(grid[..., axis], 2 - axis, 0).reshape(count, -1).mean(axis=1)
        s = np.linspace(0.0, 1.0, 4001)
        f = axis_basis(count, s) @ coords
        out[:, axis] = np.interp(points[:, axis], f, s)
    return out
