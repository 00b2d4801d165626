"""Steady-state losses and efficiency of the motor and inverter at a dq operating point, from the
plant's own loss model (``pmsm_ev.kernels.plant_rates``, the powers the plant integrates at every
step): the input of an efficiency map over torque and speed.

At a constant operating point (i_d, i_q, omega_m) the currents stand still in the rotor frame
(di/dt = 0 in eqs 10-11, or their flux form with saturation), so the voltage is
v_d = R_s i_d - omega_e psi_q(i_q), v_q = R_s i_q + omega_e psi_d(i_d), and the phase currents are
sinusoids of amplitude |i|. The powers are the kernel's at that state, the inverter's averaged over
an electrical period (``PERIOD_SAMPLES`` angles; its losses depend on the phase currents'
instantaneous values). The inverter's dead time is left out: it distorts the voltage, it is not a
loss (docs/speed-range.md).
"""

from __future__ import annotations

import math

from . import accel
from . import kernels as _k
from .params import MotorParams, PlantParams, VehicleParams
from .plant import Plant

#: angles over an electrical period at which the inverter's losses are averaged [-]: with the
#: phase currents' |i| kinks on a uniform grid the mean of |sin| is within 1e-6 of 2/pi
PERIOD_SAMPLES = 720


def steady_state(motor: MotorParams | None = None, plant: PlantParams | None = None,
                 vehicle: VehicleParams | None = None, i_d: float = 0.0, i_q: float = 0.0,
                 omega_m: float = 0.0) -> dict:
    """The steady-state powers [W] and the motor + inverter efficiency at (i_d, i_q) [A] and
    omega_m [rad/s], in the dq convention's power scaling (``MotorParams.dq_convention``):

    ``v_d``, ``v_q`` [V], ``T_e`` [N m] (eq 12 times k_dq), ``P_dc`` (terminal power plus the
    inverter's losses), ``P_copper``, ``P_inverter`` (0 unless ``PlantParams.inverter_losses``),
    ``P_friction`` (omega T_f, eq 8), ``P_iron`` (0 unless ``PlantParams.iron_c_h``, ``iron_c_e``),
    ``P_shaft`` (omega (T_e - T_f - T_fe): the shaft's power after the motor's friction and iron
    losses, what the gear gets), ``P_loss`` (the sum of the losses) and ``efficiency``:
    P_shaft / P_dc motoring, P_dc / P_shaft generating (both < 0), 0 where no power comes out
    (e.g. the losses exceed a small generated power), NaN at no power at all; ``mode``
    ("motoring", "generating" or "idle"). ``vehicle`` only matters for the friction's soft sign."""
    sim = Plant(motor, vehicle, plant)
    k = accel.kernels()
    pp = accel.vector(_k.PLANT_PARAMS)
    for i in range(_k.PLANT_PARAMS):
        pp[i] = sim._pp[i]
    pp[_k.P_DT_V] = 0.0  # the dead time distorts the voltage, it takes no power of its own
    pp[_k.P_T_BRAKE] = 0.0
    m, p = sim.motor, sim.params
    w_e = m.N * omega_m
    flux = pp[_k.P_FLUX] != 0.0
    if flux:  # the algebraic model: plant_rates takes the flux linkages
        x_d, x_q = k.flux_linkages(i_d, i_q, pp, _k.P_FLUX_C)
        f_d, f_q = x_d - sim.psi, x_q
    elif p.sat_i_d > 0 or p.sat_i_q > 0:
        f_d, _ = k.saturated_flux(i_d, m.L_d, pp[_k.P_SAT_AD])
        f_q, _ = k.saturated_flux(i_q, m.L_q, pp[_k.P_SAT_AQ])
    else:
        f_d, f_q = m.L_d * i_d, m.L_q * i_q
    if not flux:
        x_d, x_q = i_d, i_q
    r_s = pp[_k.P_R_S]
    v_d = r_s * i_d - w_e * f_q  # (10) with di_d/dt = 0
    v_q = r_s * i_q + w_e * (sim.psi + f_d)  # (11) with di_q/dt = 0
    p_inv = 0.0
    for j in range(PERIOD_SAMPLES):
        theta = 2.0 * math.pi * j / PERIOD_SAMPLES
        v_alpha, v_beta = k.inverse_park(v_d, v_q, theta)
        r = k.plant_rates(x_d, x_q, omega_m, theta, v_alpha, v_beta, 0.0, pp)
        p_inv += r[13]
    p_inv /= PERIOD_SAMPLES
    # the other powers do not depend on the angle: take them at theta = 0
    r = k.plant_rates(x_d, x_q, omega_m, 0.0, v_d, v_q, 0.0, pp)
    p_term = r[4] - r[13]
    p_dc = p_term + p_inv
    p_cu, p_fric, p_em, p_iron = r[5], r[6], r[7], r[14]
    p_shaft = p_em - p_fric - p_iron
    if p_shaft > 0.0:
        mode, eff = "motoring", (p_shaft / p_dc if p_dc > 0.0 else 0.0)
    elif p_shaft < 0.0:
        mode, eff = "generating", (p_dc / p_shaft if p_dc < 0.0 else 0.0)
    else:
        mode, eff = "idle", math.nan
    return {"v_d": v_d, "v_q": v_q, "T_e": _torque(k, i_d, i_q, pp),
            "P_dc": p_dc, "P_copper": p_cu, "P_inverter": p_inv, "P_friction": p_fric, "P_shaft": p_shaft,
            "P_iron": p_iron, "P_loss": p_cu + p_inv + p_iron + p_fric, "efficiency": eff, "mode": mode}


def _torque(k, i_d, i_q, pp) -> float:
    """T_e of the plant at (i_d, i_q) [N m] (``plant_outputs``)."""
    return k.plant_outputs(i_d, i_q, 0.0, 0.0, 0.0, pp)[2]
