"""Small vector helpers shared by the solver's packages."""

import numpy as np

# a small last axis summed as a product with ones, (x * y).dot(ONES3): a reduction (np.add.reduce,
# einsum) over it costs about four times as much on the solver's small stacks
ONES3, ONES4, ONES6 = np.ones(3), np.ones(4), np.ones(6)


def cross(a, b):
    """np.cross of (..., 3) arrays (broadcast)."""
    return np.cross(np.asarray(a, float), np.asarray(b, float))
