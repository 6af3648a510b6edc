"""The cloth's private numpy/scipy entry points (solver/cloth/fast.py: c_einsum, the clip ufunc,
scipy's csr_matvecs) have public fallbacks: with HUMANANIM_PUBLIC_NUMPY=1 only the public API is
used, and a walking skirt on capsules comes out the same (run on numpy 1.26 and 2 by CI)."""

import os
import subprocess
import sys

import numpy as np

SCRIPT = """
import sys
import numpy as np
sys.path.insert(0, sys.argv[1])
from cloth_scenes import legs, walking_skirt
from humananim.solver.cloth import ClothSimulation, preset
from humananim.solver.cloth import fast
mesh, pinned, body = walking_skirt()
sim = ClothSimulation(mesh, preset("COTTON"), pinned, [body], level=2)
prev = legs(0.0)
for k in range(1, 16):
    now = legs(k / 30.0)
    body.set_motion(*prev, *now, dt=1 / 30.0)
    sim.step(sim.x[sim.pins], 1 / 30.0)
    prev = now
fine = sim.surface()
np.save(sys.argv[2], np.concatenate([sim.x, fine]))
print(fast.PUBLIC_ONLY, fast._c_einsum is np.einsum, fast._csr_matvecs is None, fast.clip is np.clip)
"""


def run(tmp_path, public):
    out = tmp_path / f"x{public}.npy"
    env = dict(os.environ, HUMANANIM_PUBLIC_NUMPY="1" if public else "0")
    r = subprocess.run([sys.executable, "-c", SCRIPT, os.path.dirname(__file__), str(out)], env=env,
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    return np.load(out), r.stdout.split()


def test_public_fallbacks_give_the_same_cloth(tmp_path):
    private, flags_private = run(tmp_path, False)
    public, flags_public = run(tmp_path, True)
    assert flags_public == ["True", "True", "True", "True"]  # only the public API
    assert flags_private[0] == "False"
    assert np.isfinite(public).all() and np.abs(public - private).max() < 1e-6  # metres (rounding order)
