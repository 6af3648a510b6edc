"""Small vectorised helpers: cross products, skew matrices, quaternion maps, spatial operators.

Spatial vectors follow Featherstone: motion (omega, v) and force (n, f), all expressed in world
axes at the world origin unless a name says otherwise. Every function works on stacks (n, ...),
because the dynamics vectorise over bodies instead of looping in Python.
"""

import numpy as np

_EPS = np.zeros((3, 3, 3))
_EPS[0, 1, 2] = _EPS[1, 2, 0] = _EPS[2, 0, 1] = 1.0
_EPS[0, 2, 1] = _EPS[2, 1, 0] = _EPS[1, 0, 2] = -1.0

# skew(w).ravel() = w[_SKEW_IDX] * _SKEW_SIGN (index 3 is a zero slot appended to w)
_SKEW_IDX = np.array([3, 2, 1, 2, 3, 0, 1, 0, 3])
_SKEW_SIGN = np.array([0.0, -1.0, 1.0, 1.0, 0.0, -1.0, -1.0, 1.0, 0.0])
_SKEW_MAP = np.zeros((4, 9))
_SKEW_MAP[_SKEW_IDX, np.arange(9)] = _SKEW_SIGN
_SKEW_MAP = _SKEW_MAP[:3].copy()

# quaternion (w, x, y, z) outer product q q^T (16 terms) to the 9 rotation-matrix entries
_Q2R = np.zeros((16, 9))
for _entry, _terms in enumerate((
        ((0, 0, 1), (1, 1, 1), (2, 2, -1), (3, 3, -1)),
        ((1, 2, 2), (0, 3, -2)), ((1, 3, 2), (0, 2, 2)),
        ((1, 2, 2), (0, 3, 2)), ((0, 0, 1), (1, 1, -1), (2, 2, 1), (3, 3, -1)),
        ((2, 3, 2), (0, 1, -2)),
        ((1, 3, 2), (0, 2, -2)), ((2, 3, 2), (0, 1, 2)),
        ((0, 0, 1), (1, 1, -1), (2, 2, -1), (3, 3, 1)))):
    for _a, _b, _c in _terms:
        _Q2R[4 * _a + _b, _entry] += _c
del _entry, _terms, _a, _b, _c


def cross(a, b):
    """Row-wise cross products of (..., 3) stacks (np.cross is several times slower on small stacks)."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    return (skew(a) @ b[..., None])[..., 0]


def skew(w):
    """Skew matrices (..., 3, 3) with skew(w) @ x = w x x (one product with a constant map)."""
    w = np.asarray(w, dtype=float)
    return w.dot(_SKEW_MAP).reshape(w.shape[:-1] + (3, 3))  # (one nonzero term per entry: exact)


def quat_rows(w, x, y, z):
    """quat_to_matrix of one unit quaternion given as four floats, as three row tuples of floats."""
    return ((w * w + x * x - y * y - z * z, 2.0 * (x * y - w * z), 2.0 * (x * z + w * y)),
            (2.0 * (x * y + w * z), w * w - x * x + y * y - z * z, 2.0 * (y * z - w * x)),
            (2.0 * (x * z - w * y), 2.0 * (y * z + w * x), w * w - x * x - y * y + z * z))


def quat_to_matrix(q):
    """Rotation matrices of unit quaternions (n, 4), without renormalising (callers keep them unit)."""
    q = np.asarray(q, dtype=float)
    outer = (q[..., :, None] * q[..., None, :]).reshape(q.shape[:-1] + (16,))
    return (outer @ _Q2R).reshape(q.shape[:-1] + (3, 3))


def quat_exp(w):
    """Unit quaternions exp(w / 2) for rotation vectors w (..., 3): the rotation by |w| about w."""
    w = np.asarray(w, dtype=float)
    angle = np.linalg.norm(w, axis=-1, keepdims=True)
    half = 0.5 * angle
    # sin(x/2)/x, with its Taylor series near zero to stay exact (angle + small: no division by
    # zero in the branch np.where drops)
    small = angle < 1e-6
    scale = np.where(small, 0.5 - angle * angle / 48.0, np.sin(half) / (angle + small))
    out = np.empty(w.shape[:-1] + (4,))
    out[..., :1] = np.cos(half)
    out[..., 1:] = scale * w
    return out


def quat_log(q):
    """Rotation vectors (..., 3) of unit quaternions, taking the short way round."""
    q = np.asarray(q, dtype=float)
    w = np.abs(q[..., :1])
    xyz = q[..., 1:] * np.where(q[..., :1] < 0.0, -1.0, 1.0)
    s = np.sqrt(np.einsum("...i,...i->...", xyz, xyz))[..., None]
    return log_scale(s, w) * xyz


def log_scale(s, aw):
    """The factor taking a unit quaternion's vector part (norm s, |w| = aw) to its rotation vector:
    2 atan2(s, aw) / s, and 2 / aw below s = 1e-8 (the limit, without dividing by a vanishing s)."""
    small = s < 1e-8
    if not small.any():  # the usual case: no vanishing rotation
        return 2.0 * np.arctan2(s, aw) / s
    return np.where(small, 2.0 / np.maximum(aw, 1e-300), 2.0 * np.arctan2(s, aw) / np.where(small, 1.0, s))


# quaternion product a * b = (a @ _QMUL).reshape(4, 4) @ b: the left-multiplication matrix of a
_QMUL = np.zeros((4, 16))
for _r, _row in enumerate(((0, 1, 2, 3), (1, 0, 3, 2), (2, 3, 0, 1), (3, 2, 1, 0))):
    for _c, _k in enumerate(_row):
        _QMUL[_k, 4 * _r + _c] = ((1, -1, -1, -1), (1, 1, -1, 1), (1, 1, 1, -1), (1, -1, 1, 1))[_r][_c]
del _r, _row, _c, _k
# ... and a * b = outer(a, b).reshape(16) @ _QMUL_OUTER (outer's entry 4 j + l = a_j b_l), for
# stacks one 2-D product; conj(a) * b
# = outer(a, b).reshape(16) @ _CONJ_QMUL_OUTER
_QMUL_OUTER = np.ascontiguousarray(_QMUL.reshape(4, 4, 4).transpose(0, 2, 1).reshape(16, 4))
_CONJ_QMUL_OUTER = _QMUL_OUTER * np.repeat([1.0, -1.0, -1.0, -1.0], 4)[:, None]


def quat_multiply(a, b):
    """Hamilton products a*b of (..., 4) stacks."""
    a = np.asarray(a, dtype=float)
    left = (a @ _QMUL).reshape(a.shape[:-1] + (4, 4))
    return (left @ np.asarray(b, dtype=float)[..., None])[..., 0]


def quat_conjugate(q):
    return q * np.array([1.0, -1.0, -1.0, -1.0])


# crm(m).ravel() = m_ext[_CRM_IDX] * _CRM_SIGN, with m_ext = (omega, v, 0)
_CRM_IDX = np.full(36, 6)
_CRM_SIGN = np.zeros(36)
for _blk_r, _blk_c, _src in ((0, 0, 0), (1, 1, 0), (1, 0, 3)):
    for _r in range(3):
        for _c in range(3):
            _k = _SKEW_IDX[3 * _r + _c]
            if _k < 3:
                _CRM_IDX[6 * (3 * _blk_r + _r) + 3 * _blk_c + _c] = _src + _k
                _CRM_SIGN[6 * (3 * _blk_r + _r) + 3 * _blk_c + _c] = _SKEW_SIGN[3 * _r + _c]
del _blk_r, _blk_c, _src, _r, _c, _k
_CRM_MAP = np.zeros((7, 36))
_CRM_MAP[_CRM_IDX, np.arange(36)] = _CRM_SIGN
_CRM_MAP = _CRM_MAP[:6].copy()


def crm(m):
    """Motion cross-product operators (n, 6, 6): crm(m) @ u = m x u; crf(m) = -crm(m)^T."""
    m = np.asarray(m, dtype=float)
    return m.dot(_CRM_MAP).reshape(m.shape[:-1] + (6, 6))  # (one nonzero term per entry: exact)


def body_spatial_inertia(mass, com, inertia):
    """Spatial inertias (n, 6, 6) about each body's origin from mass, centre of mass and the
    rotational inertia about the centre of mass, all in body axes."""
    mass = np.asarray(mass, dtype=float)
    c = skew(com)
    out = np.zeros(mass.shape + (6, 6))
    m = mass[..., None, None]
    out[..., :3, :3] = inertia + m * (c @ np.swapaxes(c, -1, -2))
    out[..., :3, 3:] = m * c
    out[..., 3:, :3] = -m * c
    out[..., 3:, 3:] = m * np.eye(3)
    return out
