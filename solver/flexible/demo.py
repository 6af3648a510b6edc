"""The thesis's table (Fig. 1.2, 4.3) in 3-D: a box lattice with shear, bend, squash and
horizontal squash modes, and the rod of appendix A."""

import numpy as np

from .body import FlexibleBody
from .ffd import grid_points

TABLE_DIMS = (4, 2, 4)
TABLE_SIZE = (1.0, 0.5, 0.6)          # length (x, forward), depth (y), height (z) in metres
TABLE_MODES = ("shear", "bend", "squash", "hsquash")


def table_lattice(size=TABLE_SIZE, dims=TABLE_DIMS):
    """Rest lattice points (centred on the origin, Blender order) and the mode offsets."""
    size = np.asarray(size, float)
    rest = grid_points(dims, size, -0.5 * size)
    nu, nv, nw = dims
    w, v, u = np.meshgrid(np.linspace(0, 1, nw), np.linspace(0, 1, nv), np.linspace(0, 1, nu), indexing="ij")
    u, w = u.ravel(), w.ravel()
    L, H = size[0], size[2]
    modes = {
        # the top slides forward over the feet
        "shear": np.stack([0.35 * L * w, 0 * u, 0 * u], 1),
        # the table arches: the middle of the top rises, the legs splay (Fig. 4.1)
        "bend": np.stack([0.25 * L * (u - 0.5) * (1 - w), 0 * u, 0.35 * H * (1 - (2 * u - 1) ** 2)], 1),
        # the top comes down towards the feet
        "squash": np.stack([0 * u, 0 * u, -0.4 * H * w], 1),
        # the table gets longer
        "hsquash": np.stack([0.3 * L * (u - 0.5), 0 * u, 0 * u], 1),
    }
    return rest, modes


def table_points(size=TABLE_SIZE, count=11):
    """Body-frame sample points of a table: four feet, four top corners and points along the top
    (11 by default, as the thesis's Fig. 4.3)."""
    L, D, H = size
    feet = [(sx * L / 2, sy * D / 2, -H / 2) for sx in (-1, 1) for sy in (-1, 1)]
    corners = [(sx * L / 2, sy * D / 2, H / 2) for sx in (-1, 1) for sy in (-1, 1)]
    extra = count - 8
    if extra < 0:
        raise ValueError("a table needs at least 8 points")
    top = [(x, 0.0, H / 2) for x in np.linspace(-L / 2, L / 2, extra + 2)[1:-1]]
    return np.array(feet + corners + top, float)


def table_body(mass=20.0, count=11, modes=TABLE_MODES, size=TABLE_SIZE):
    rest, offsets = table_lattice(size)
    points = table_points(size, count)
    body = FlexibleBody.from_points(TABLE_DIMS, rest, [offsets[m] for m in modes], list(modes),
                                    points, np.full(len(points), mass / len(points)))
    return body


def blob_body(points=200, modes=8, mass=30.0, seed=0):
    """A 200-point, 8-mode character for the benchmark: points in a 4x4x4 lattice box, smooth
    random modes (low-order polynomial fields, so they are independent)."""
    rng = np.random.default_rng(seed)
    dims = (4, 4, 4)
    size = np.array([1.0, 0.8, 0.8])
    rest = grid_points(dims, size, -0.5 * size)
    uvw = (rest + 0.5 * size) / size
    basis = [uvw[:, 0], uvw[:, 1], uvw[:, 2], uvw[:, 0] * uvw[:, 2], uvw[:, 1] * uvw[:, 2],
             uvw[:, 0] ** 2, uvw[:, 2] ** 2, uvw[:, 0] * uvw[:, 1]]
    offsets = []
    for k in range(modes):
        f = basis[k % len(basis)] - basis[k % len(basis)].mean()
        axis = k % 3
        d = np.zeros_like(rest)
        d[:, axis] = 0.2 * f
        d[:, (axis + 1) % 3] += 0.05 * f * rng.uniform(-1, 1)
        offsets.append(d)
    pts = rng.uniform(0.05, 0.95, (points, 3))
    return FlexibleBody(dims, rest, offsets, [f"mode{k + 1}" for k in range(modes)], pts,
                        np.full(points, mass / points))


def rod_body(mass=50.0, C=-0.1, xs=(0.0, 1.0), ly=0.5, spacing=0.3):
    """Appendix A: two equal point masses in a 4x1x4 lattice (the thesis's 4x4 in the x-z
    plane), one mode d_z = C * i (i the lattice index along x)."""
    dims = (4, 1, 4)
    rest = grid_points(dims, (3 * spacing, 0.0, 3 * spacing))
    d = np.zeros_like(rest)
    i = np.tile(np.arange(4), 4)
    d[:, 2] = C * i
    uvw = np.array([[xs[0], 0.5, ly], [xs[1], 0.5, ly]])
    return FlexibleBody(dims, rest, [d], ["a"], uvw, np.full(2, mass))
