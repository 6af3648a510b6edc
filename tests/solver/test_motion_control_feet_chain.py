"""The position re-solve's feet kinematics (controller._FeetChain): the forward kinematics of the
feet's ancestors alone must give exactly (bit for bit) the feet's frames and legs' Jacobian
columns that the full forward kinematics gives (controller._Loop._leg_jacobians), in the same
memory layout (column-major: the legs' damped least squares take BLAS's same path), since the
control decisions are chaotic in the last bit (test_motion_control_reference.py)."""

import numpy as np
import pytest

from humananim.solver.motion_control import ControlSettings
from humananim.solver.motion_control.controller import _Loop

from test_dynamics_closed_loop_rigs import load


@pytest.fixture(scope="module")
def cmu_loop():
    sk, tr = load("cmu_131_01", frames=60)
    return _Loop(sk, tr, ControlSettings())


@pytest.mark.parametrize("feet", [(True, True), (True, False), (False, True)])
def test_feet_chain_matches_the_full_forward_kinematics_bit_for_bit(cmu_loop, feet):
    loop = cmu_loop
    body = loop.body
    feet = np.array(feet)
    rng = np.random.default_rng(1)
    for f in range(0, loop.tr.frame_count, 7):
        q = loop.tracking.q_d[f].copy()
        # a configuration off the input: every quaternion turned a little
        quats = q[3:].reshape(-1, 4)
        quats += rng.normal(0.0, 0.05, quats.shape)
        quats /= np.linalg.norm(quats, axis=1)[:, None]
        body.data.key = None
        full = loop._leg_jacobians(body, q, feet)
        mine = body.feet_chain.legs(q, feet)
        for s in (0, 1):
            if not feet[s]:
                assert mine[s] is None
                continue
            frame, jac, cols = mine[s]
            assert np.array_equal(frame, full[s][1])
            assert np.array_equal(jac, full[s][3])
            assert np.array_equal(cols, full[s][4])
            assert jac.flags.f_contiguous and full[s][3].strides[0] == jac.strides[0]
