"""The result contract shared by the monolithic reference and the co-simulation, and what the physics
itself says about a run's rows.

``DIR/results.csv``: one header row, SI units (angles in rad except ``delta_deg``),
rows at the output interval, streamed (flushed row by row). A row at time t_k holds
every signal at communication point t_k: the plant's outputs at t_k and the control
unit's outputs as last computed (at t_{k-1}), i.e. before step k is taken.

Here: the columns the plant and the control units output (``CONTRACT_COLUMNS`` ... ``BATTERY_COLUMNS``),
quantities the model's equations define on them (the angle error, wrapped, unwrapped and with the row
timing removed; eq 31's load torque) and the model's own energy bookkeeping (each integral's change over
the rows and the balance residual, which conservation of energy makes zero: ``energy_balance``,
``battery_balance``). Nothing here chooses a band, a threshold, a time window or a verdict: the figures
of merit of a run (its ``DIR/metrics.json``) are the application's (``pmsm_cosim.app.metrics``;
docs/architecture.md, "Physics and policy").
"""

from __future__ import annotations

import math

import numpy as np

from .params import MotorParams, VehicleParams

#: columns every results.csv has, in this order (more may follow)
CONTRACT_COLUMNS = (
    "time", "delta_deg", "omega_ref", "omega_m", "omega_hat", "theta_e", "theta_hat",
    "i_d", "i_q", "i_d_hat", "i_q_hat", "T_e", "T_L_mech", "T_L_hat", "v_d", "v_q",
)
#: extra columns the project's runs add
EXTRA_COLUMNS = ("i_alpha", "i_beta", "v_alpha", "v_beta", "i_qref", "v_vehicle")
ALL_COLUMNS = CONTRACT_COLUMNS + EXTRA_COLUMNS
#: what runs of the sensorless unit add: the vehicle position [m] (roll-back), the mode
#: (0 alignment, 1 I-f, 2 closed loop on the observer; ``pmsm_ev.control_unit.MODES``), the fault
#: (``pmsm_ev.kernels`` FAULT_*) and the control frame's angle [rad] and speed [rad/s] (synchronism)
SENSORLESS_COLUMNS = ("x_vehicle", "mode", "fault", "theta_ctrl", "omega_ctrl")
#: the injection strategy's identification at enable (the sensorless controller's outputs of the same names): a run
#: that records them gets the identification block of its metrics, the identified values beside the plant's
IDENTIFICATION_COLUMNS = ("L_d_id", "L_q_id", "saliency_id", "R_s_id", "noise_id", "offset_a_id", "offset_b_id",
                          "angle_accuracy", "blind")
#: the plant's energy outputs [J] (``pmsm_ev.plant.Plant.energies``, the plant FMU's outputs of the same
#: names) and the position [m]: a run that records them all gets the energy block of its metrics
#: (``energy_balance``); the acceleration and drive-cycle scenarios record them
ENERGY_COLUMNS = ("E_dc", "E_regen", "E_copper", "E_inverter", "E_iron", "E_friction", "E_gear", "E_aero", "E_rolling",
                  "E_grade", "E_brake", "E_kinetic", "W_magnetic", "x_vehicle")
#: the battery's outputs (``pmsm_ev.plant.BATTERY_SLOTS``; plant start value battery = "ecm"): a run that records them
#: with ``ENERGY_COLUMNS`` gets the battery's figures in its energy block (``battery_balance``)
BATTERY_COLUMNS = ("soc", "v_bat", "i_bat", "Q_bat", "E_chemical", "E_battery", "W_battery")


def wrap_angle(x):
    """An angle [rad] wrapped to [-pi, pi)."""
    return (x + math.pi) % (2 * math.pi) - math.pi


def angle_error(r: dict[str, np.ndarray]) -> np.ndarray:
    """theta_hat - theta_e [rad] as recorded, wrapped to [-pi, pi)."""
    return wrap_angle(r["theta_hat"] - r["theta_e"])


def angle_error_unwrapped(r: dict[str, np.ndarray]) -> np.ndarray:
    """theta_hat - theta_e [rad], continuous across rows: wrapped to [-pi, pi) at the first
    row, then unwrapped, so that an estimate slipping by whole electrical turns shows as
    a steadily growing error (k 2 pi after k slips) instead of a saw-tooth. Valid while
    the error changes by less than pi between two recorded rows."""
    err = angle_error(r)
    return np.unwrap(err) if len(err) else err


def row_timing_corrected_angle_error(r: dict[str, np.ndarray], dt: float, pole_pairs: float) -> np.ndarray:
    """theta_hat - theta_e [rad] with the row-timing term removed, wrapped to [-pi, pi): a row at
    t_k holds the estimate computed at t_{k-1}, one control period ``dt`` [s] before the rotor's
    angle in the same row, so the raw error includes -N omega_m dt (-0.08 rad at 200 rad/s and
    1e-4 s with N = 4, for every observer, sensored too); N = ``pole_pairs``. Take both from the
    run (``pmsm_cosim.app.metrics.windows.run_timing``)."""
    return wrap_angle(r["theta_hat"] - r["theta_e"] + pole_pairs * r["omega_m"] * dt)


def eq31_load_torque(r: dict[str, np.ndarray], motor=None, vehicle=None) -> np.ndarray:
    """What the EKF5's T_L state converges to (eqs 30-31): its mechanical model carries
    J_m only, so T_L_hat absorbs friction and the reflected vehicle inertia:
    T_L_mech + B_m omega + T_m0 + (J_eq - J_m) d(omega)/dt [N m], d(omega)/dt by central
    differences of the recorded speed. Default parameters unless given."""
    motor, vehicle = motor or MotorParams(), vehicle or VehicleParams()
    w, t = r["omega_m"], r["time"]
    dw = np.gradient(w, t) if len(t) >= 2 else np.zeros_like(w)
    return r["T_L_mech"] + motor.B_m * w + motor.T_m0 + vehicle.reflected_inertia * dw


_WH = 1.0 / 3600.0  #: J -> Wh


def energy_balance(r: dict[str, np.ndarray]) -> dict:
    """The plant's energy bookkeeping over the rows of a run that recorded ``ENERGY_COLUMNS`` [Wh], from its
    first to its last row (the plant's energies are integrals since its start, the stored ones its state's):
    ``dc`` (the DC link's net energy), ``drawn`` (what it delivered, dc + regen) and ``regen`` (what
    went back), the ``losses`` by kind (copper, inverter, iron, friction, gear; ``total``), the ``road``
    work by force (aero, rolling, grade: the grade's is the potential energy gained), ``brake`` (the
    friction brake's), the changes of the ``kinetic`` and ``magnetic`` energies, ``residual`` (dc
    minus all the others, the balance: each term is integrated on its own) and ``distance_m`` (the
    path travelled, the sum of |dx| over the rows). ``{"rows": 0}`` without rows."""
    if len(r["time"]) == 0:
        return {"rows": 0}

    def wh(name: str) -> float:
        return float(r[name][-1] - r[name][0]) * _WH

    losses = {"copper": wh("E_copper"), "inverter": wh("E_inverter"), "iron": wh("E_iron"),
              "friction": wh("E_friction"), "gear": wh("E_gear")}
    losses["total"] = sum(losses.values())
    road = {"aero": wh("E_aero"), "rolling": wh("E_rolling"), "grade": wh("E_grade")}
    dc, regen, brake = wh("E_dc"), wh("E_regen"), wh("E_brake")
    kinetic, magnetic = wh("E_kinetic"), wh("W_magnetic")
    distance = float(np.sum(np.abs(np.diff(r["x_vehicle"])))) if len(r["x_vehicle"]) > 1 else 0.0
    return {
        "dc_Wh": dc, "drawn_Wh": dc + regen, "regen_Wh": regen,
        "losses_Wh": losses, "road_Wh": road, "brake_Wh": brake,
        "kinetic_change_Wh": kinetic, "magnetic_change_Wh": magnetic,
        "residual_Wh": dc - losses["total"] - sum(road.values()) - brake - kinetic - magnetic,
        "distance_m": distance,
    }


def battery_balance(r: dict[str, np.ndarray], energy: dict) -> dict:
    """The battery's bookkeeping over the rows of a run that recorded ``BATTERY_COLUMNS`` and ``ENERGY_COLUMNS``,
    from its first to its last row: the state of charge at both ends, the charge drawn ``charge_Ah`` (negative:
    charged), the terminal energy (the DC link's, ``energy['dc_Wh']`` of ``energy_balance``), the chemical energy
    (the open-circuit voltage times the current), the battery's losses, the change of the RC pair's stored energy
    and ``residual_Wh`` (chemical less the three: the battery's balance)."""
    def wh(name: str) -> float:
        return float(r[name][-1] - r[name][0]) * _WH

    chemical, losses, stored = wh("E_chemical"), wh("E_battery"), wh("W_battery")
    return {"soc_start": float(r["soc"][0]), "soc_end": float(r["soc"][-1]),
            "charge_Ah": float(r["Q_bat"][-1] - r["Q_bat"][0]) / 3600.0,
            "terminal_Wh": energy["dc_Wh"], "chemical_Wh": chemical, "losses_Wh": losses, "rc_change_Wh": stored,
            "residual_Wh": chemical - energy["dc_Wh"] - losses - stored}
