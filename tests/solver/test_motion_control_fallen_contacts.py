"""The fallen body's ground contacts with the product's projected Gauss-Seidel (contact blocks on
plain floats, projections by comparisons) against the same sweeps as they were written before
(max/min calls, the impulses read back from the array: previous_pgs below) and against the
textbook PGS, row by row (benchmarks/microopt.py, pgs_plain), on the CMU walk knocked over by a
150 N s push sideways (benchmarks/control.py's cmu_knocked_over, a fallen body on the ground for
most of the bake): the same fall, every joint within 1 deg of the previous code at every frame,
the pelvis within 1 cm of both, and no body point deeper below the ground than with either.

A fallen body is sensitive to its contacts' last bits: the textbook sweeps, the same arithmetic in
another order, turn the left ankle 40 deg away on numpy 2 late in the fall (0.5 deg on numpy
1.26), so the joints are held to the previous code's sweeps, whose order the product keeps."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from humananim.solver.motion_control import Impulse, collisions, control
from humananim.solver.motion_control.controller import ControlSettings

from test_dynamics_closed_loop_rigs import load
from test_motion_control_ground import depth_below_ground

BENCHMARKS = Path(__file__).resolve().parents[2] / "benchmarks"


@pytest.fixture(scope="module")
def textbook_pgs():
    spec = importlib.util.spec_from_file_location("benchmarks_microopt", BENCHMARKS / "microopt.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.pgs_plain


def previous_pgs(w, rel, targets, mu, iterations):
    """collisions.pgs before the fallen body's speed-up (commit fe71bd7): the reference."""
    n = len(targets)
    p = np.zeros(3 * n)
    rows = [w[3 * c:3 * c + 3] for c in range(n)]
    blocks = [w[3 * c:3 * c + 3, 3 * c:3 * c + 3].tolist() for c in range(n)]
    rel_rows = [rel[3 * c:3 * c + 3] for c in range(n)]
    targets = np.asarray(targets, float).tolist()
    for _ in range(iterations):
        change = 0.0
        for c in range(n):
            i = 3 * c
            u0, u1, u2 = (rel_rows[c] + rows[c] @ p).tolist()
            pn, p1, p2 = old = p[i:i + 3].tolist()
            (d0, _, _), (w10, d1, _), (w20, w21, d2) = blocks[c]
            new = max(0.0, pn + (targets[c] - u0) / d0)
            dp = new - pn
            if dp:
                pn = new
                u1 += w10 * dp
                u2 += w20 * dp
                change = max(change, abs(dp))
            cap = mu * pn
            new = min(max(p1 - u1 / d1, -cap), cap)
            dp = new - p1
            if dp:
                p1 = new
                u2 += w21 * dp
                change = max(change, abs(dp))
            new = min(max(p2 - u2 / d2, -cap), cap)
            dp = new - p2
            if dp:
                p2 = new
                change = max(change, abs(dp))
            if [pn, p1, p2] != old:
                p[i:i + 3] = pn, p1, p2
        if change < 1e-7:
            break
    return p


def joint_angles_between(a, b):
    """(F, J) degrees between two motions' joint rotations (unit quaternions, either sign)."""
    dot = np.abs(np.einsum("fjk,fjk->fj", a.rotations, b.rotations))
    return np.degrees(2.0 * np.arccos(np.clip(dot, 0.0, 1.0)))


def test_knocked_over_bake_falls_as_with_the_textbook_contact_solver(textbook_pgs, monkeypatch):
    sk, tr = load("cmu_131_01")
    chest = sk.roles.chain("spine")[-1]
    settings = ControlSettings(impulses=(Impulse(0.5, chest, (0.0, 0.1, 0.0), (0.0, 1.0, 0.0), 150.0),))
    product = control(sk, tr, settings)
    monkeypatch.setattr(collisions, "pgs", previous_pgs)
    previous = control(sk, tr, settings)
    monkeypatch.setattr(collisions, "pgs", textbook_pgs)
    textbook = control(sk, tr, settings)
    assert product.falling.sum() > 100  # on the ground for most of the bake
    depth = depth_below_ground(sk, product.trajectories, product.ground_height).max()
    assert depth < 0.01
    for other in (previous, textbook):
        assert np.array_equal(product.falling, other.falling)
        pelvis = product.trajectories.translations[:, 0] - other.trajectories.translations[:, 0]
        assert np.linalg.norm(pelvis, axis=-1).max() < 0.01
        assert depth <= depth_below_ground(sk, other.trajectories, other.ground_height).max() + 1e-3
    assert joint_angles_between(product.trajectories, previous.trajectories).max() < 1.0
