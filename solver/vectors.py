"""Small vector helpers shared by the solver's packages."""

import numpy as np

def cross(a, b):
    """np.cross of (..., 3) arrays (broadcast)."""
    return np.cross(np.asarray(a, float), np.asarray(b, float))
