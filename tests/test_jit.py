"""pslog._jit.kernel: compiled kernels equal their Python originals, and a kernel whose
cache cannot be written anywhere is compiled in memory instead of failing."""

import numpy as np

from pslog._jit import kernel

SOURCE = '''
def total(a):
    s = 0.0
    for x in a:
        s += x
    return s / 0.0 if s < 0 else s
'''


def test_a_kernel_without_a_cache_location_is_compiled_in_memory():
    # a function compiled from a string has no file: numba finds no cache location for it,
    # exactly as for a module in a read-only folder with no writable home
    namespace: dict = {}
    exec(compile(SOURCE, "<no file>", "exec"), namespace)
    fn = kernel(namespace["total"])
    a = np.arange(5.0)
    assert fn(a) == fn.py_func(a) == 10.0
    assert np.isinf(fn(-a - 1))  # numpy's error model: a division by zero gives inf
