"""Current control and discretisation at top speed (issue 23; docs/high-speed.md).

At 131 km/h the motor turns at ~1554 rad/s (omega_e dt = 0.62 rad per 1e-4 s period). The tests run the
kernels the controllers run (``current_step``, ``modulate``, ``control_step``, ``sensorless_step``) on
the plant (``Plant``, whose RK4 takes at most 0.1 rad per sub-step), the speed held where the issue asks
for it by a vehicle of 1e9 kg, and print the figures the issue asks for (``pytest -s`` shows them).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from pmsm_ev import accel
from pmsm_ev import kernels as _k
from pmsm_ev.control_unit import ControlUnit
from pmsm_ev.params import SENSORLESS_EKF, ControllerParams, EkfParams, MotorParams, PlantParams, VehicleParams
from pmsm_ev.plant import Plant
from pmsm_ev.transforms import inverse_park, park

M = MotorParams()
DT = 1e-4
HELD = VehicleParams(m_v=1e9)  #: a vehicle that holds the speed over a current step
#: operating points inside the voltage limit (u_max = 208 V): (omega_m, i_d, i_q), field weakening at
#: 800 and 1500 rad/s (the back-EMF N omega psi is 287 V and 538 V there)
POINTS = {200: (0.0, 50.0), 800: (-200.0, 50.0), 1500: (-380.0, 50.0)}
STEP = 30.0  #: the size of each current step [A]
SETTLE = 400  #: periods at the operating point before the step
AFTER = 300  #: periods recorded after it (30 ms: the integrators' zero R_s/L = 30-43 rad/s is slow)


def _wrap(x):
    return (x + math.pi) % (2.0 * math.pi) - math.pi


def current_run(mode: str, omega_m: float, refs, i_d0: float, i_q0: float, plant_params=None,
                controller=None):
    """The sensored drive's current loop, its speed held: at each period the measured currents in the
    rotor frame (the measured angle), ``current_step`` (the unit's current PIs, of ``mode``) and
    ``modulate`` (inverse Park with the angle advance and ZOH gain), the vector held over the period by
    the plant. ``refs(k)`` gives (i_dref, i_qref) of period k. The integrators and the decoupling filters
    start at the operating point (i_d0, i_q0). Returns the currents [A] at each period, (k, 2)."""
    ctrl = controller or ControllerParams(current_control=mode)
    unit = ControlUnit("sensored", controller=ctrl, dt=DT)
    s, c = unit._s, unit._c
    kern = accel.kernels()
    plant = Plant(vehicle=HELD, plant=plant_params or PlantParams(omega_m0=omega_m, i_d0=i_d0, i_q0=i_q0))
    s[_k.S_INT_D], s[_k.S_INT_Q] = M.R_s * i_d0, M.R_s * i_q0  # the PIs' share of the steady voltage
    s[_k.S_I_DL], s[_k.S_I_QL] = i_d0, i_q0
    out = []
    n = 0
    while True:
        ref = refs(n)
        if ref is None:
            break
        theta = plant.theta_e
        i_d, i_q = park(plant.i_alpha, plant.i_beta, theta)
        out.append((i_d, i_q))
        v_d, v_q = kern.current_step(s, c, ref[0], ref[1], i_d, i_q, plant.omega_m)
        v_alpha, v_beta = kern.modulate(c, v_d, v_q, theta, plant.omega_m, True)
        plant.step(v_alpha, v_beta, 0.0, DT)
        n += 1
    return np.array(out)


def step_figures(mode: str, omega_m: float, axis: int):
    """(overshoot [%], steady-state error [A], largest excursion of the other axis [A]) of a STEP A
    step of the d (axis 0) or q (axis 1) reference at ``omega_m``; the steady-state error is the mean
    error over the last 2 ms of the AFTER periods."""
    i_d0, i_q0 = POINTS[omega_m]
    start = (i_d0, i_q0)
    end = (i_d0 + STEP, i_q0) if axis == 0 else (i_d0, i_q0 + STEP)
    x = current_run(mode, omega_m, lambda k: None if k >= SETTLE + AFTER else (start if k < SETTLE else end),
                    i_d0, i_q0)
    y = x[SETTLE:, axis]
    overshoot = 100.0 * max(np.max(y - end[axis]), 0.0) / STEP
    ss = float(np.mean(y[-20:]) - end[axis])
    cross = float(np.max(np.abs(x[SETTLE:, 1 - axis] - x[SETTLE - 1, 1 - axis])))
    return overshoot, ss, cross


#: stated bounds of the high-speed current control: overshoot [%], |steady-state error| [A], cross-coupled
#: excursion of the other axis [A] (measured: at most 0.04 %, 0.006 A, 0.39 A, at 1500 rad/s)
HS_BOUNDS = (1.0, 0.05, 1.0)


@pytest.mark.parametrize("omega_m", [200, 800, 1500])
def test_current_steps_of_the_high_speed_control(omega_m):
    for axis, name in ((0, "d"), (1, "q")):
        over, ss, cross = step_figures("high_speed", omega_m, axis)
        print(f"\nhigh_speed, {omega_m} rad/s (omega_e dt = {M.N * omega_m * DT:.2f} rad), {name} step "
              f"{STEP:+.0f} A at i_d, i_q = {POINTS[omega_m]} A: overshoot {over:.2f} %, steady-state error "
              f"{ss:+.3f} A, other axis moved {cross:.2f} A")
        assert over < HS_BOUNDS[0] and abs(ss) < HS_BOUNDS[1] and cross < HS_BOUNDS[2]


def test_paper_against_high_speed_at_1500_rad_s():
    """At 1500 rad/s the paper's current control (decoupling on the filtered references, no ZOH gain)
    overshoots and is off in the steady state where the high-speed one is not."""
    figs = {}
    for mode in ("paper", "high_speed"):
        for axis, name in ((0, "d"), (1, "q")):
            figs[mode, name] = over, ss, cross = step_figures(mode, 1500, axis)
            print(f"\n{mode:10s} 1500 rad/s, {name} step {STEP:+.0f} A: overshoot {over:.2f} %, steady-state "
                  f"error {ss:+.3f} A, other axis moved {cross:.2f} A")
    for name in ("d", "q"):
        assert figs["high_speed", name][2] < 0.5 * figs["paper", name][2]  # the cross-coupling halved
    assert figs["high_speed", "q"][0] < 0.5 * figs["paper", "q"][0]
    assert abs(figs["high_speed", "q"][1]) < 0.5 * abs(figs["paper", "q"][1])
