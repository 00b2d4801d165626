"""The drive as one compiled loop, no FMI (``pmsm_ev.kernels.whole_loop``): a plant and a control unit on the
buffers their FMUs' compiled steps run on, stepped Gauss-Seidel with the master's transfers, signals and rows.

``WholeLoop`` makes the ``Plant`` and the ``ControlUnit`` from the parameter groups the FMUs make them from, and
fills the buffers as the slaves fill them for the lean binding when they are initialised
(``PmsmEvPlant.compiled_step``, ``FocSlave.compiled_step`` with the ``dt`` parameter 0: the sample period is
the first step's); ``run`` takes the signals' events and the recorded columns (``pmsm_cosim.app.whole_loop``
makes them from a system file, the master's way) and returns the rows. A step the FMUs' compiled steps do not
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

#: the sample-clock tolerance of the controller FMUs (``pmsm_ev_fmus.foc_slave.SAMPLE_TOLERANCE``)
SAMPLE_TOLERANCE = 1.0e-2
#: the plant FMU's outputs in its buffer, the plant's attributes of the same names (``PmsmEvPlant._IO_OUTPUTS``)
_PLANT_OUTPUTS = ("i_alpha", "i_beta", "i_d", "i_q", "omega_m", "theta_e", "T_e", "T_L_mech", "v_vehicle",
                  "x_vehicle")
#: the plant's own attributes there (``PmsmEvPlant._IO_PLANT``)
_PLANT_STATE = {"delta": _k.PIO_PLANT_DELTA, "T_brake": _k.PIO_PLANT_T_BRAKE, "clock": _k.PIO_CLOCK,
                "samples": _k.PIO_SAMPLES, "v_alpha_applied": _k.PIO_V_ALPHA_APPLIED,
                "v_beta_applied": _k.PIO_V_BETA_APPLIED, "i_alpha_true": _k.PIO_I_ALPHA_TRUE,
                "i_beta_true": _k.PIO_I_BETA_TRUE}


class NotCovered(RuntimeError):
    """A system, or a step of it, that the whole loop does not run (the reason in the message)."""


class WholeLoop:
    """A plant and a control unit on the FMUs' compiled-step buffers (the module doc)."""

    def __init__(self, plant: Plant, unit: ControlUnit, unit_dt: float = 0.0):
        """``unit_dt``: the controller FMU's ``dt`` parameter (0: the first step's size)."""
        if not accel.compiled():
            raise NotCovered("the whole loop needs the compiled kernels (numba)")
        if plant.delay or plant._thermal:
            raise NotCovered("the plant's inverter delay and thermal model are not in the FMU's compiled step")
        self.plant, self.unit = plant, unit
        self._kernels = accel.kernels()
        p, u = plant, unit
        pio = self.pio = np.zeros(_k.PLANT_IO)
        for name in _PLANT_OUTPUTS:
            pio[getattr(_k, "PIO_" + name.upper())] = getattr(p, name)
        for name, slot in _PLANT_STATE.items():
            pio[slot] = getattr(p, name)
        pio[_k.PIO_U_LIM] = p._u_lim
        pio[_k.PIO_SENSORS] = 1.0 if p._sensors else 0.0
        pio[_k.PIO_SEED] = p._seed64 >> 32
        pio[_k.PIO_SEED + 1] = p._seed64 & 0xFFFFFFFF
        for i, value in enumerate(p._sensor_args):
            pio[_k.PIO_SENSOR_ARGS + i] = value
        uio = self.uio = np.zeros(_k.UNIT_IO)
        uio[_k.UIO_V_ALPHA], uio[_k.UIO_V_BETA] = u.v_out
        for name in ("v_d", "v_q", "i_d", "i_q", "i_qref", "mode", "fault", "omega_ctrl"):
            uio[getattr(_k, "UIO_" + name.upper())] = getattr(u, name)
        (uio[_k.UIO_I_D_HAT], uio[_k.UIO_I_Q_HAT], uio[_k.UIO_OMEGA_HAT], uio[_k.UIO_THETA_HAT],
         uio[_k.UIO_T_L_HAT]) = u.estimates
        # FocSlave._copy_outputs: the measured angle (the input's start, 0) where the unit runs on it
        uio[_k.UIO_THETA_CTRL] = u.theta_ctrl if u.sensorless or u.angle_source == "estimated" else 0.0
        uio[_k.UIO_T_BRAKE] = u.T_brake
        uio[_k.UIO_DT] = unit_dt
        uio[_k.UIO_UNIT_DT] = u.dt
        uio[_k.UIO_TOLERANCE] = SAMPLE_TOLERANCE
        uio[_k.UIO_KIND] = (_k.UNIT_KIND_INJECTION if u.injecting else _k.UNIT_KIND_SENSORLESS if u.sensorless
                            else _k.UNIT_KIND_CONTROL)
        uio[_k.UIO_MEASURED] = 1.0 if u.angle_source == "measured" else 0.0
        uio[_k.UIO_REFERENCE] = u.reference

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
        (``Plant.step`` on its inputs held), the plant taken from the buffer and put back
        (``PmsmEvPlant.compiled_pull``, ``compiled_step``); ``FloatingPointError`` if the state is not finite (the
        FMU fails the step)."""
        p, pio = self.plant, self.pio
        for name in _PLANT_OUTPUTS:
            setattr(p, name, float(pio[getattr(_k, "PIO_" + name.upper())]))
        for name, slot in _PLANT_STATE.items():
            setattr(p, name, float(pio[slot]))
        p.samples = int(p.samples)
        p.step(float(pio[_k.PIO_V_ALPHA]), float(pio[_k.PIO_V_BETA]), float(pio[_k.PIO_DELTA]), h,
               float(pio[_k.PIO_T_BRAKE]))
        if not math.isfinite(p.omega_m + p.i_d + p.i_q):
            raise FloatingPointError(f"plant state is not finite at t = {(n + 1) * h!r} s")
        for name in _PLANT_OUTPUTS:
            pio[getattr(_k, "PIO_" + name.upper())] = getattr(p, name)
        for name, slot in _PLANT_STATE.items():
            pio[slot] = getattr(p, name)
