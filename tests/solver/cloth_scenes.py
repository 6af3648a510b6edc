"""Shared scenes for the cloth tests: a sheet, a walking capsule body and a skirt on it."""

import numpy as np

from humananim.solver.cloth import CapsuleBody, build_mesh, fit_skirt


def sheet(nx=6, ny=6, size=0.5, z=1.0):
    xs, ys = np.meshgrid(np.linspace(0, size, nx), np.linspace(0, size, ny))
    pos = np.column_stack([xs.ravel(), ys.ravel(), np.full(xs.size, z)])
    idx = np.arange(nx * ny).reshape(ny, nx)
    faces = []
    for j in range(ny - 1):
        for i in range(nx - 1):
            a, b, c, d = idx[j, i], idx[j, i + 1], idx[j + 1, i + 1], idx[j + 1, i]
            faces += [(a, b, c), (a, c, d)]
    return pos, np.array(faces)


RADII = np.array([0.088, 0.071, 0.071, 0.11, 0.046, 0.046])


def legs(t, stride=0.5, speed=0.0):
    """A walking lower body at time t: capsule ends (hips, thighs, torso, shins)."""
    root = np.array([0.0, speed * t, 0.0])
    hip_l, hip_r = np.array([0.08, 0, 0.9]) + root, np.array([-0.08, 0, 0.9]) + root
    a = stride * np.sin(2 * np.pi * t)
    dl, dr = np.array([0, np.sin(a), -np.cos(a)]), np.array([0, -np.sin(a), -np.cos(a)])
    knee_l, knee_r = hip_l + 0.42 * dl, hip_r + 0.42 * dr
    b = max(0.0, a)
    foot_l = knee_l + 0.4 * np.array([0, -np.sin(0.8 * b), -np.cos(0.8 * b)])
    foot_r = knee_r + 0.4 * np.array([0, -np.sin(0.8 * max(0.0, -a)), -np.cos(0.8 * max(0.0, -a))])
    a_ = np.array([hip_l, hip_l, hip_r, root + [0, 0, 0.95], knee_l, knee_r])
    b_ = np.array([hip_r, knee_l, knee_r, root + [0, 0, 1.4], foot_l, foot_r])
    return a_, b_


def walking_skirt(**kw):
    body = CapsuleBody(RADII)
    a, b = legs(0.0)
    body.set_motion(a, b)
    pos, faces, pinned = fit_skirt(np.array([a[1], a[2]]), np.array([b[1], b[2]]), bodies=[body], **kw)
    return build_mesh(pos, faces), pinned, body
