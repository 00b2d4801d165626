"""The drive as one compiled loop, no FMI (``pmsm_ev.kernels.whole_loop``): a plant and a control unit on the
buffers their FMUs' compiled steps run on, stepped Gauss-Seidel with the master's transfers, signals and rows.

``WholeLoop`` steps a ``Plant`` and a ``ControlUnit`` made from the parameter groups the FMUs make them from, on
their buffers as the slaves hand them to the lean binding when they are initialised (``Plant.io``,
``ControlUnit.io`` filled by ``ControlUnit.load_io``, ``PmsmEvPlant.compiled_step``, ``FocSlave.compiled_step``;
the ``dt`` parameter 0: the sample period is the first step's); ``run`` takes the signals' events and the
recorded columns (``pmsm_cosim.app.whole_loop`` makes them from a system file, the master's way) and returns the
rows. A step the FMUs' compiled steps do not
take (``pmsm_ev.kernels.fmu``) is taken as the FMU takes it: a plant step (a voltage at or near the DC link's
limit, where ``math.hypot`` decides) by the plant's Python step (``WholeLoop.python_plant_step``), then the loop
goes on; a controller step (its unit rebuilt for another period) is not covered: ``run`` raises ``NotCovered``.
"""

from __future__ import annotations

import math

import numpy as np

from . import accel
from . import kernels as _k
from .control_unit import ControlUnit
from .plant import Plant


class NotCovered(RuntimeError):
    """A system, or a step of it, that the whole loop does not run (the reason in the message)."""


class WholeLoop:
    """A plant and a control unit on the FMUs' compiled-step buffers (the module doc)."""

    def __init__(self, plant: Plant, unit: ControlUnit, unit_dt: float = 0.0):
        """``unit_dt``: the controller FMU's ``dt`` parameter (0: the first step's size)."""
        if not accel.compiled():
            raise NotCovered("the whole loop needs the compiled kernels (numba)")
        if plant.delay:
            raise NotCovered("the plant's inverter delay is not in the FMU's compiled step")
        self.plant, self.unit = plant, unit
        self._kernels = accel.kernels()
        #: the buffers: the plant's and the unit's own, as the FMUs hand them to the lean binding
        self.pio = plant.io
        unit.load_io(unit.outputs(), unit_dt)
        self.uio = unit.io

    def compile(self) -> None:
        """Compile the loop (or load it from numba's cache) for its argument types: no step taken."""
        go, _, _ = self._loop(-1, 0.0, 1, [[(0.0,) * self._kernels.EV_COLUMNS]], [(0, 0)],
                              np.zeros((1, 2), dtype=np.intp), 1, False)
        go(0)

    def _loop(self, n_steps, h, every, events, targets, cols, n_rows, states):
        """A callable ``go(n0) -> (step reached, rows made, LOOP_*)`` on the arrays of one run, its rows, its
        unit states."""
        k = self._kernels
        n_sig = len(events)
        ev = np.array([e for evs in events for e in evs], dtype=np.float64).reshape(-1, k.EV_COLUMNS)
        first = np.zeros(n_sig, dtype=np.intp)
        last = np.zeros(n_sig, dtype=np.intp)
        at = 0
        for i, evs in enumerate(events):
            first[i], at = at, at + len(evs)
            last[i] = at
        ptr = first.copy()
        value = np.zeros(n_sig)
        ramp = np.zeros((n_sig, 5))
        target = np.array(targets, dtype=np.intp).reshape(n_sig, 2)
        rows = np.zeros((n_rows, cols.shape[0]))
        state_rows = np.zeros((n_rows if states else 0, _k.UNIT_STATE))
        u, p = self.unit, self.plant
        made = [0]

        def go(n_from):
            n, r, code = k.whole_loop(self.pio, p._pp, p.energy, self.uio, u._s, u._c, n_from, n_steps, h, every, ev,
                                      first, last, ptr, value, ramp, target, cols, rows, state_rows, made[0])
            made[0] = r
            return n, r, code

        return go, rows, state_rows

    def run(self, n_steps: int, h: float, every: int, events, targets, cols, states: bool = False):
        """Steps 0 .. ``n_steps`` of ``h``, a row every ``every`` and at the last: (rows, unit states: one row per
        recorded row when ``states``). ``events``: per signal, its events (``kernels.loop``, ``EV_*``);
        ``targets``: per signal, (``TARGET_PLANT`` or ``TARGET_UNIT``, the slot); ``cols``: per column, (``COL_*``,
        slot). A plant step that the FMU's compiled step declines is the FMU's Python step (``python_plant_step``),
        as in the FMU; ``NotCovered`` at a controller step it declines."""
        k = self._kernels
        n_rows = n_steps // every + 1 + (1 if n_steps % every else 0)
        cols = np.asarray(cols, dtype=np.intp).reshape(-1, 2)
        go, rows, state_rows = self._loop(n_steps, h, every, events, targets, cols, n_rows, states)
        n, r, code = go(0)
        while code == k.LOOP_PLANT_STOPPED:
            self.python_plant_step(n, h)
            n, r, code = go(n + 1)
        if code != k.LOOP_DONE:
            raise NotCovered(f"the controller's compiled step did not take the step at t = {n * h:.9g} s (step {n}): "
                             f"the FMU runs its Python step there, which the whole loop does not have")
        return rows[:r], state_rows[:r]

    def python_plant_step(self, n: int, h: float) -> None:
        """Step n of the plant as the plant FMU takes a step its compiled step declines: its Python step
        (``Plant.step`` on its inputs held in its buffer); ``FloatingPointError`` if the state is not finite (the
        FMU fails the step)."""
        p, pio = self.plant, self.pio
        p.step(float(pio[_k.PIO_V_ALPHA]), float(pio[_k.PIO_V_BETA]), float(pio[_k.PIO_DELTA]), h,
               float(pio[_k.PIO_T_BRAKE]))
        if not math.isfinite(p.omega_m + p.i_d + p.i_q):
            raise FloatingPointError(f"plant state is not finite at t = {(n + 1) * h!r} s")
