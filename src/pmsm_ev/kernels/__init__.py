"""The per-step numerics of the drive, written once, in a form numba can compile.

Every equation that runs at each control period lives in this package, one module per subject,
each function's docstring citing its equations:

* ``layout``: the slots of the flat vectors (``P_*``, ``S_*``, ``C_*``), declared once as tables
  of (name, length, meaning) and checked at import, and the mode, fault and observer codes;
* ``transforms``: Park, inverse Park, the angle wrap;
* ``plant``: the PMSM (eqs 10-13), the road load (eqs 2-4, 8, 29), the plant's RK4 step, and the
  inverter's dead time, saturation and temperature;
* ``control``: the controller (eqs 14-20), the dead-time compensation and the control unit's step;
* ``observers``: the EKFs (eqs 23-27, A2-A33) and the magnet flux adaptation;
* ``adaptation``: psi and R_s tracked while driving, a model-reference estimator (eqs AD1-AD6);
* ``references``: the reference generator (torque, speed and voltage to the current references: MTPA,
  field weakening, MTPV, the current and torque limits), the regenerative-braking limit and the friction
  brake's share;
* ``machine``: the sensorless unit's two state machines' events, entry actions and their one ordered
  transition table ``TRANSITIONS`` (looked up by ``lookup``);
* ``startup``: the sensorless unit with the I-f strategy as a state machine (alignment, I-f, handover, the
  stand, synchronism; its step);
* ``injection``: high-frequency injection at and near zero speed (the square wave, its demodulation, the
  tracking observer, the blend with the EKF);
* ``modes``: the sensorless unit with injection as a state machine (modes, detectors, the transition
  table, its step);
* ``fmu``: the FMUs' ``fmi2DoStep`` on flat buffers and its C functions (numba ``cfunc``), which the lean
  binding calls with no Python on the way;
* ``loop``: the whole drive in one compiled loop of the FMUs' compiled steps, no FMI (the benchmark's limit);
* ``jit``: the ``kernel`` decorator (numba or plain Python).

The functions take floats and flat float vectors (a numpy float64 array when compiled, a list of
floats otherwise) whose slots are named by the layout's constants; they allocate nothing. This
module re-exports them all: ``from pmsm_ev.kernels import plant_step``, ``kernels.S_X``.

``pmsm_ev.accel`` loads this package either as plain Python (as it is) or compiled with numba
(``JIT = True`` set on the package before its body runs, see ``jit``), so the reference run, the
FMUs and the tests share one implementation whether numba is there or not. The other modules of
``pmsm_ev`` keep the readable, dataclass-based interface (``pmsm.current_derivatives(..., m)``,
``Plant``, ``ControlUnit``, the observer classes) on top of these functions. The package imports
nothing outside itself but ``math`` (and numba, with numpy for its constant tables, ``jit.table``):
``pmsm_ev.accel`` compiles a copy of it.

Floating-point results are the same compiled or not: the operations are written in the
order of the plain-Python formulas they replaced (numba does not reorder or fuse them
without fastmath), and only functions that numba and CPython compute identically are
used (sin, cos, tanh, sqrt, %; not math.hypot, whose CPython 3.10+ algorithm differs in
the last bit).
"""

from __future__ import annotations

from .adaptation import *  # noqa: F403 - the package's interface is all its kernels and constants
from .control import *  # noqa: F403
from .fmu import *  # noqa: F403
from .injection import *  # noqa: F403
from .jit import CACHE, JIT  # noqa: F401 - how this copy was loaded (pmsm_ev.accel reads it)
from .layout import *  # noqa: F403
from .loop import *  # noqa: F403
from .machine import *  # noqa: F403
from .modes import *  # noqa: F403
from .observers import *  # noqa: F403
from .plant import *  # noqa: F403
from .references import *  # noqa: F403
from .startup import *  # noqa: F403
from .transforms import *  # noqa: F403
