"""Cholesky solves of the kernel's small system in place, on preallocated buffers.

The plain formula is b[:] = cho_solve(cho_factor(A), b) (scipy.linalg). Kept in place instead,
since it saves 9-15 % of the flexible thesis workload's time (benchmarks/microopt.py,
flexible_cholesky_in_place, which holds the plain version beside it):
scipy.linalg.lapack.dposv, the same LAPACK routine, with overwrite_a and overwrite_b, on A seen
transposed (A.T, a Fortran-ordered view of the same memory, is A itself for a symmetric A), so
the factor stays in A's buffer and the solution in b's, with no copies."""

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
        if x is not self.b:                       # a copy after all: the solution back into b
            self.b[...] = x
        self._factor = factor
        return True

    def resolve(self):
        x = dpotrs(self._factor, self.b, lower=0, overwrite_b=1)[0]
        if x is not self.b:
            self.b[...] = x
