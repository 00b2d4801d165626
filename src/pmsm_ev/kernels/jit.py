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
    from numba.core import typeinfer
    from numba.core.registry import CPUDispatcher

    class _Kernel(CPUDispatcher):
        """A top-level kernel: numba's dispatcher of its one ``signature``, compiled (or loaded from numba's
        cache) when first needed (called from Python, typed by a compiled caller, or ``ready``), then closed
        to any other signature, as ``njit(signature)`` makes it at once. A process loads only the kernels it
        runs: the same machine code, the same numbers."""

        _pending = None  #: the signature not compiled yet

        def ready(self):
            """Compile (or load) the kernel's signature now, if not done yet."""
            signature = self._pending
            if signature is not None:
                with typeinfer.register_dispatcher(self):
                    self.compile(signature)
                self.disable_compile()
                self._pending = None
            return self

        def get_call_template(self, args, kws):
            self.ready()
            return super().get_call_template(args, kws)

        def _compile_for_args(self, *args, **kws):
            # numba's dispatch calls this on a call no compiled signature takes while it may compile (before the
            # kernel is ready, or in another thread meanwhile), and calls what it returns: the call dispatched
            # again, to the one signature now compiled (converted to it, or a TypeError, as with njit(signature))
            return self.ready().__call__

    def kernel(signature=None):
        """Compile with numba: for ``signature`` (a top-level kernel) when it is first needed (``_Kernel``),
        else lazily when a compiled caller first needs it."""
        def wrap(fn):
            dispatcher = njit(cache=CACHE)(fn)
            if signature:
                dispatcher.__class__ = _Kernel
                dispatcher._pending = signature
            return dispatcher
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
