"""The ground the feet are put on: a flat floor at a height, a height field (a grid of heights,
bilinear between its points) or a triangle mesh (the highest surface under each point, found by
a vertical ray). Each answers `height(xy)`: world Z of the ground under points (..., 2), NaN where
there is no ground (off the mesh or the grid). Metres, Z up."""

import numpy as np


class Flat:
    def __init__(self, z=0.0):
        self.z = float(z)

    def height(self, xy):
        return np.full(np.shape(xy)[:-1], self.z)

    def describe(self):
        return {"kind": "flat", "height_m": self.z}


class HeightField:
    """heights (ny, nx) at x = origin[0] + i * cell, y = origin[1] + j * cell (row j, column i)."""

    def __init__(self, heights, origin=(0.0, 0.0), cell=1.0):
        self.heights = np.asarray(heights, float)
        if self.heights.ndim != 2 or min(self.heights.shape) < 2 or not np.isfinite(self.heights).all():
            raise ValueError("a height field needs a finite grid of at least 2 x 2 heights")
        if not (np.isfinite(cell) and cell > 0):
            raise ValueError("a height field's cell size must be positive")
        self.origin = np.asarray(origin, float)
        self.cell = float(cell)

    def height(self, xy):
        xy = np.asarray(xy, float)
        ny, nx = self.heights.shape
        u = (xy[..., 0] - self.origin[0]) / self.cell
        v = (xy[..., 1] - self.origin[1]) / self.cell
        inside = (u >= 0) & (u <= nx - 1) & (v >= 0) & (v <= ny - 1)
        i = np.clip(np.floor(u).astype(int), 0, nx - 2)
        j = np.clip(np.floor(v).astype(int), 0, ny - 2)
        s, t = np.clip(u - i, 0, 1), np.clip(v - j, 0, 1)
        h = self.heights
        z = ((1 - s) * (1 - t) * h[j, i] + s * (1 - t) * h[j, i + 1]
             + (1 - s) * t * h[j + 1, i] + s * t * h[j + 1, i + 1])
        return np.where(inside, z, np.nan)

    def describe(self):
        return {"kind": "heightfield", "shape": list(self.heights.shape), "cell_m": self.cell,
                "origin_m": self.origin.tolist()}


class TriangleMesh:
    """vertices (V, 3), triangles (T, 3) vertex indices. Faces standing vertical are ignored."""

    CHUNK = 200_000  # point-triangle pairs tested at once

    def __init__(self, vertices, triangles):
        v = np.asarray(vertices, float)
        t = np.asarray(triangles, int)
        if v.ndim != 2 or v.shape[1] != 3 or t.ndim != 2 or t.shape[1] != 3 or not len(t):
            raise ValueError("a ground mesh needs vertices (V, 3) and at least one triangle")
        if not np.isfinite(v).all() or t.min() < 0 or t.max() >= len(v):
            raise ValueError("the ground mesh has non-finite vertices or faces pointing past its vertices")
        tri = v[t]
        a, b, c = tri[:, 0, :2], tri[:, 1, :2], tri[:, 2, :2]
        area = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])
        keep = np.abs(area) > 1e-12
        if not keep.any():
            raise ValueError("the ground mesh has no face that is not vertical")
        self.tri, self.area = tri[keep], area[keep]
        self.lo, self.hi = self.tri[..., :2].min(axis=1), self.tri[..., :2].max(axis=1)

    def height(self, xy):
        xy = np.asarray(xy, float)
        flat = xy.reshape(-1, 2)
        out = np.full(len(flat), -np.inf)
        step = max(1, self.CHUNK // len(self.tri))
        for s in range(0, len(flat), step):
            p = flat[s:s + step, None, :]  # (n, 1, 2) against (T, ...)
            near = np.all((p >= self.lo - 1e-9) & (p <= self.hi + 1e-9), axis=-1)
            if not near.any():
                continue
            n_idx, t_idx = np.nonzero(near)
            q, tri, area = flat[s + n_idx], self.tri[t_idx], self.area[t_idx]
            a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
            w1 = ((b[:, 0] - q[:, 0]) * (c[:, 1] - q[:, 1]) - (c[:, 0] - q[:, 0]) * (b[:, 1] - q[:, 1])) / area
            w2 = ((c[:, 0] - q[:, 0]) * (a[:, 1] - q[:, 1]) - (a[:, 0] - q[:, 0]) * (c[:, 1] - q[:, 1])) / area
            w3 = 1.0 - w1 - w2
            hit = (w1 >= -1e-9) & (w2 >= -1e-9) & (w3 >= -1e-9)
            z = w1 * a[:, 2] + w2 * b[:, 2] + w3 * c[:, 2]
            np.maximum.at(out, s + n_idx[hit], z[hit])  # the top surface where faces overlap
        out[~np.isfinite(out)] = np.nan
        return out.reshape(xy.shape[:-1])

    def describe(self):
        return {"kind": "mesh", "triangles": int(len(self.tri)),
                "bounds_m": [self.lo.min(axis=0).tolist(), self.hi.max(axis=0).tolist()]}


def read_obj(path):
    """A Wavefront OBJ's vertices and faces (fans of triangles), in the file's axes: Blender's
    OBJ exporter writes Y up by default, so (x, y, z) in the file is (x, -z, y) in Blender
    (`y_up=True`); pass y_up=False for a file written Z up."""
    verts, faces = [], []
    with open(path, encoding="utf-8", errors="replace") as f:
        for line in f:
            parts = line.split()
            if not parts:
                continue
            if parts[0] == "v" and len(parts) >= 4:
                verts.append([float(x) for x in parts[1:4]])
            elif parts[0] == "f" and len(parts) >= 4:
                idx = [int(p.split("/")[0]) for p in parts[1:]]
                idx = [i - 1 if i > 0 else len(verts) + i for i in idx]
                faces += [[idx[0], idx[k], idx[k + 1]] for k in range(1, len(idx) - 1)]
    if not verts or not faces:
        raise ValueError(f"{path}: no vertices or faces")
    return np.array(verts, float), np.array(faces, int)


def load(path, y_up=True, cell=None, origin=(0.0, 0.0)):
    """A ground from a file: .obj (a mesh), .npz (a height field: arrays `heights`, `cell`,
    optional `origin`), .npy/.csv/.txt (a grid of heights, needing `cell`)."""
    path = str(path)
    low = path.lower()
    if low.endswith(".obj"):
        v, f = read_obj(path)
        if y_up:
            v = np.stack((v[:, 0], -v[:, 2], v[:, 1]), axis=1)
        return TriangleMesh(v, f)
    if low.endswith(".npz"):
        with np.load(path) as data:
            if "heights" not in data or "cell" not in data:
                raise ValueError(f"{path}: a height field .npz needs arrays 'heights' and 'cell'")
            org = data["origin"] if "origin" in data else origin
            return HeightField(data["heights"], org, float(data["cell"]))
    if low.endswith((".npy", ".csv", ".txt")):
        if cell is None:
            raise ValueError(f"{path}: a grid of heights needs its cell size")
        grid = np.load(path) if low.endswith(".npy") else np.loadtxt(path, delimiter="," if low.endswith(".csv") else None)
        return HeightField(grid, origin, cell)
    raise ValueError(f"{path}: a ground is an .obj mesh or a height field (.npz, .npy, .csv, .txt)")


def as_ground(value):
    """A ground from a height (flat floor), None, or a ground object."""
    if value is None or hasattr(value, "height"):
        return value
    return Flat(value)
