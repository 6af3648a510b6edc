"""The procedural skirt (Oshita 2003 §4.5): rings of particles around the hips and thighs, the
top ring (the waistband) pinned; sized from a skeleton's pelvis and thighs so it fits any rig."""

import numpy as np

from .collision import query_bodies


def skirt_mesh(centre, lateral, up, heights, radii, columns=11, depth_ratio=0.85):
    """Rings at `heights` (R,) along `up` from `centre` with radii (R,) across `lateral` (and
    depth_ratio times that front to back): positions (R * columns, 3), triangles with normals
    pointing out, and the indices of the top ring."""
    up = np.asarray(up, float) / np.linalg.norm(up)
    lateral = np.asarray(lateral, float) - np.dot(lateral, up) * up
    lateral /= np.linalg.norm(lateral)
    forward = np.cross(up, lateral)
    ang = np.linspace(0.0, 2 * np.pi, columns, endpoint=False)
    rings = len(heights)
    pos = np.empty((rings, columns, 3))
    for r in range(rings):
        pos[r] = (np.asarray(centre, float) + heights[r] * up + radii[r] * np.cos(ang)[:, None] * lateral
                  + depth_ratio * radii[r] * np.sin(ang)[:, None] * forward)
    idx = np.arange(rings * columns).reshape(rings, columns)
    faces = []
    for r in range(rings - 1):
        for c in range(columns):
            a, b = idx[r, c], idx[r, (c + 1) % columns]
            d, e = idx[r + 1, c], idx[r + 1, (c + 1) % columns]
            if (r + c) % 2 == 0:  # alternate the diagonals: no handedness in the drape
                faces += [(a, d, e), (a, e, b)]
            else:
                faces += [(a, d, b), (b, d, e)]
    pos, faces = pos.reshape(-1, 3), np.array(faces)
    n = np.cross(pos[faces[:, 1]] - pos[faces[:, 0]], pos[faces[:, 2]] - pos[faces[:, 0]])
    out = pos[faces].mean(axis=1) - np.asarray(centre, float)
    out -= np.outer(out @ up, up)
    if np.sum(np.einsum("ij,ij->i", n, out)) < 0:
        faces = faces[:, ::-1].copy()
    return pos, faces, idx[0].copy()


def needed_radius(centre, lateral, up, height, bodies, clearance, columns, depth_ratio, r_min, r_max=1.5):
    """Smallest ring radius (5 mm steps) from which on every wider ring is `clearance` outside
    the bodies (so a ring goes round the legs, never between them)."""
    radii = np.arange(r_min, r_max, 0.005)
    up = np.asarray(up, float) / np.linalg.norm(up)
    lat = np.asarray(lateral, float) - np.dot(lateral, up) * up
    lat /= np.linalg.norm(lat)
    fwd = np.cross(up, lat)
    ang = np.linspace(0.0, 2 * np.pi, columns, endpoint=False)
    ring = np.cos(ang)[:, None] * lat + depth_ratio * np.sin(ang)[:, None] * fwd
    pts = (np.asarray(centre, float) + height * up)[None, None] + radii[:, None, None] * ring[None]
    phi, _, _ = query_bodies(bodies, pts.reshape(-1, 3), 1.0)
    ok = (phi.reshape(len(radii), columns) >= clearance).all(axis=1)
    if ok.all():
        return float(r_min)
    last_bad = len(ok) - 1 - np.argmax(~ok[::-1])
    return float(radii[last_bad + 1]) if last_bad + 1 < len(radii) else float(r_max)


def fit_skirt(thigh_heads, knees, up=(0.0, 0.0, 1.0), bodies=(), rings=6, columns=11, length=0.9,
              waist=0.25, flare=1.3, clearance=0.02, depth_ratio=0.85):
    """A skirt for a posed skeleton: waistband `waist` thigh lengths above the hip joints, hem
    `length` thigh lengths below them, each ring wide enough to clear the bodies (capsules at
    that pose) by `clearance`, the hem flared by `flare`. Returns (positions, faces, pinned)."""
    thigh_heads, knees, up = np.asarray(thigh_heads, float), np.asarray(knees, float), np.asarray(up, float)
    up = up / np.linalg.norm(up)
    thigh = float(np.mean(np.linalg.norm(knees - thigh_heads, axis=1)))
    centre = thigh_heads.mean(axis=0)
    lateral = thigh_heads[0] - thigh_heads[1]
    if np.linalg.norm(lateral - np.dot(lateral, up) * up) < 1e-6:
        lateral = np.cross(up, [0.0, 1.0, 0.0]) if abs(up[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    heights = np.linspace(waist * thigh, -length * thigh, rings)
    half_hips = 0.5 * np.linalg.norm(thigh_heads[0] - thigh_heads[1])
    base = max(half_hips + 0.15 * thigh, 0.05)  # never narrower than the hips
    radii = np.empty(rings)
    for r, h in enumerate(heights):
        radii[r] = (needed_radius(centre, lateral, up, h, bodies, clearance, columns, depth_ratio, base)
                    if bodies else base)
    waist_r = radii[0]
    hem_r = max(radii[-1], waist_r) * flare
    t = np.linspace(0.0, 1.0, rings)
    radii = np.maximum(radii, waist_r + (hem_r - waist_r) * t)
    radii[-1] = max(radii[-1], hem_r)
    return skirt_mesh(centre, lateral, up, heights, radii, columns, depth_ratio)
