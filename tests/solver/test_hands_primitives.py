"""Primitive fitting by principal axes and volume, and the primitives' signed distances."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from hands_cases import frame
from humananim.solver.hands.primitives import (Box, Cylinder, Frustum, Sphere, fit_primitive, kind, mesh_of,
                                               mesh_volume, prim_volume)

ROT = Rotation.from_rotvec([0.3, -0.5, 0.8]).as_matrix()


@pytest.mark.parametrize("shape", [
    Sphere(np.array([0.1, 0.2, 0.3]), 0.05),
    Box(frame([0, 0.1, 1], ROT), np.array([0.02, 0.05, 0.09])),
    Cylinder(frame([0.3, 0, 1], ROT), 0.03, 0.12),
    Frustum(frame([0.3, 0, 1], ROT), 0.05, 0.02, 0.08),
], ids=kind)
def test_fit_recovers_the_primitive(shape):
    v, t = mesh_of(shape, segments=48)
    fit = fit_primitive(v, t)
    assert kind(fit) == kind(shape)
    assert prim_volume(fit) == pytest.approx(mesh_volume(v, t), rel=0.08)
    centre = fit.centre if isinstance(fit, Sphere) else fit.frame[:3, 3]
    want = shape.centre if isinstance(shape, Sphere) else shape.frame[:3, 3]
    assert np.allclose(centre, want, atol=0.004)
    # the fit bounds the mesh
    assert np.all(fit.distance(v) < 1e-6)


def test_frustum_distance():
    f = Frustum(frame([0, 0, 0]), 0.05, 0.02, 0.1)
    assert f.distance(np.array([0.0, 0, 0])) < 0
    assert f.distance(np.array([0.0, 0, 0.15])) == pytest.approx(0.05)
    assert f.distance(np.array([0.05, 0, -0.1])) == pytest.approx(0.0, abs=1e-9)
    assert f.distance(np.array([0.10, 0, -0.1])) == pytest.approx(0.05, abs=1e-9)
    c = Cylinder(frame([0, 0, 0]), 0.03, 0.1)
    assert c.distance(np.array([0.05, 0, 0])) == pytest.approx(0.02)
    assert c.distance(np.array([0.0, 0, 0])) == pytest.approx(-0.03)
