"""Balance control (Oshita 2003, sec. 2.5.1 eq. 2.11-2.14, sec. 2.5.3) and the falling criterion
(sec. 2.3.3), on a horizontal ground at z = ground_height (Blender's Z up).

The zero moment point (ZMP) of the commanded accelerations is compared with the support polygon
(convex hull of the sole points of the feet in contact); when it lies outside, the acceleration
of the arms, then the back, then the pelvis (legs, through J_p) is changed to move it to the
minimum moment point (MMP), the polygon's point closest to it.

The relation between a joint's acceleration and the ZMP is the augmented body's (fig. 2.5): the
composite rigid body below the joint. A unit acceleration about the joint's axis changes the
ground wrench the motion needs by the augmented body's rate of momentum (mass M, centre p,
acceleration a of eq. 2.13-2.14, plus its rotational inertia). The ZMP is a ratio of that wrench's
components, but "the ZMP is at the MMP" is linear: the horizontal moment of the ground wrench about
the MMP vanishes. Solving that linear condition by pseudo-inverse puts the ZMP on the MMP exactly.

When the legs cannot bring the ZMP inside (more than Settings.max_pelvis_acceleration), the figure
falls: it turns about the MMP with the torque the ground cannot supply over the whole body's moment
of inertia about that axis (sec. 2.3.3).
"""

import math
from dataclasses import dataclass

import numpy as np

from ..dynamics.balance import _turn, closest_boundary_xy, convex_hull, inside_xy, monotone_chain
from ..dynamics.inertia_matrix import composite_inertias
from ..dynamics.kinematics import body_com, motion_subspace, update_frames
from .comfort_control import ControlLog, control_sequence, part_matrix, pinv, required_torques


# ---- support polygon, ZMP, MMP ---------------------------------------------------------------

def support_polygon(state):
    """Counter-clockwise convex hull (m, 2) of the sole points of the feet in contact.

    The hull's vertex indices are remembered per body parts and contact set: while the feet stay
    (every sole point within _HULL_REUSE of where the hull was built; planted feet do not move)
    the polygon is those points at their current positions, without a new hull; beyond that, while
    the monotone chain would take the same path on the moved points, the same
    vertices (_same_path). Once per state."""
    if state.polygon is None:
        state.polygon = _support_polygon(state)
    return state.polygon


def _support_polygon(state):
    soles = state.sole_world()
    pts = [soles[s][:, :2] for s in state.sides()]
    if not pts:
        return np.zeros((0, 2))
    pts = np.concatenate(pts)
    hulls = state.constants.hulls
    key = tuple(state.feet.tolist())
    cached = hulls.get(key)
    same_shape = cached is not None and cached[0].shape == pts.shape
    if same_shape and np.abs(cached[0] - pts).max() < _HULL_REUSE:
        return pts[cached[1]]
    plist = pts.tolist()
    path = cached[2] if same_shape else None
    if path is not None and _same_path(plist, path):
        idx = cached[1]  # the monotone chain would take the same path to the same vertices
    else:
        found = _hull_path(plist)
        if found is not None:
            idx, path = np.array(found[0], int), found[1]
        else:  # duplicates: set() in convex_hull merges them, no path is kept
            hull = convex_hull(pts)
            first = {}
            for i, p in enumerate(map(tuple, plist)):
                first.setdefault(p, i)
            idx = np.array([first[p] for p in map(tuple, hull.tolist())], int)
            path = None
    hulls[key] = (pts, idx, path)
    return pts.take(idx, axis=0)


def _hull_path(pts):
    """dynamics.balance.convex_hull (Andrew's monotone chain) on the indices of points (a list of
    [x, y]): its vertex indices and its path, the sort permutation and every turn test it made
    [(o, a, b, outcome)]; None when two points coincide (convex_hull's set() merges them)."""
    tup = [tuple(p) for p in pts]
    perm = sorted(range(len(tup)), key=tup.__getitem__)
    for i, j in zip(perm, perm[1:]):
        if tup[i] == tup[j]:
            return None
    if len(perm) <= 2:
        return list(perm), (perm, ())
    tests = []
    return monotone_chain(tup, perm, tests), (perm, tuple(tests))


def _same_path(pts, path):
    """Whether the monotone chain takes `path` (_hull_path's) on points (a list of [x, y]): the
    same sort order (strictly increasing, so no duplicates) and every turn test with the same
    outcome (the same products on the same floats). Then it finds the same vertex indices: the
    rolling feet's hull, whose points move every step but keep that path, is built once per
    contact set (bit for bit convex_hull's own result)."""
    perm, tests = path
    # (the [x, y] lists compare as _hull_path's tuples do)
    for i, j in zip(perm, perm[1:]):
        if not pts[i] < pts[j]:
            return False
    for o, a, b, turned in tests:
        if (_turn(pts[o], pts[a], pts[b]) <= 1e-14) != turned:
            return False
    return True


_HULL_REUSE = 1e-4  # m


# the ZMP is a ratio over the vertical ground force: below this share of the body's weight (a
# body all but airborne, a capture's one-frame glitch) it is ill-conditioned (metres off for a
# newton) and the figure is not judged for balance
MIN_SUPPORT = 0.2


def zmp_of(wrench, ground_height=0.0):
    """ZMP (2,) of a ground wrench (world, about the origin: torque, force)."""
    return np.array(zmp_xy(wrench, ground_height))


def zmp_xy(wrench, ground_height=0.0):
    """zmp_of as two floats (x, y)."""
    n0, n1, _, f0, f1, f2 = np.asarray(wrench, float).tolist()
    h = float(ground_height)
    return (h * f0 - n1) / f2, (n0 + h * f1) / f2


def _on_ground(xy, height):
    """The ground point (3,) below (x, y)."""
    return np.append(np.asarray(xy, float), float(height))


def moment_about(wrench, point):
    """The wrench's torque (3,) about a world point."""
    return wrench[:3] - np.cross(np.asarray(point, float)[:3], wrench[3:6])


def _xyz(x):
    return tuple(float(c) for c in x[:3])


def _skew(p):
    """skew(p) (3, 3): skew(p) @ x = p x x (np.cross(p, columns) as one product)."""
    p0, p1, p2 = _xyz(p)
    return np.array([[0.0, -p2, p1], [p2, 0.0, -p0], [-p1, p0, 0.0]])


def balance_error(state, wrench, polygon=None):
    """(zmp, mmp, distance) of a ground wrench on the current support polygon; mmp is None when
    nothing supports the body (no foot down) or nothing pushes on the ground. Remembered per
    state, wrench and polygon (the control sequence asks for the same one several times)."""
    polygon = support_polygon(state) if polygon is None else polygon
    memo = state.balance_memo
    key = (np.asarray(wrench, float).tobytes(), id(polygon))
    known = memo.get(key)
    if known is not None and known[0] is polygon:
        return known[1]
    out = _balance_error(state, wrench, polygon)
    memo[key] = (polygon, out)
    return out


def _balance_error(state, wrench, polygon):
    if len(polygon) == 0 or wrench[5] <= MIN_SUPPORT * state.constants.weight:
        return None, None, 0.0
    # the ZMP, the test and the MMP on plain floats (inside_xy, closest_boundary_xy) save 5.7-7.5 %
    # of a Dynamic Control bake (benchmarks/microopt.py, balance_zmp_mmp_floats) over the plain
    # formula on arrays: p = zmp_of(wrench); mmp = minimum_moment_point(polygon, p); |mmp - p|
    px, py = zmp_xy(wrench, state.ground_height)
    p = np.array([px, py])
    pts = polygon.tolist()
    if len(pts) >= 3 and inside_xy(pts, px, py):
        return p, p.copy(), 0.0
    mx, my = closest_boundary_xy(pts, px, py)
    dx, dy = mx - px, my - py
    return p, np.array((mx, my)), math.sqrt(dx * dx + dy * dy)


# ---- the augmented body (fig. 2.5, eq. 2.13-2.14) ---------------------------------------------

@dataclass
class AugmentedBody:
    """The composite bodies below DOFs: mass (k,), centre of mass (k, 3), the acceleration (k, 3)
    of that centre per unit joint acceleration (a of fig. 2.5), and the rate of the whole body's
    spatial momentum (6, k) (world, about the origin: torque, force) per unit joint acceleration."""

    mass: np.ndarray
    com: np.ndarray
    acceleration: np.ndarray
    momentum_rate: np.ndarray


def augmented_body(state, dofs=None):
    """The augmented bodies of DOFs (all by default) at rest (velocity terms excluded)."""
    m, d, q = state.model, state.data, state.q
    dofs = np.arange(m.nv) if dofs is None else np.asarray(dofs, int)
    rate = momentum_rate(state)[:, dofs]
    if state.subtree_mass_com is None:
        state.subtree_mass_com = _subtree_mc(m, d, q)
    mass_c = state.subtree_mass_com
    b = m.dof_body[dofs]
    mass, com = mass_c[0][b], mass_c[1][b]
    return AugmentedBody(mass, com, rate[3:].T / mass[:, None], rate)


def momentum_rate(state):
    """The whole body's rate of spatial momentum (6, nv) per unit joint acceleration (once per
    state)."""
    if state.momentum_rate is None:
        state.momentum_rate = _momentum_rate(state.model, state.data, state.q)
    return state.momentum_rate


def _momentum_rate(model, data, q):
    s = motion_subspace(model, data, q)
    ic = composite_inertias(model, data, q)
    return np.einsum("kij,kj->ik", ic.take(model.dof_body, axis=0), s)


def _subtree_mc(model, data, q):
    mass = model.ancestors.T @ model.mass
    return mass, (model.ancestors.T @ (model.mass[:, None] * body_com(model, data, q))) / mass[:, None]


def zmp_jacobian(state, wrench, dofs=None):
    """Eq. 2.13-2.14 (Z up): d ZMP / d theta'' (2, k) at the ZMP of `wrench`."""
    rate = augmented_body(state, dofs).momentum_rate
    p = _on_ground(zmp_xy(wrench, state.ground_height), state.ground_height)
    dn = rate[:3] - _skew(p) @ rate[3:]  # moment change about the ZMP
    return np.vstack((-dn[1], dn[0])) / wrench[5]


def moment_rows(rate, point):
    """(2, k): horizontal moment about a ground point of the momentum rate columns (6, k)."""
    return rate[:2] - _skew(point)[:2].dot(rate[3:])


# ---- balance control of one part --------------------------------------------------------------

def balance_candidates(state, part, a):
    """The part's acceleration of least norm that moves the ZMP of `a` to its MMP (eq. 2.13-2.14
    as the linear condition 'no horizontal moment about the MMP'), uncapped (control_sequence caps
    the one that acts: comfort_control.bounded). Empty when balanced."""
    wrench = required_torques(state, a)[1]
    p, mmp, dist = balance_error(state, wrench)
    if mmp is None or dist <= state.settings.zmp_tolerance:
        return []
    # the ZMP goes back just inside the tolerance: the MMP itself for a tolerance of ~0, the input's
    # own excursion for captured motion (controller's baseline)
    target = mmp + (p - mmp) * (0.9 * state.settings.zmp_tolerance / dist)
    point = _on_ground(target, state.ground_height)
    rate = momentum_rate(state)
    matrix = part_matrix(state, part)
    if part == "legs":  # horizontally: unloading the feet is no way to balance
        matrix = matrix * np.array([1.0, 1.0, 0.0])
    rows = moment_rows(rate.dot(matrix), point)
    if np.abs(rows).max() < 1e-9:
        return []
    x = pinv(rows, rcond=state.settings.rcond).dot(-moment_about(wrench, point)[:2])
    return [x]


def balance_criterion(state, part, active, current):
    """Balance is judged on the current acceleration (passive change included)."""
    return balance_candidates(state, part, current)


# ---- falling (sec. 2.3.3) ---------------------------------------------------------------------

@dataclass
class Falling:
    """A figure whose ZMP stays outside its support turns about the MMP."""

    mmp: np.ndarray  # (2,) the axis passes through (mmp, ground_height)
    segment: int  # the supporting segment: the foot in contact nearest the MMP (bone index)
    angular_acceleration: np.ndarray  # (3,) world, horizontal
    base_acceleration: np.ndarray  # (nv,) that rotation as base DOFs (add to the output)


def falling(state, wrench, mmp):
    """Rotation about the MMP: the ground's missing horizontal moment about it, over the whole
    body's moment of inertia about that axis; None when the moment vanishes."""
    point = _on_ground(mmp, state.ground_height)
    torque = moment_about(wrench, point)
    torque[2] = 0.0
    size = np.linalg.norm(torque)
    if size < 1e-9:
        return None
    axis = torque / size
    alpha = -torque / float(axis @ whole_body_inertia(state, point) @ axis)
    m, d = state.model, state.data
    base = np.zeros(m.nv)
    base[:6] = np.linalg.solve(d.motion[0], np.concatenate((alpha, np.cross(point, alpha))))
    return Falling(np.asarray(mmp, float), _supporting_foot(state, mmp), alpha, base)


def whole_body_inertia(state, point):
    """Rotational inertia (3, 3) of the whole body about a world point, world axes."""
    m, d = state.model, state.data
    update_frames(m, d, state.q)
    rot = d.frames[:, :3, :3]
    r = body_com(m, d, state.q) - point
    own = np.einsum("bij,bjk,blk->il", rot, m.inertia, rot)
    return own + np.einsum("b,bij->ij", m.mass, np.einsum("bk,bk->b", r, r)[:, None, None] * np.eye(3)
                           - r[:, :, None] * r[:, None, :])


def _supporting_foot(state, mmp):
    soles = state.sole_world()
    sides = np.flatnonzero(state.feet)
    dist = [np.linalg.norm(soles[s][:, :2].mean(axis=0) - mmp) for s in sides]
    return int(state.parts.feet[sides[int(np.argmin(dist))]])


# ---- balance control alone ----------------------------------------------------------------------

@dataclass
class BalanceResult:
    delta: np.ndarray  # (nv,) change of acceleration
    zmp_before: np.ndarray  # (2,) or None
    zmp: np.ndarray  # (2,) at the output, or None
    mmp: np.ndarray  # (2,) at the output, or None
    polygon: np.ndarray  # (m, 2)
    falling: Falling  # or None
    log: ControlLog


def balance_control(state, a):
    """Balance control alone (no comfort control): arms, back, then legs move the ZMP to the MMP;
    exactly zero change when the ZMP is inside the support polygon. Passive control of the upper
    body stays on: it is what limits the arms and back to their strength (sec. 2.5.3), leaving the
    rest to the legs."""
    a = np.asarray(a, float)
    polygon = support_polygon(state)
    p0, mmp, dist = balance_error(state, required_torques(state, a)[1], polygon)
    log = ControlLog(state.model.nv)
    if mmp is None or dist <= state.settings.zmp_tolerance:
        return BalanceResult(np.zeros_like(a), p0, p0, mmp, polygon, None, log)
    out, log = control_sequence(state, a, {"balance": balance_criterion}, log=log)
    return finish_balance(state, a, out, p0, polygon, log)


def finish_balance(state, a, out, p0, polygon, log):
    """The output's ZMP and MMP, and the fall when the ZMP stayed outside."""
    wrench = required_torques(state, out)[1]
    p, mmp, dist = balance_error(state, wrench, polygon)
    fall = falling(state, wrench, mmp) if mmp is not None and dist > state.settings.zmp_tolerance else None
    return BalanceResult(out - a, p0, p, mmp, polygon, fall, log)
