"""The whole drive in one compiled loop, no FMI: the limit that the co-simulation is measured against
(``pmsm-cosim bench``, case (h); ``pmsm_ev.whole_loop`` builds its buffers and reads its rows).

``whole_loop`` runs the base steps of a plant FMU and a controller FMU wired as the shipped scenarios wire them
(``plant.i_alpha, i_beta, theta_e, omega_m -> ctrl.i_alpha, i_beta, theta_meas, omega_meas``;
``ctrl.v_alpha, v_beta, T_brake -> plant.v_alpha, v_beta, T_brake``), Gauss-Seidel as the master steps them:
at t_n the scenario signals take their value of step n, the row of t_n is recorded if due, the controller reads
the plant's outputs and steps (``unit_fmu_step``), then the plant reads the controller's and steps
(``plant_fmu_step``). The two steps are the FMUs' own compiled steps on the buffers their slaves hand the lean
binding (``pmsm_ev.kernels.fmu``), so nothing of the physics or of the slaves' bookkeeping is written here a
second time: what this loop adds is what the master does between the steps (the transfers, the signals, the
rows).

The signals are sampled as the master samples them (``pmsm_cosim.engine.master``, ``_update_signals``): a
signal's events, one row each of ``ev`` (``EV_*``), say that at step ``EV_N`` its value is ``EV_VALUE`` (the
master's evaluation of the profile there) and, up to step ``EV_RAMP_END`` (exclusive), that it follows the ramp
``v0 + dv * (t - t0) / dt`` with the constants ``EV_V0 .. EV_DT``, the master's formula; ``target`` row k:
where signal k goes (``TARGET_PLANT`` or ``TARGET_UNIT``, the slot of that buffer). A recorded row is one row of
``rows``; ``cols`` row j says where its column j comes from (``COL_*``, a slot); with ``states`` of one row per
recorded row, the unit's state vector is copied there too (the columns that the unit's Python properties give,
``COL_LATER``, are filled from it afterwards).
"""

from __future__ import annotations

from .fmu import STEP_TAKEN, plant_fmu_step, unit_fmu_step
from .jit import kernel
from .layout import (
    PIO_I_ALPHA,
    PIO_I_BETA,
    PIO_I_D,
    PIO_I_Q,
    PIO_OMEGA_M,
    PIO_T_BRAKE,
    PIO_THETA_E,
    PIO_V_ALPHA,
    PIO_V_BETA,
    UIO_I_ALPHA,
    UIO_I_BETA,
    UIO_OMEGA_MEAS,
    UIO_T_BRAKE,
    UIO_THETA_MEAS,
    UIO_V_ALPHA,
    UIO_V_BETA,
)
from .plant import stored_energies

#: the columns of a signal's event (``ev``)
EV_N, EV_VALUE, EV_RAMP_END, EV_V0, EV_DV, EV_T0, EV_DT = range(7)
EV_COLUMNS = 7
#: where a signal goes (``target`` column 0)
TARGET_PLANT, TARGET_UNIT = 0, 1
#: where a recorded column comes from (``cols`` column 0; column 1 the slot): the time; signal ``slot``'s value;
#: the plant's buffer, its energy vector, the controller's buffer; the plant's stored magnetic and kinetic
#: energies (``stored_energies``); a column filled afterwards from the unit's state (``states``)
COL_TIME, COL_SIGNAL, COL_PLANT, COL_ENERGY, COL_UNIT, COL_W_MAGNETIC, COL_E_KINETIC, COL_LATER = range(8)
#: ... the plant's parameter vector (R_s and psi now, which the thermal network moves: ``R_s_now``, ``psi_now``)
COL_PARAM = 8
#: the returns of ``whole_loop`` (with the step reached): done; the controller's or the plant's compiled step
#: did not take step n (declined or failed: nothing of that component changed; the steps before n are taken)
LOOP_DONE, LOOP_UNIT_STOPPED, LOOP_PLANT_STOPPED = 0, 1, 2


@kernel()
def _record(r, n, h, pio, ee, pp, uio, s, value, cols, rows, states):
    """Row r of ``rows`` (and of ``states``) from the buffers at step n."""
    for j in range(cols.shape[0]):
        kind = cols[j, 0]
        slot = cols[j, 1]
        if kind == COL_TIME:
            x = n * h
        elif kind == COL_SIGNAL:
            x = value[slot]
        elif kind == COL_PLANT:
            x = pio[slot]
        elif kind == COL_ENERGY:
            x = ee[slot]
        elif kind == COL_UNIT:
            x = uio[slot]
        elif kind == COL_W_MAGNETIC or kind == COL_E_KINETIC:
            w_mag, e_kin = stored_energies(pio[PIO_I_D], pio[PIO_I_Q], pio[PIO_OMEGA_M], pp)
            x = w_mag if kind == COL_W_MAGNETIC else e_kin
        elif kind == COL_PARAM:
            x = pp[slot]
        else:
            x = 0.0
        rows[r, j] = x
    if states.shape[0] > 0:
        for i in range(s.shape[0]):
            states[r, i] = s[i]


@kernel()
def whole_loop(pio, pp, ee, uio, s, c, n0, n_steps, h, every, ev, first, last, ptr, value, ramp, target, cols,
               rows, states, r0):
    """The base steps n0 .. ``n_steps`` (the last one only recorded) of the system of the module doc, rows from
    ``rows[r0]`` on. ``first[k] .. last[k]-1``: signal k's rows of ``ev``; ``ptr[k]`` its next event,
    ``value[k]`` its value and ``ramp[k]`` its ramp's constants (``EV_RAMP_END`` .. ``EV_DT`` as floats), all
    carried over between calls. Returns (the step reached, the row reached, ``LOOP_*``)."""
    r = r0
    for n in range(n0, n_steps + 1):
        t = n * h
        for k in range(first.shape[0]):
            p = ptr[k]
            if p < last[k] and n == ev[p, EV_N]:
                value[k] = ev[p, EV_VALUE]
                for i in range(4):
                    ramp[k, 1 + i] = ev[p, EV_V0 + i]
                ramp[k, 0] = ev[p, EV_RAMP_END]
                ptr[k] = p + 1
            elif n < ramp[k, 0]:
                value[k] = ramp[k, 1] + ramp[k, 2] * (t - ramp[k, 3]) / ramp[k, 4]
            if target[k, 0] == TARGET_PLANT:
                pio[target[k, 1]] = value[k]
            else:
                uio[target[k, 1]] = value[k]
        if n % every == 0 or n == n_steps:
            _record(r, n, h, pio, ee, pp, uio, s, value, cols, rows, states)
            r += 1
        if n == n_steps:
            break
        uio[UIO_I_ALPHA] = pio[PIO_I_ALPHA]
        uio[UIO_I_BETA] = pio[PIO_I_BETA]
        uio[UIO_THETA_MEAS] = pio[PIO_THETA_E]
        uio[UIO_OMEGA_MEAS] = pio[PIO_OMEGA_M]
        if unit_fmu_step(uio, s, c, t, h) != STEP_TAKEN:
            return n, r, LOOP_UNIT_STOPPED
        pio[PIO_V_ALPHA] = uio[UIO_V_ALPHA]
        pio[PIO_V_BETA] = uio[UIO_V_BETA]
        pio[PIO_T_BRAKE] = uio[UIO_T_BRAKE]
        if plant_fmu_step(pio, pp, ee, h) != STEP_TAKEN:
            return n, r, LOOP_PLANT_STOPPED
    return n_steps, r, LOOP_DONE

