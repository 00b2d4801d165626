"""How the kernels are compiled: the ``kernel`` decorator and numba's type signatures.

``pmsm_ev.accel`` loads the kernels package either as plain Python (as it is) or compiled with
numba: it sets ``JIT = True`` (and ``CACHE``, numba's on-disk cache) on the package module before
the package's body runs; this module reads them from there when the package imports it first.
"""

from __future__ import annotations

import sys

_package = sys.modules[__name__.rpartition(".")[0]]
#: compile the kernels with numba (set by ``pmsm_ev.accel`` on the package)
JIT = bool(getattr(_package, "JIT", False))
#: numba's on-disk cache on (set likewise)
CACHE = bool(getattr(_package, "CACHE", False))

if JIT:
    from numba import njit

    def kernel(signature=None):
        """Compile with numba: eagerly for ``signature`` (a top-level kernel), else lazily
        when a compiled caller first needs it."""
        def wrap(fn):
            options = {"cache": CACHE}
            return njit(signature, **options)(fn) if signature else njit(**options)(fn)
        return wrap
else:
    def kernel(signature=None):
        """Plain Python: the function as written."""
        def wrap(fn):
            return fn
        return wrap

def table(rows):
    """A constant table of float rows as the kernels read it: compiled, a numpy array (numba keeps a
    global array as read-only data: a lookup reads memory, where a tuple of tuples is rebuilt on the
    stack at each call); plain Python, the rows as they are."""
    if not JIT:
        return rows
    import numpy as np  # noqa: PLC0415 - numpy is there wherever numba is

    return np.array(rows, dtype=np.float64)


F = "float64"  #: numba's type of a float argument
V = "float64[::1]"  #: ... of a vector (contiguous)


def sig(result: str, *args: str) -> str:
    """numba's signature string ``result(arg, ...)``."""
    return f"{result}({', '.join(args)})"
