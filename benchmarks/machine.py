"""The machine's speed, printed beside the figures it scales: a shared or throttled host (other
guests, CPU taken by the hypervisor) can make every figure of one run twice another's."""

import time

import numpy as np


def numpy_op_us(count=20000):
    """CPU microseconds of one small numpy operation, a + b on (66, 3): the price of each of the
    many small calls the solvers make, so the indicator of how fast this host is right now."""
    a, b = np.random.rand(66, 3), np.random.rand(66, 3)
    t = time.process_time()
    for _ in range(count):
        a + b
    return (time.process_time() - t) / count * 1e6
