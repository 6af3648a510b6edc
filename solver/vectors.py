"""Small vector helpers shared by the solver's packages."""

import numpy as np

# a small last axis summed as a product with ones, (x * y).dot(ONES3): a reduction (np.add.reduce,
# einsum) over it costs about four times as much on the solver's small stacks
ONES3, ONES4, ONES6 = np.ones(3), np.ones(4), np.ones(6)


def cross(a, b):
    """np.cross of (..., 3) arrays (broadcast) without its axis bookkeeping, which costs several
    times the products on the small stacks the solver's hot loops use; the same products and
    differences, so bit for bit np.cross's components."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out
