"""Shared scenes for the cloth tests: a sheet, a walking capsule body and a skirt on it."""

import numpy as np

from humananim.solver.cloth import CapsuleBody, MeshBody, build_mesh, capsule_mesh, fit_skirt


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


class SkinnedLegs(MeshBody):
    """The walking capsules as one closed triangle mesh per capsule, re-tessellated every frame
    (a skinned body): a MeshBody with `update(a0, b0, a1, b1)` for the frame's motion."""

    def __init__(self):
        a, b = legs(0.0)
        self.update(a, b, a, b)
        super().__init__(self.tris, len(self.v_end))
        self.set_motion(self.v_start, self.v_end, 1 / 30)

    def update(self, a0, b0, a1, b1):
        self.v_start, self.tris = _capsules_mesh(a0, b0)
        self.v_end, _ = _capsules_mesh(a1, b1)
        if hasattr(self, "parts"):  # after MeshBody.__init__
            self.set_motion(self.v_start, self.v_end, 1 / 30)


def _capsules_mesh(a, b):
    vs, ts, n = [], [], 0
    for k in range(len(RADII)):
        v, t = capsule_mesh(a[k], b[k], RADII[k], segments=20, rings=24)
        vs.append(v), ts.append(t + n)
        n += len(v)
    return np.vstack(vs), np.vstack(ts)


def walk(sim, pin0, capsules, bodies, frames):
    """Step `sim` through `frames` frames of the walking legs at 30 fps, the capsules and any
    skinned body following them; yields each frame's capsule ends (a, b) after its step."""
    a0, b0 = legs(0.0)
    for f in range(1, frames + 1):
        a1, b1 = legs(f / 30.0)
        capsules.set_motion(a0, b0, a1, b1, 1 / 30)
        for body in bodies:
            if body is not capsules:
                body.update(a0, b0, a1, b1)
        sim.step(pin0, 1 / 30)
        yield a1, b1
        a0, b0 = a1, b1
