"""Cholesky solves of the kernel's small system in place, on preallocated buffers.

scipy.linalg.lapack.dposv called the usual way copies A into a new Fortran-ordered array, the
right side into another and returns new arrays: on a 10 x 10 system the copies cost a third of
the call. A is symmetric, so its C-ordered buffer seen transposed (A.T, a Fortran-ordered view
of the same memory) is A itself: with overwrite_a and overwrite_b the wrapper factors A in its own
buffer and leaves the solution in b's, with no copies. (Calling LAPACK through ctypes instead
was measured no faster: the factorisation itself, not the wrapper, is most of the time.)"""

from scipy.linalg.lapack import dposv, dpotrs


class CholeskySolver:
    """A x = b in place for a fixed n x n buffer `A` (C-contiguous, symmetric when solved) and
    right side `b` (1-D, contiguous). solve() factors A (A <- its Cholesky factor) and overwrites
    b with x, returning True, or returns False when A is not positive definite (b untouched, A
    overwritten); resolve() solves again with the factor of the last successful solve(), in place
    of b."""

    def __init__(self, A, b):
        n = A.shape[0]
        if A.shape != (n, n) or not A.flags.c_contiguous or b.shape != (n,) or not b.flags.c_contiguous:
            raise ValueError("CholeskySolver needs a contiguous n x n matrix and n-vector")
        self.A, self.At, self.b = A, A.T, b

    def solve(self):
        factor, x, info = dposv(self.At, self.b, lower=0, overwrite_a=1, overwrite_b=1)
        if info:
            return False
        if x is not self.b:                       # the wrapper had to copy after all
            self.b[...] = x
        self._factor = factor
        return True

    def resolve(self):
        x = dpotrs(self._factor, self.b, lower=0, overwrite_b=1)[0]
        if x is not self.b:
            self.b[...] = x
