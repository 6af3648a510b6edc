#!/usr/bin/env python3
"""Does each micro-optimisation in solver/ earn its place? The time of the capability it serves,
with the trick beside the same capability with the plain, readable formula instead.

    python3 benchmarks/microopt.py                 # a table
    python3 benchmarks/microopt.py --json          # one JSON object (also benchmarks/results/microopt.json)
    python3 benchmarks/microopt.py --rounds 9      # alternating rounds per trick (default 5)
    python3 benchmarks/microopt.py --only cloth    # the tricks whose name or capability contains this
                                                   # (several: --only cloth_product,feet_dls)

With --json and --only, the rows measured are merged by trick name into the committed
benchmarks/results/microopt.json (the others keep theirs; its `runs` says which run measured which).

The rule (docs/physics.md, the developers' guide): a trick stays in product code only where it
saves at least 5 % of its capability's time, with a comment naming the plain formula; otherwise
the plain formula is the product code. This file holds both versions of every trick it judges
(the trick and the plain one), so it measures the same pair whichever of the two the product
code holds: per trick, every module attribute or method that holds the product's version is
set to the trick's, then to the plain one's, in turn.

What is timed is the capability, not the kernel: CPU time (time.process_time: the machine is
shared) of
- Dynamic Control: bakes of benchmarks/control.py's cases figure_15kg (comfort control acting)
  and cmu (the CMU walk 131_01, dynamic control on about a third of the steps, a few frames out
  of balance, so the falling rotation too);
- contacts (Dynamic Control with contact impulses): bakes of benchmarks/control.py's case
  cmu_knocked_over (the fallen body's ground contacts) and of the thesis's punch (a 6 kg fist, a
  finite-mass collider, at 4 m/s into the metarig standing still);
- grasp: complete grasps (solver.hands.grasp.grasp) of every fifth object of benchmarks/grasp.py's
  cases on the Rigify metarig;
- flexible: benchmarks/flexible.py's thesis workload (the 11-point table under pose control,
  1,200 steps), semi-implicit and implicit-midpoint integrators;
- cloth: the solver alone (no Blender): the thesis-size skirt (66 particles, smoothing level 2) on
  the tests' walking capsule legs (tests/solver/cloth_scenes.py), 60 frames at 30 fps.
Each round times the whole workload with the trick and with the plain version, unit by unit (one
bake, one grasp, one simulation with each version in turn, the order alternating from unit to
unit), so a swing of the machine's load falls on both; the figure per trick is the median over
the rounds of (time with the trick / time with the plain version), with the smallest and largest
round's ratio as its spread. saving = 1 - that median.
"""

import argparse
import importlib
import inspect
import math
import statistics
import textwrap
import sys
import time
from pathlib import Path

import numpy as np
from scipy.linalg import cho_factor, cho_solve, lapack

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests" / "solver"))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from machine import claim, emit, result  # noqa: E402

# (modules by import_module: the motion_control package's names balance_control and
# comfort_control are functions)
cloth_dynamics = importlib.import_module("humananim.solver.cloth.dynamics")
cloth_fast = importlib.import_module("humananim.solver.cloth.fast")
importlib.import_module("humananim.solver.cloth.collision")  # its imports are patched too
importlib.import_module("humananim.solver.cloth.smoothing")
vectors = importlib.import_module("humananim.solver.vectors")
dynamics_model = importlib.import_module("humananim.solver.dynamics.model")
inverse_dynamics = importlib.import_module("humananim.solver.dynamics.inverse_dynamics")
flexible_kernel = importlib.import_module("humananim.solver.flexible.kernel")
ik = importlib.import_module("humananim.solver.hands.ik")
balance_control = importlib.import_module("humananim.solver.motion_control.balance_control")
comfort_control = importlib.import_module("humananim.solver.motion_control.comfort_control")
feet = importlib.import_module("humananim.solver.motion_control.feet")
importlib.import_module("humananim.solver.motion_control.controller")  # its imports are patched too
importlib.import_module("humananim.solver.hands.grasp")
sensors = importlib.import_module("humananim.solver.hands.sensors")
tracking = importlib.import_module("humananim.solver.motion_control.tracking")
kinematics = importlib.import_module("humananim.solver.dynamics.kinematics")
inertia_matrix = importlib.import_module("humananim.solver.dynamics.inertia_matrix")
dynamics_balance = importlib.import_module("humananim.solver.dynamics.balance")
importlib.import_module("humananim.solver.motion_control.falling")  # its imports are patched too
collisions = importlib.import_module("humananim.solver.motion_control.collisions")

AIM = 0.05  # a trick must save at least this share of its capability's time
ONES3, ONES4, ONES6 = np.ones(3), np.ones(4), np.ones(6)  # the products-with-ones tricks' constants


# ==== the two versions of every trick ==========================================================

# -- comfort_control.pinv: the pseudo-inverse of eq. 2.21 ----------------------------------------

def pinv_trick(a, rcond):
    """LAPACK's gesdd called directly."""
    a = np.asarray(a, float)
    if a.size == 0:
        return np.zeros(a.shape[::-1])
    u, s, vt, info = lapack.dgesdd(a, full_matrices=0)
    if info != 0:
        return np.linalg.pinv(a, rcond=rcond)
    large = s > rcond * s.max()
    inv = np.zeros_like(s)
    inv[large] = 1.0 / s[large]
    return vt.T.dot(inv[:, None] * u.T)


def pinv_plain(a, rcond):
    a = np.asarray(a, float)
    if a.size == 0:
        return np.zeros(a.shape[::-1])
    return np.linalg.pinv(a, rcond=rcond)


# -- comfort_control.joint_stress: eq. 2.9 --------------------------------------------------------

def joint_stress_trick(tau, limits, tolerance=0.0):
    """np.minimum(np.maximum()) for np.clip."""
    low, high = limits
    s = tau - np.minimum(np.maximum(tau, low), high)
    s[np.abs(s) <= tolerance] = 0.0
    return s


def joint_stress_plain(tau, limits, tolerance=0.0):
    low, high = limits
    s = tau - np.clip(tau, low, high)
    s[np.abs(s) <= tolerance] = 0.0
    return s


# -- balance_control.falling: the base's acceleration of the rotation about the MMP --------------

def _falling(solve):
    bc = balance_control

    def falling(state, wrench, mmp):
        point = bc._on_ground(mmp, state.ground_height)
        torque = bc.moment_about(wrench, point)
        torque[2] = 0.0
        size = np.linalg.norm(torque)
        if size < 1e-9:
            return None
        axis = torque / size
        alpha = -torque / float(axis @ bc.whole_body_inertia(state, point) @ axis)
        m, d = state.model, state.data
        base = np.zeros(m.nv)
        base[:6] = solve(d.motion[0], np.concatenate((alpha, np.cross(point, alpha))))
        return bc.Falling(np.asarray(mmp, float), bc._supporting_foot(state, mmp), alpha, base)
    return falling


def _gesv(a, b):
    _, _, x, info = lapack.dgesv(a, b)
    return x if info == 0 else np.linalg.solve(a, b)


falling_trick, falling_plain = _falling(_gesv), _falling(np.linalg.solve)


# -- feet.PlantedFeet.dls / .damping: the planted legs' damped least squares ---------------------

def dls_trick(self, jac, r):
    """LAPACK's potrf / potrs called directly."""
    known = self._dls_factors.get(id(jac))
    if known is None or known[0] is not jac:
        jj = jac.dot(jac.T)
        factor, info = lapack.dpotrf(jj + self.damping(jj))
        if info != 0:
            raise np.linalg.LinAlgError("a planted leg's Jacobian is singular")
        known = self._dls_factors[id(jac)] = (jac, factor)
    x, info = lapack.dpotrs(known[1], r)
    if info != 0:
        raise np.linalg.LinAlgError("a planted leg's Jacobian is singular")
    return jac.T.dot(x)


def dls_plain(self, jac, r):
    """The product's: the damped pseudo-inverse J' (J J' + lambda^2 I)^-1 once per Jacobian
    (np.linalg.solve), one product per solve."""
    known = self._dls_factors.get(id(jac))
    if known is None or known[0] is not jac:
        jj = jac.dot(jac.T)
        try:
            pseudo_inverse = np.linalg.solve(jj + self.damping(jj), jac).T
        except np.linalg.LinAlgError:
            raise np.linalg.LinAlgError("a planted leg's Jacobian is singular") from None
        known = self._dls_factors[id(jac)] = (jac, pseudo_inverse)
    return known[1].dot(r)


def _damping(smallest_eigenvalue):
    def damping(self, jj):
        band2, extra = self.singular
        low = smallest_eigenvalue(jj)
        if low >= band2:
            return self.eye6
        return self.eye6 + (extra * (1.0 - max(low, 0.0) / band2)) * np.eye(6)
    return damping


damping_trick = _damping(lambda jj: lapack.dsyevd(jj, compute_v=0)[0][0])
damping_plain = _damping(lambda jj: np.linalg.eigvalsh(jj)[0])


# -- hands.ik.null_space_step: the grasp's IK step (eq. 2-1) -------------------------------------

def _null_space_step(smallest_eigenvalue, spd_solve):
    def null_space_step(jac, dx, dz=None, active=None, epsilon=0.02, lam_max=0.05):
        if active is not None:
            jac = jac * active
            if dz is not None:
                dz = np.asarray(dz, float) * active
        rows, n = jac.shape
        wide = n >= rows
        g = jac @ jac.T if wide else jac.T @ jac
        smin2 = smallest_eigenvalue(g) if len(g) else 0.0
        eps2 = epsilon * epsilon
        lam2 = 0.0 if smin2 >= eps2 else lam_max ** 2 * (1.0 - max(smin2, 0.0) / eps2)
        g.flat[::len(g) + 1] += lam2
        if dz is not None:
            dz = np.asarray(dz, float)
        rhs = dx if dz is None else dx - jac @ dz
        x = spd_solve(g, rhs if wide else jac.T @ rhs)
        if x is None:  # not positive definite to rounding (no damping on an exactly singular J): the SVD
            dq = ik.damped_pinv(jac, epsilon, lam_max) @ rhs
        else:
            dq = jac.T @ x if wide else x
        if dz is not None:
            dq = dq + dz
        return dq if active is None else dq * active
    return null_space_step


def _posv(g, b):
    _, x, info = lapack.dposv(g, b)
    return None if info else x


def _cho(g, b):
    try:
        return cho_solve(cho_factor(g, check_finite=False), b, check_finite=False)
    except np.linalg.LinAlgError:
        return None


null_space_step_trick = _null_space_step(lambda g: lapack.dsyevd(g, compute_v=0)[0][0], _posv)
null_space_step_plain = _null_space_step(lambda g: np.linalg.eigvalsh(g)[0], _cho)


# -- flexible.lapack.CholeskySolver: the kernel's Cholesky solve a step --------------------------

class CholeskyInPlace:
    """LAPACK's posv / potrs on the buffers themselves (overwrite_a, overwrite_b; A seen
    transposed, a Fortran view of the same symmetric memory): no copies."""

    def __init__(self, A, b):
        self.A, self.At, self.b = A, A.T, b

    def solve(self):
        factor, x, info = lapack.dposv(self.At, self.b, lower=0, overwrite_a=1, overwrite_b=1)
        if info:
            return False
        if x is not self.b:
            self.b[...] = x
        self._factor = factor
        return True

    def resolve(self):
        x = lapack.dpotrs(self._factor, self.b, lower=0, overwrite_b=1)[0]
        if x is not self.b:
            self.b[...] = x


class CholeskyPlain:
    """x = cho_solve(cho_factor(A), b), written back into b."""

    def __init__(self, A, b):
        self.A, self.b = A, b

    def solve(self):
        try:
            self._factor = cho_factor(self.A, check_finite=False)
        except np.linalg.LinAlgError:  # not positive definite
            return False
        self.b[...] = cho_solve(self._factor, self.b, check_finite=False)
        return True

    def resolve(self):
        self.b[...] = cho_solve(self._factor, self.b, check_finite=False)


# -- cloth.dynamics: sums over springs / edges into particles ------------------------------------

def _scatter_plan(first, second, w_first, w_second, descending=False):
    """The trick's plan: entries particle by particle, items ascending (descending), as flat
    coordinate indices, items and weights."""
    item = np.r_[np.arange(len(first)), np.arange(len(second))]
    particle = np.r_[first, second]
    order = np.lexsort((-item if descending else item, particle))
    flat = (3 * particle[order][:, None] + np.arange(3)).ravel()
    return flat, item[order], np.r_[w_first, w_second][order][:, None]


def _plan_matrix(plan, particles):
    from scipy import sparse
    idx, item, w = plan
    particle = idx[::3] // 3
    indptr = np.r_[0, np.cumsum(np.bincount(particle, minlength=particles))]
    return sparse.csr_matrix((w[:, 0].astype(float), item.astype(np.int32), indptr.astype(np.int32)),
                             shape=(particles, int(item.max()) + 1 if len(item) else 0))


class SumPlanned:
    """The trick: a compiled CSR product whose entries per row are in a fixed (the scatter
    plan's) order, into an output kept between calls."""

    def __init__(self, first, second, w_first, w_second, particles, descending=False):
        self.matrix = _plan_matrix(_scatter_plan(first, second, w_first, w_second, descending), particles)

    def into(self, values, out):
        out[...] = self.matrix @ values
        return out


class SumAddAt:
    """The plain formula: out[first] += w_first values; out[second] += w_second values (np.add.at)."""

    def __init__(self, first, second, w_first, w_second, particles, descending=False):
        self.first, self.second = first, second
        self.w_first, self.w_second = np.asarray(w_first, float)[:, None], np.asarray(w_second, float)[:, None]

    def into(self, values, out):
        out[...] = 0.0
        np.add.at(out, self.first, self.w_first * values)
        np.add.at(out, self.second, self.w_second * values)
        return out


# ==== a version of a product function with one expression replaced ===============================

def rewritten(function, *replacements, names=None):
    """`function` compiled again from its own source in its own module's namespace, with each
    (old, new) text replaced: the other version of a trick written inline in a long function.
    Every `old` must occur exactly once (LookupError otherwise), so a trick that has left the
    product code, or an expression that a replacement would change in two places, is noticed.
    `names`: what the new text needs that the module no longer imports (the namespace is then a
    copy)."""
    source = textwrap.dedent(inspect.getsource(function))
    for old, new in replacements:
        count = source.count(old)
        if count != 1:
            raise LookupError(f"{function.__qualname__}: {old!r} occurs {count} times in its source, "
                              "not exactly once")
        source = source.replace(old, new)
    module = vars(inspect.getmodule(function))
    namespace = {}
    exec(compile(source, inspect.getsourcefile(function), "exec"), {**module, **names} if names else module, namespace)
    return namespace[function.__name__]


def text_pair(function, *replacements, names=None):
    """(trick version, plain version) of a product function whose trick is inline: each
    replacement is (the trick's text, the plain formula's text); whichever of the two the product
    code holds, the other is made from its source by rewritten(), which checks that each text
    occurs exactly once. LookupError when the source holds neither every trick text nor every
    plain text (a trick half made plain, or an expression rewritten since the pair was written)."""
    source = textwrap.dedent(inspect.getsource(function))  # as rewritten() reads it
    if all(trick in source for trick, _ in replacements):
        return function, rewritten(function, *replacements)
    if all(plain in source for _, plain in replacements):
        return rewritten(function, *[(plain, trick) for trick, plain in replacements], names=names), function
    missing = [trick for trick, plain in replacements if trick not in source and plain not in source]
    raise LookupError(f"{function.__qualname__}: its source holds neither every trick text nor every "
                      f"plain text of the pair (neither version of {missing!r}; or the two mixed)")


# -- dynamics.model.Model.expand: (nb, 6) entries of a velocity-like vector ------------------------

def expand_trick(self, v):
    """v written into a preallocated (v, 0) buffer (made once per model, its last entry zero)."""
    buffer = self.__dict__.get("_expand_buffer")
    if buffer is None:
        buffer = self._expand_buffer = np.zeros(self.nv + 1)
    buffer[:-1] = v
    return buffer[self.v_index]


def expand_plain(self, v):
    return np.append(v, 0.0)[self.v_index]


# -- dynamics.model.Data.inertia: each body's world spatial inertia --------------------------------

def _inertia(gather):
    def inertia(self):
        if self._inertia is None:
            xf = gather(self._force, self.model.force_gather).reshape(self.model.nb, 6, 6)
            self._inertia = xf @ self.model.spatial_inertia @ xf.swapaxes(1, 2)
        return self._inertia
    return property(inertia)


inertia_trick = _inertia(lambda force, columns: force.T.take(columns, axis=0).T)
inertia_plain = _inertia(lambda force, columns: force[:, columns])


# -- dynamics.inverse_dynamics: ndarray.dot for the ancestor sums ----------------------------------

def _ancestor_pair(function, name):
    """(with model.ancestors.dot(x), with model.ancestors @ x)."""
    return text_pair(function, (f"model.ancestors.dot({name})", f"model.ancestors @ {name}"))


# -- vectors.cross: np.cross of (..., 3) stacks -----------------------------------------------------

def cross_trick(a, b):
    """np.cross without its axis bookkeeping: the components written one by one."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


def cross_plain(a, b):
    return np.cross(a, b)


# -- motion_control: per-call savings written inline (the pairs by text_pair) ----------------------

def on_ground_trick(xy, height):
    """np.append without its dispatch: on Python floats."""
    x, y = np.asarray(xy, float).tolist()
    return np.array((x, y, float(height)))


def on_ground_plain(xy, height):
    return np.append(np.asarray(xy, float), float(height))


def moment_about_trick(wrench, point):
    """np.cross on Python floats."""
    (p0, p1, p2) = tuple(float(c) for c in point[:3])
    (f0, f1, f2) = tuple(float(c) for c in wrench[3:6])
    return wrench[:3] - np.array([p1 * f2 - p2 * f1, p2 * f0 - p0 * f2, p0 * f1 - p1 * f0])


def moment_about_plain(wrench, point):
    return wrench[:3] - np.cross(np.asarray(point, float)[:3], wrench[3:6])


# -- comfort_control._ground_wrenches: the feet's ground wrenches on plain floats -----------------

def ground_wrenches_plain(state, wrench):
    """The plain formula on arrays: ZMP p; application points c + (p - w c); moment about the ZMP
    m = n - p x f; per foot (x_i x w_i f + w_i m, w_i f)."""
    cc = comfort_control
    sides = state.sides()
    if not len(sides):
        return None
    n, f = np.asarray(wrench[:3], float), np.asarray(wrench[3:6], float)
    if f[2] <= 1e-9:
        return None
    h = float(state.ground_height)
    p = np.array([(h * f[0] - n[1]) / f[2], (n[0] + h * f[1]) / f[2], h])
    if state.sole_centres is None:
        state.sole_centres = cc._sole_centres(state, sides, h)
    c = np.asarray(state.sole_centres, float)
    w = np.ones(1) if len(c) == 1 else np.asarray(cc._split(state.sole_centres, p[0], p[1]))
    x = c + (p - w @ c)
    g = w[:, None] * f
    rows = np.hstack((np.cross(x, g) + w[:, None] * (n - np.cross(p, f)), g))
    if state.foot_bodies is None:
        state.foot_bodies = state.model.joint_body[np.asarray(state.parts.feet)[sides]]
    return state.foot_bodies, rows


# -- feet.PlantedFeet.predicted_resolve: the six components of the error, on plain floats -------

PREDICTED_ERROR_FLOATS = """error = np.array([t0 - h * w[0] - h2 * al[0], t1 - h * w[1] - h2 * al[1], t2 - h * w[2] - h2 * al[2],
                          p0 - x[0] - h * xd[0] - h2 * xdd[0], p1 - x[1] - h * xd[1] - h2 * xdd[1],
                          p2 - x[2] - h * xd[2] - h2 * xdd[2]])"""  # (as dedented by one level)
PREDICTED_ERROR_PLAIN = """target = np.array([t0, t1, t2, p0, p1, p2])
        pose = np.array([0.0, 0.0, 0.0, *x])
        error = target - (pose + h * np.array([*w, *xd]) + h2 * np.array([*al, *xdd]))"""


# -- hands.sensors.length: Euclidean lengths of (..., k) vectors ---------------------------------

def length_trick(v):
    """np.linalg.norm's result by one einsum."""
    return np.sqrt(np.einsum("...i,...i->...", v, v))


def length_plain(v):
    return np.linalg.norm(v, axis=-1)


# -- cloth.fast.Product: a fixed sparse product into a kept output ---------------------------------

class ProductKept:
    """The trick: the product written into an output kept between calls."""

    def __init__(self, matrix, cols):
        self.matrix, self.cols = matrix.tocsr(), cols
        self.out = np.zeros((matrix.shape[0], cols))

    def __call__(self, dense):
        return self.into(dense, self.out)

    def into(self, dense, out):
        out[...] = self.matrix @ dense
        return out


class ProductPlain:
    """The plain formula: matrix @ dense, a new array each call."""

    def __init__(self, matrix, cols):
        self.matrix, self.cols = matrix.tocsr(), cols

    def __call__(self, dense):
        return self.matrix @ dense

    def into(self, dense, out):
        out[...] = self.matrix @ dense
        return out


# -- cloth.fast.IndexDifference: differences x[second] - x[first] as one sparse product ----------------------

class DifferenceProduct:
    """The trick for cloth.fast.IndexDifference(first, second): x[second] - x[first] as one compiled
    sparse product, Product(difference_matrix(first, second, len(x))) (made at the first call)."""

    def __init__(self, first, second):
        self.first, self.second, self.product = first, second, None

    def __call__(self, x):
        if self.product is None:
            self.product = cloth_fast.Product(cloth_fast.difference_matrix(self.first, self.second, len(x)), 3)
        return self.product(x)


# -- cloth.fast.CornerSum: per-corner values summed at each particle -------------------------------

class CornerSumBincount:
    """The trick: one np.bincount over flat coordinate indices."""

    def __init__(self, faces, particles):
        self.idx = (3 * np.asarray(faces).ravel()[:, None] + np.arange(3)).ravel()
        self.size = 3 * particles

    def __matmul__(self, values):
        return np.bincount(self.idx, values.ravel(), minlength=self.size).reshape(-1, 3)


class CornerSumAddAt:
    """The plain formula: out = 0; np.add.at(out, faces.ravel(), values)."""

    def __init__(self, faces, particles):
        self.corners, self.particles = np.asarray(faces).ravel(), particles

    def __matmul__(self, values):
        out = np.zeros((self.particles, 3))
        np.add.at(out, self.corners, values)
        return out


# -- balance_control._balance_error with dynamics.balance.inside / closest_boundary_point: ------
# -- the ZMP's test against the support polygon and the MMP --------------------------------------

def inside_xy(pts, px, py):
    """The trick's point-in-polygon test on plain floats: a counter-clockwise convex polygon as a
    list of at least three [x, y] vertices and the point's coordinates."""
    x0, y0 = pts[-1]
    for x1, y1 in pts:  # edge from the previous vertex: cross(edge, point - previous) >= 0
        if (x1 - x0) * (py - y0) - (y1 - y0) * (px - x0) < -1e-10:
            return False
        x0, y0 = x1, y1
    return True


def closest_boundary_xy(pts, px, py):
    """The trick's closest boundary point on plain floats: the polygon as a list of [x, y]
    vertices, the point's coordinates; returns (x, y)."""
    best, out = None, None
    for (ax, ay), (bx, by) in zip(pts, pts[1:] + pts[:1]):
        ex, ey = bx - ax, by - ay
        length2 = ex * ex + ey * ey
        t = ((px - ax) * ex + (py - ay) * ey) / (length2 if length2 > 0 else 1.0)
        t = min(max(t, 0.0), 1.0)
        cx, cy = ax + t * ex, ay + t * ey
        dist = math.sqrt((cx - px) * (cx - px) + (cy - py) * (cy - py))
        if best is None or dist < best:
            best, out = dist, (cx, cy)
    return out


def inside_floats(polygon, point):
    """dynamics.balance.inside by inside_xy."""
    polygon = np.asarray(polygon, float)
    if len(polygon) < 3:
        return len(polygon) > 0 and np.allclose(dynamics_balance.minimum_moment_point(polygon, point), point)
    px, py = np.asarray(point, float).ravel()[:2].tolist()
    return inside_xy(polygon.tolist(), px, py)


def closest_boundary_point_floats(polygon, point):
    """dynamics.balance.closest_boundary_point by closest_boundary_xy."""
    px, py = np.asarray(point, float).ravel()[:2].tolist()
    return np.array(closest_boundary_xy(np.asarray(polygon, float).reshape(-1, 2).tolist(), px, py))


def balance_error_floats(state, wrench, polygon):
    """balance_control._balance_error with the ZMP, the test and the MMP on plain floats."""
    bc = balance_control
    if len(polygon) == 0 or wrench[5] <= bc.MIN_SUPPORT * state.constants.weight:
        return None, None, 0.0
    px, py = bc.zmp_xy(wrench, state.ground_height)
    p = np.array([px, py])
    pts = polygon.tolist()
    if len(pts) >= 3 and inside_xy(pts, px, py):
        return p, p.copy(), 0.0
    mx, my = closest_boundary_xy(pts, px, py)
    dx, dy = mx - px, my - py
    return p, np.array((mx, my)), math.sqrt(dx * dx + dy * dy)


def inside_plain(polygon, point):
    """A point lies in a counter-clockwise convex polygon when it is left of (or on) every edge:
    cross(edge, point - edge start) >= 0, all edges at once."""
    polygon = np.asarray(polygon, float)
    if len(polygon) < 3:
        return len(polygon) > 0 and np.allclose(dynamics_balance.minimum_moment_point(polygon, point), point)
    start = np.concatenate((polygon[-1:], polygon[:-1]))  # each edge runs from the previous vertex
    edge, to_point = polygon - start, np.asarray(point, float).ravel()[:2] - start
    return bool(np.all(edge[:, 0] * to_point[:, 1] - edge[:, 1] * to_point[:, 0] >= -1e-10))


def closest_boundary_point_plain(polygon, point):
    """Each edge's closest point a + clip((p - a).e / |e|^2, 0, 1) e, all edges at once; the
    nearest of them."""
    a = np.asarray(polygon, float).reshape(-1, 2)
    p = np.asarray(point, float).ravel()[:2]
    e = np.concatenate((a[1:], a[:1])) - a  # each edge runs to the next vertex (one vertex: length 0)
    length2 = (e * e).sum(axis=1)
    t = np.clip(((p - a) * e).sum(axis=1) / np.where(length2 > 0, length2, 1.0), 0.0, 1.0)
    closest = a + t[:, None] * e
    return closest[np.argmin(np.linalg.norm(closest - p, axis=1))]


def balance_error_plain(state, wrench, polygon):
    """zmp_of, minimum_moment_point (inside, else closest_boundary_point) and their distance, on
    arrays."""
    bc = balance_control
    if len(polygon) == 0 or wrench[5] <= bc.MIN_SUPPORT * state.constants.weight:
        return None, None, 0.0
    p = bc.zmp_of(wrench, state.ground_height)
    mmp = dynamics_balance.minimum_moment_point(polygon, p)
    return p, mmp, float(np.linalg.norm(mmp - p))


# -- collisions.pgs: projected Gauss-Seidel on the contacts' impulses ----------------------------

def pgs_plain(w, rel, targets, mu, iterations):
    """Textbook projected Gauss-Seidel, row by row (normal, then the two tangents, per contact):
    the row's relative speed with the impulses so far, u_r = rel_r + W_r p (J_r v, v updated by
    every impulse before it); the impulse change that brings it to its target, (target - u_r) /
    W_rr; projected: the normal impulse >= 0, each friction impulse within +-mu times the normal
    one (a box)."""
    n = len(targets)
    p = np.zeros(3 * n)
    for _ in range(iterations):
        change = 0.0
        for c in range(n):
            normal = 3 * c
            for r in (normal, normal + 1, normal + 2):
                speed = rel[r] + w[r] @ p
                if r == normal:
                    new = max(0.0, p[r] + (targets[c] - speed) / w[r, r])
                else:
                    cap = mu * p[normal]
                    new = min(max(p[r] - speed / w[r, r], -cap), cap)
                change = max(change, abs(new - p[r]))
                p[r] = new
        if change < 1e-7:
            break
    return p


def pgs_blocks_calls(w, rel, targets, mu, iterations):
    """The contact blocks as first kept (this stop's first microopt run, 28 %): each contact's
    speeds by `rows[c] @ p` on arrays, the impulses read back from p, the projections by max and
    min; against pgs_blocks it measures the call-overhead changes made to it since."""
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


def pgs_blocks(w, rel, targets, mu, iterations):
    """The trick: contact by contact, its three speeds from the impulses at once (one 3 x 3c
    product, its rows' bound dot), its rows then updated on plain floats through its own 3 x 3
    block (the impulses mirrored in a list of floats, the projections as comparisons)."""
    n = len(targets)
    p = np.zeros(3 * n)
    floats = [0.0] * (3 * n)  # p's values, read on plain floats
    # each contact's three speeds from the impulses: its rows' bound dot (a third of `@`'s call)
    row_dots = [w[3 * c:3 * c + 3].dot for c in range(n)]
    blocks = [w[3 * c:3 * c + 3, 3 * c:3 * c + 3].tolist() for c in range(n)]
    rel_rows = np.asarray(rel, float).reshape(n, 3).tolist()
    targets = np.asarray(targets, float).tolist()
    for _ in range(iterations):
        change = 0.0
        for c in range(n):
            i = 3 * c
            s0, s1, s2 = row_dots[c](p).tolist()
            r0, r1, r2 = rel_rows[c]
            u0, u1, u2 = r0 + s0, r1 + s1, r2 + s2
            pn, p1, p2 = floats[i:i + 3]
            moved = False
            (d0, _, _), (w10, d1, _), (w20, w21, d2) = blocks[c]
            new = pn + (targets[c] - u0) / d0
            new = new if new > 0.0 else 0.0  # max(0, new)
            dp = new - pn
            if dp:
                pn = new
                u1 += w10 * dp
                u2 += w20 * dp
                moved = True
                dp = abs(dp)
                change = dp if dp > change else change
            cap = mu * pn
            new = p1 - u1 / d1
            new = -cap if new < -cap else new  # min(max(new, -cap), cap)
            new = cap if new > cap else new
            dp = new - p1
            if dp:
                p1 = new
                u2 += w21 * dp
                moved = True
                dp = abs(dp)
                change = dp if dp > change else change
            new = p2 - u2 / d2
            new = -cap if new < -cap else new
            new = cap if new > cap else new
            dp = new - p2
            if dp:
                p2 = new
                moved = True
                dp = abs(dp)
                change = dp if dp > change else change
            if moved:
                floats[i:i + 3] = pn, p1, p2
                p[i] = pn  # element by element: half a slice assignment's time
                p[i + 1] = p1
                p[i + 2] = p2
        if change < 1e-7:
            break
    return p


# ==== which version the product code holds, and switching ======================================

class Trick:
    """One trick: the product code's names it lives under, its version and the plain one. A trick
    spread over several functions gives each version as {attribute name: function}."""

    def __init__(self, name, capability, plain_formula, targets, trick, plain):
        self.name, self.capability, self.plain_formula = name, capability, plain_formula
        self.targets, self.versions = targets, {"trick": trick, "plain": plain}

    def version(self, version, attr):
        """What `version` ('trick' or 'plain') puts under the attribute name `attr`."""
        held = self.versions[version]
        return held[attr] if isinstance(held, dict) else held

    def use(self, version):
        """Every target (owner, attribute) set to `version` ('trick' or 'plain')."""
        for owner, attr in self.targets:
            setattr(owner, attr, self.version(version, attr))


def _holders(name, original):
    """Every (module, name) of the loaded solver modules that holds `original` (the defining
    module and every one that imported it)."""
    return [(mod, name) for key, mod in sorted(sys.modules.items())
            if key.startswith("humananim.solver") and getattr(mod, name, None) is original]


def tricks():
    cc, bc = comfort_control, balance_control
    out = [
        Trick("comfort_pinv_gesdd", "control", "np.linalg.pinv(a, rcond)",
              _holders("pinv", cc.pinv), pinv_trick, pinv_plain),
        Trick("comfort_joint_stress_min_max", "control", "tau - np.clip(tau, low, high)",
              _holders("joint_stress", cc.joint_stress), joint_stress_trick, joint_stress_plain),
        Trick("balance_falling_gesv", "control", "np.linalg.solve(I_base, rhs)",
              _holders("falling", bc.falling), falling_trick, falling_plain),
        Trick("feet_dls_potrf_potrs", "control", "J' (J J' + lambda^2 I)^-1 once per Jacobian (np.linalg.solve), J^+ r",
              [(feet.PlantedFeet, "dls")], dls_trick, dls_plain),
        Trick("feet_damping_syevd", "control", "np.linalg.eigvalsh(J J')[0]",
              [(feet.PlantedFeet, "damping")], damping_trick, damping_plain),
        Trick("ik_null_space_step_syevd_posv", "grasp",
              "np.linalg.eigvalsh(G)[0]; cho_solve(cho_factor(G + l^2 I), rhs)",
              _holders("null_space_step", ik.null_space_step), null_space_step_trick, null_space_step_plain),
        Trick("flexible_cholesky_in_place", "flexible", "b[:] = cho_solve(cho_factor(A), b)",
              [(flexible_kernel, "CholeskySolver")], CholeskyInPlace, CholeskyPlain),
        Trick("cloth_scatter_plan", "cloth", "np.add.at(out, first, w_first f); np.add.at(out, second, w_second f)",
              [(cloth_dynamics, "ParticleSum")], SumPlanned, SumAddAt),
        Trick("dynamics_expand_buffer", "control", "np.append(v, 0.0)[v_index]",
              [(dynamics_model.Model, "expand")], expand_trick, expand_plain),
        Trick("dynamics_inertia_take", "control", "force[:, force_gather]",
              [(dynamics_model.Data, "inertia")], inertia_trick, inertia_plain),
        Trick("dynamics_velocity_terms_dot", "control", "model.ancestors @ u",
              _holders("velocity_terms", inverse_dynamics.velocity_terms),
              *_ancestor_pair(inverse_dynamics.velocity_terms, "u")),
        Trick("dynamics_subtree_wrenches_dot", "control", "model.ancestors @ own",
              _holders("subtree_wrenches", inverse_dynamics.subtree_wrenches),
              *_ancestor_pair(inverse_dynamics.subtree_wrenches, "own")),
        Trick("cloth_product_kept_output", "cloth", "matrix @ dense (a new array each call)",
              _holders("Product", cloth_fast.Product), ProductKept, ProductPlain),
        Trick("cloth_corner_sum_bincount", "cloth", "np.add.at(out, faces.ravel(), values)",
              _holders("CornerSum", cloth_fast.CornerSum), CornerSumBincount, CornerSumAddAt),
        Trick("vectors_cross_cloth", "cloth", "np.cross(a, b)",
              _holders("cross", vectors.cross) + _holders("cross_rows", vectors.cross), cross_trick, cross_plain),
        Trick("vectors_cross_grasp", "grasp", "np.cross(a, b)",
              _holders("cross", vectors.cross) + _holders("cross_rows", vectors.cross), cross_trick, cross_plain),
        Trick("comfort_required_torques_take", "control", "total[m.dof_body]; m.dof_subtree[bodies]",
              _holders("_required_torques", cc._required_torques),
              *text_pair(cc._required_torques, ("total.take(m.dof_body, axis=0)", "total[m.dof_body]"),
                         ("m.dof_subtree.take(bodies, axis=0)", "m.dof_subtree[bodies]"))),
        Trick("comfort_required_torques_ones", "control", "(S * below).sum(axis=1)",
              _holders("_required_torques", cc._required_torques),
              *text_pair(cc._required_torques, ("(motion_subspace(m, d, state.q) * below).dot(ONES6)",
                                                "(motion_subspace(m, d, state.q) * below).sum(axis=1)"),
                         names={"ONES6": ONES6})),
        Trick("comfort_sole_centres_add_reduce", "control", "soles[s][:, :2].mean(axis=0)",
              _holders("_sole_centres", cc._sole_centres),
              *text_pair(cc._sole_centres, ("(np.add.reduce(soles[s][:, :2], 0) / len(soles[s]))",
                                            "soles[s][:, :2].mean(axis=0)"))),
        Trick("balance_support_polygon_reduce_take", "control", "np.abs(a - b).max(); pts[hull]",
              _holders("_support_polygon", bc._support_polygon),
              *text_pair(bc._support_polygon, ("np.maximum.reduce(np.abs(cached[0] - pts), None)",
                                               "np.abs(cached[0] - pts).max()"),
                         ("pts.take(cached[1], axis=0)", "pts[cached[1]]"))),
        Trick("balance_on_ground_floats", "control", "np.append(xy, height)",
              _holders("_on_ground", bc._on_ground), on_ground_trick, on_ground_plain),
        Trick("balance_moment_about_floats", "control", "wrench[:3] - np.cross(point, wrench[3:])",
              _holders("moment_about", bc.moment_about), moment_about_trick, moment_about_plain),
        Trick("feet_predicted_resolve_max_reduce", "control", "np.abs(turns).max()",
              [(feet.PlantedFeet, "predicted_resolve")],
              *text_pair(feet.PlantedFeet.predicted_resolve, ("np.maximum.reduce(np.abs(turns))",
                                                              "np.abs(turns).max()"))),
        Trick("cloth_difference_product", "cloth", "x[second] - x[first]",
              _holders("IndexDifference", cloth_fast.IndexDifference), DifferenceProduct, cloth_fast.IndexDifference),
        Trick("hands_length_einsum", "grasp", "np.linalg.norm(v, axis=-1)",
              _holders("length", sensors.length), length_trick, length_plain),
        Trick("comfort_ground_wrenches_floats", "control", "ZMP p, c + (p - w c), n - np.cross(p, f) on arrays",
              _holders("_ground_wrenches", cc._ground_wrenches), cc._ground_wrenches, ground_wrenches_plain),
        Trick("feet_predicted_resolve_error_floats", "control", "target - (pose + velocity h + acceleration h^2 / 2)",
              [(feet.PlantedFeet, "predicted_resolve")],
              *text_pair(feet.PlantedFeet.predicted_resolve, (PREDICTED_ERROR_FLOATS, PREDICTED_ERROR_PLAIN))),
        Trick("tracking_frame_error_ones", "control", "(xyz * xyz).sum(axis=1)",
              [(tracking.TrackingController, "_frame_error")],
              *text_pair(tracking.TrackingController._frame_error,
                         ("(xyz * xyz).dot(ONES3)", "(xyz * xyz).sum(axis=1)"),
                         ("(rel * rel * self._diag_sign).dot(ONES4)", "(rel * rel * self._diag_sign).sum(axis=1)"),
                         names={"ONES3": ONES3, "ONES4": ONES4})),
        Trick("kinematics_integrate_ones", "control", "(turn * turn).sum(axis=1)",
              _holders("integrate", kinematics.integrate),
              *text_pair(kinematics.integrate, ("(turn * turn).dot(ONES3)", "(turn * turn).sum(axis=1)"),
                         ("(turned * turned).dot(ONES4)", "(turned * turned).sum(axis=1)"),
                         names={"ONES3": ONES3, "ONES4": ONES4})),
        Trick("comfort_dof_limits_ones", "control", "(xyz * xyz).sum(axis=1)",
              _holders("_dof_limits", cc._dof_limits),
              *text_pair(cc._dof_limits, ("(xyz * xyz).dot(ONES3)", "(xyz * xyz).sum(axis=1)"),
                         names={"ONES3": ONES3})),
        Trick("dynamics_crba_take", "control", "ic[model.dof_body]",
              _holders("crba", inertia_matrix.crba),
              *text_pair(inertia_matrix.crba, ("ic.take(model.dof_body, axis=0)", "ic[model.dof_body]"))),
        Trick("balance_zmp_mmp_floats", "control",
              "zmp_of; minimum_moment_point: all(cross(edge, p - a) >= 0), else the nearest a + clip(t) e, on arrays",
              _holders("_balance_error", bc._balance_error) + _holders("inside", dynamics_balance.inside)
              + _holders("closest_boundary_point", dynamics_balance.closest_boundary_point),
              {"_balance_error": balance_error_floats, "inside": inside_floats,
               "closest_boundary_point": closest_boundary_point_floats},
              {"_balance_error": balance_error_plain, "inside": inside_plain,
               "closest_boundary_point": closest_boundary_point_plain}),
        Trick("collisions_pgs_contact_blocks", "contacts",
              "row by row: p_r += (target_r - rel_r - W_r p) / W_rr, projected",
              _holders("pgs", collisions.pgs), pgs_blocks, pgs_plain),
        Trick("collisions_pgs_call_overhead", "contacts",
              "contact blocks with rows @ p, p read as floats, max and min",
              _holders("pgs", collisions.pgs), pgs_blocks, pgs_blocks_calls),
    ]
    return out


# ==== the capabilities ==========================================================================

def control_workload():
    import control as control_bench
    from humananim.solver.motion_control import controller as ctl
    chosen = [c for c in control_bench.cases(ctl) if c[0] in ("figure_15kg", "cmu")]
    return [lambda sk=sk, motion=motion, settings=settings: ctl.control(sk, motion, settings)
            for _, sk, motion, settings in chosen]


def grasp_workload():
    from hands_cases import metarig, object_cases
    from humananim.solver.hands import grasp as G
    sk, basis, a2w = metarig()
    shapes = [case[3] for case in object_cases()[::5]]
    G.grasp(sk, basis, a2w, shapes[0])  # per-skeleton caches filled once, as in a session
    return [lambda shape=shape: G.grasp(sk, basis, a2w, shape) for shape in shapes]


def flexible_workload():
    import flexible as flexible_bench
    from humananim.solver.flexible import Ground, ModeGains, Settings, Simulator
    from humananim.solver.flexible.demo import table_body
    from humananim.solver.flexible.simulate import State
    body = table_body(count=11)
    gains = ModeGains.from_frequency(body, 3.0, 0.3)
    start = State.rest(4, t=(0, 0, 0.3))

    def run(integrator):  # the simulator made inside: the kernel takes its solver class when built
        sim = Simulator(body, gains, Settings(dt=0.01, integrator=integrator, ground=Ground.flat(), cond_every=0),
                        flexible_bench.table_controller(body))
        sim.run(start, 12.0)
    return [lambda: run("semi_implicit"), lambda: run("implicit")]


def cloth_workload(frames=60):
    from cloth_scenes import walk, walking_skirt
    from humananim.solver.cloth import ClothSimulation, preset

    def run():  # the simulation is made inside: its dynamics take their particle sums when built
        mesh, pinned, capsules = walking_skirt()
        sim = ClothSimulation(mesh, preset("COTTON"), pinned, [capsules], level=2, fps=30)
        for _ in walk(sim, mesh.rest[pinned], capsules, [capsules], frames):
            pass
    return [run, run]


def contacts_workload():
    """Dynamic Control with contact impulses: benchmarks/control.py's cmu_knocked_over (the CMU walk
    pushed over by 150 N s: the fallen body's ground contacts) and the thesis's punch (a 6 kg fist,
    a finite-mass collider, at 4 m/s into the metarig standing still for 2 s; it falls too)."""
    import control as control_bench
    from humananim.solver.motion_control import controller as ctl
    from humananim.solver.synthesis import keyframed
    from humananim.solver.synthesis.punch import punch_collider
    from test_dynamics_closed_loop_rigs import load
    chosen = [c for c in control_bench.cases(ctl) if c[0] == "cmu_knocked_over"]
    sk, tr = load("metarig_legs", frames=1)
    still = keyframed.still(sk, tr, seconds=2.0).trajectories
    fist = punch_collider(sk, still, 4.0, mass=6.0)
    chosen.append(("punch", sk, still, ctl.ControlSettings(colliders=(fist,))))
    return [lambda sk=sk, motion=motion, settings=settings: ctl.control(sk, motion, settings)
            for _, sk, motion, settings in chosen]


WORKLOADS = {"control": control_workload, "contacts": contacts_workload, "grasp": grasp_workload,
             "flexible": flexible_workload, "cloth": cloth_workload}


# ==== measuring =================================================================================

def cpu_seconds(fn):
    t0 = time.process_time()
    fn()
    return time.process_time() - t0


def measure(trick, units, rounds):
    """times[version][round][unit]: CPU seconds of each unit of the workload (one bake, one grasp,
    one simulation) with each version, run in turn, the order alternating from unit to unit, so a
    swing of the machine's load falls on both. The product code's version is restored after."""
    held = [(owner, attr, getattr(owner, attr)) for owner, attr in trick.targets]
    times = {"trick": [], "plain": []}
    try:
        for version in ("trick", "plain"):  # a warm-up of each (imports, caches)
            trick.use(version)
            units[0]()
        flip = 0
        for _ in range(rounds):
            for version in times:
                times[version].append([])
            for unit in units:
                for version in (("trick", "plain"), ("plain", "trick"))[flip]:
                    trick.use(version)
                    times[version][-1].append(cpu_seconds(unit))
                flip ^= 1
    finally:
        for owner, attr, value in held:
            setattr(owner, attr, value)
    return times


def figures(trick, times):
    """The median over the rounds of (workload time with the trick / with the plain version), its
    spread, and beside it the ratio of the best times (each unit's fastest run of each version,
    summed: the load a shared machine adds only ever slows a run down)."""
    trick_s = [sum(r) for r in times["trick"]]
    plain_s = [sum(r) for r in times["plain"]]
    ratios = [t / p for t, p in zip(trick_s, plain_s)]
    ratio = statistics.median(ratios)
    best = sum(map(min, zip(*times["trick"]))) / sum(map(min, zip(*times["plain"])))
    return {"trick": trick.name, "capability": trick.capability, "plain_formula": trick.plain_formula,
            "capability_ms_with_trick": 1e3 * statistics.median(trick_s),
            "capability_ms_plain": 1e3 * statistics.median(plain_s),
            "ratio_trick_over_plain": ratio, "ratio_min": min(ratios), "ratio_max": max(ratios),
            "ratio_of_best_times": best, "saving_percent": 100.0 * (1.0 - ratio), "rounds": len(ratios),
            "worth_keeping": bool(1.0 - ratio >= AIM)}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true", help="print one JSON object (and write benchmarks/results/microopt.json)")
    parser.add_argument("--rounds", type=int, default=5, help="alternating rounds per trick (default 5)")
    parser.add_argument("--only", default="", help="only the tricks whose name or capability contains this (several: comma-separated)")
    args = parser.parse_args(argv)
    wanted = args.only.split(",")
    chosen = [t for t in tricks() if any(w in t.name or w in t.capability for w in wanted)]
    runs, rows = {}, []
    for trick in chosen:
        if trick.capability not in runs:
            runs[trick.capability] = WORKLOADS[trick.capability]()
        row = figures(trick, measure(trick, runs[trick.capability], max(1, args.rounds)))
        rows.append(row)
        if not args.json:
            print(f"{row['trick']:32s} {row['capability']:9s} {row['capability_ms_with_trick']:8.1f} ms "
                  f"/ {row['capability_ms_plain']:8.1f} ms plain = {row['ratio_trick_over_plain']:.3f} "
                  f"({row['ratio_min']:.3f}-{row['ratio_max']:.3f}; best times {row['ratio_of_best_times']:.3f}), "
                  f"saves {row['saving_percent']:5.1f} %"
                  f" -> {'keep' if row['worth_keeping'] else 'plain'}", flush=True)
    if args.json:
        everything = len(chosen) == len(tricks())
        emit(merged(rows, None if everything else previous_result(), [t.name for t in tricks()]))


def row_claim(r):
    return claim(f"{r['trick']}: {r['capability']} time with the trick / with {r['plain_formula']} "
                 f"(median of {r['rounds']} alternating rounds, spread {r['ratio_min']:.3f}-{r['ratio_max']:.3f})",
                 r["ratio_trick_over_plain"], "ratio", "saves >= 5 % of the capability's time", r["worth_keeping"])


def previous_result():
    """The committed benchmarks/results/microopt.json, or None."""
    import json
    from machine import RESULTS
    path = Path(RESULTS) / "microopt.json"
    return json.loads(path.read_text()) if path.exists() else None


def merged(rows, previous, names):
    """The JSON object of this run's rows, merged into `previous` (the last result, None for a run
    of every trick) by trick name: a trick this run measured gets this run's row, the others keep
    theirs; rows in the order of `names` (the current tricks; a pair since removed is dropped).
    `runs` says which tricks each run measured, with its date and machine speed."""
    this = result("microopt", [])
    run = {"tricks": [r["trick"] for r in rows], "date": this["date"], "machine_speed": this["machine_speed"]}
    by_name = {r["trick"]: r for r in (previous or {}).get("tricks", ())}
    by_name.update((r["trick"], r) for r in rows)
    kept = [by_name[n] for n in names if n in by_name]
    runs = []
    for old in (previous or {}).get("runs", ()):
        left = [n for n in old["tricks"] if n not in run["tricks"] and n in names]
        if left:
            runs.append({**old, "tricks": left})
    return {**this, "claims": [row_claim(r) for r in kept], "tricks": kept, "runs": runs + [run]}


if __name__ == "__main__":
    main()
