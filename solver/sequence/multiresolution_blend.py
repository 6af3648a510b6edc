"""Joining two sequences band by band (Huang 1996 table 5-5), and the plain weighted sum (eq. 5-8).

Sequence A covers frames [0, Fa - 1] of the output timeline, B covers [s, s + Fb - 1], s >= 0
(frames of the same rate). Two cases, as in the thesis:
- B ends after A: the transition is the overlap [s, Fa - 1] (or a given window inside it); A's
  weight eases from 1 to 0 across it.
- B lies inside A: A's weight eases from 1 at s to 0 at the middle of B and back to 1 at its end.
The output covers [0, max(Fa, s + Fb) - 1].

Multiresolution: both sequences are extended over the whole timeline by point reflection (so each
has a value wherever a band reaches), decomposed into Laplacian pyramids on the same dyadic grid,
each band l is blended with the weight seen at that level, and the result is collapsed.
The weight at level l is either the ease curve sampled on that level's grid ('window', the
thesis: the same transition window on every band) or the level l of the weight's own Gaussian
pyramid ('gaussian', Burt and Adelson's multiresolution spline: the window widens with the wave
length of the band).
"""

import numpy as np

from . import channels as _channels
from .pyramid import DEFAULT_A, dyadic_length, gaussian_pyramid, laplacian_pyramid, reflect, reconstruct


def smoothstep(u):
    """Ease-in/ease-out from 0 to 1 on [0, 1] (3u^2 - 2u^3)."""
    u = np.clip(u, 0.0, 1.0)
    return u * u * (3.0 - 2.0 * u)


def _ramp(frames, start, end, ease):
    if end <= start:
        return (frames > start).astype(float)
    return ease((frames - start) / (end - start))


def blend_weights(length_a, start_b, length_b, transition=None, ease=smoothstep):
    """Weight of A on every output frame; `transition` (first, last frame) overrides the window
    of the overlap case."""
    if start_b < 0 or start_b > length_a - 1:
        raise ValueError("B must start inside A (0 <= start_b <= len(A) - 1)")
    end_b = start_b + length_b - 1
    frames = np.arange(max(length_a, end_b + 1), dtype=float)
    if end_b < length_a - 1:  # B inside A
        mid = 0.5 * (start_b + end_b)
        return 1.0 - _ramp(frames, start_b, mid, ease) + _ramp(frames, mid, end_b, ease)
    first, last = (start_b, length_a - 1) if transition is None else transition
    if not start_b <= first <= last <= length_a - 1:
        raise ValueError("the transition must lie where A and B overlap")
    return 1.0 - _ramp(frames, first, last, ease)


def _on_timeline(a, b, start_b, total):
    a = reflect(a, 0, total - len(a))
    b = reflect(b, start_b, total - start_b - len(b))
    return a, b


def weighted_sum_blend(a, b, start_b, transition=None, ease=smoothstep):
    """Eq. 5-8: w(t) A(t) + (1 - w(t)) B(t) on the output timeline."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    w = blend_weights(len(a), start_b, len(b), transition, ease)
    a, b = _on_timeline(a, b, start_b, len(w))
    w = w.reshape((-1,) + (1,) * (a.ndim - 1))
    return w * a + (1.0 - w) * b


def level_weights(w, levels, mask="window", a=DEFAULT_A):
    """The weight of A at each pyramid level 0..levels, on the extended dyadic grid."""
    n = dyadic_length(len(w), levels)
    w = np.concatenate((w, np.full(n - len(w), w[-1])))  # constant beyond the end
    if mask == "window":
        return [w[::2 ** l] for l in range(levels + 1)]
    if mask == "gaussian":
        return [np.clip(g, 0.0, 1.0) for g in gaussian_pyramid(w, levels, a)]
    raise ValueError(f"mask must be 'window' or 'gaussian', not {mask!r}")


def multiresolution_blend(a, b, start_b, levels=None, transition=None, ease=smoothstep,
                          mask="window", kernel_a=DEFAULT_A):
    """Table 5-5: blend the Laplacian pyramids of A and B band by band and reconstruct.
    `levels` default: enough that the coarsest band's sample step spans the transition."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    w = blend_weights(len(a), start_b, len(b), transition, ease)
    a, b = _on_timeline(a, b, start_b, len(w))
    if levels is None:
        span = np.count_nonzero((w > 0.0) & (w < 1.0)) + 2
        levels = int(np.clip(np.ceil(np.log2(span)), 1, np.ceil(np.log2(len(w) - 1))))
    pa, pb = laplacian_pyramid(a, levels, kernel_a), laplacian_pyramid(b, levels, kernel_a)
    ws = [x.reshape((-1,) + (1,) * (a.ndim - 1)) for x in level_weights(w, levels, mask, kernel_a)]
    pa.bands = [ws[l] * la + (1.0 - ws[l]) * lb for l, (la, lb) in enumerate(zip(pa.bands, pb.bands))]
    pa.top = ws[-1] * pa.top + (1.0 - ws[-1]) * pb.top
    return reconstruct(pa)


def blend_quaternions(qa, qb, start_b, method="multiresolution", **kw):
    """Blend quaternion curves (Fa, ..., 4) and (Fb, ..., 4) in the tangent space about their
    common mean; unit quaternions on the hemisphere of qa's first frame."""
    qa = _channels.rotations.make_continuous(qa)
    qb = _channels.rotations.make_continuous(qb)
    ref = _channels.mean_quaternion(np.concatenate((qa, qb)))
    va, vb = _channels.to_tangent(qa, ref), _channels.to_tangent(qb, ref)
    shape = va.shape[1:]
    fn = multiresolution_blend if method == "multiresolution" else weighted_sum_blend
    v = fn(va.reshape(len(va), -1), vb.reshape(len(vb), -1), start_b, **kw)
    return _channels.from_tangent(v.reshape((len(v),) + shape), ref, like=qa)


def blend_euler(ea, eb, start_b, orders="XYZ", method="multiresolution", **kw):
    """Blend Euler curves (Fa, J, 3) and (Fb, J, 3) (radians): both unrolled, B moved by whole
    turns onto A's branch at the frame where it starts."""
    ea, eb = _channels.unroll_euler(ea, orders), _channels.unroll_euler(eb, orders)
    eb = eb - 2.0 * np.pi * np.round((eb[0] - ea[start_b]) / (2.0 * np.pi))
    fn = multiresolution_blend if method == "multiresolution" else weighted_sum_blend
    out = fn(ea.reshape(len(ea), -1), eb.reshape(len(eb), -1), start_b, **kw)
    return out.reshape((len(out),) + ea.shape[1:])
