"""The injection strategy's identification at enable (``pmsm_ev.kernels.identify``): what the unit measured of its
motor, beside the plant's truth.

The plant's algebraic flux model is built so that its incremental inductances at zero current are the motor's
L_d, L_q (``pmsm_ev.params.flux_model_coefficients``): the identification's truth is the plant's ``L_d``,
``L_q`` and their ratio, and its ``R_s`` (at 20 degC, the plant's default winding temperature)."""

from __future__ import annotations

from dataclasses import fields

import numpy as np

from pmsm_ev.kernels import incremental_inductances
from pmsm_ev.params import MotorParams, PlantParams, flux_model_coefficients
from pmsm_ev.results import IDENTIFICATION_COLUMNS


def identification_metrics(r: dict[str, np.ndarray]) -> dict | None:
    """The identified L_d, L_q [H], saliency L_q / L_d [-], R_s [Ohm], the current measurement's noise floor and
    the sensors' offsets [A], the angle accuracy at a stop [rad] and the blind flag at the end of a run that
    records ``IDENTIFICATION_COLUMNS``; None where it does not or the unit identified nothing (0: a unit without
    injection, or one whose identification could not finish)."""
    if not all(c in r for c in IDENTIFICATION_COLUMNS) or not len(r["L_d_id"]):
        return None
    l_d, l_q = float(r["L_d_id"][-1]), float(r["L_q_id"][-1])
    if not (l_d > 0.0 and l_q > 0.0):
        return None
    return {"L_d": l_d, "L_q": l_q, "saliency": float(r["saliency_id"][-1]), "R_s": float(r["R_s_id"][-1]),
            "noise": float(r["noise_id"][-1]), "offset_a": float(r["offset_a_id"][-1]),
            "offset_b": float(r["offset_b_id"][-1]), "angle_accuracy": float(r["angle_accuracy"][-1]),
            "blind": bool(r["blind"][-1] != 0.0),
            "gain_ratio": float(r["gain_ratio_id"][-1]) if "gain_ratio_id" in r and len(r["gain_ratio_id"]) else None}


def identification_truth(motor: MotorParams, block: dict, plant: PlantParams | None = None) -> dict:
    """The plant's truth (``motor``: its parameters; ``plant``: its plant parameters, where known) and the identified
    values' relative errors beside ``identification_metrics``' block. With ``plant`` on the algebraic flux model the
    inductances' truth is its incremental inductances at zero current (``pmsm_ev.kernels.incremental_inductances``;
    a magnet at another temperature than 20 degC moves them off L_d, L_q), and the sensors' noise and offsets
    beside their identified values."""
    l_d, l_q = motor.L_d, motor.L_q
    if plant is not None and plant.flux_model == "algebraic":
        l_dd, _, l_qq = incremental_inductances(0.0, 0.0, list(flux_model_coefficients(motor, plant)), 0)
        l_d, l_q = float(l_dd), float(l_qq)
    saliency = l_q / l_d
    out = {"L_d_plant": l_d, "L_q_plant": l_q, "saliency_plant": saliency, "R_s_plant": motor.R_s,
           "L_d_error": block["L_d"] / l_d - 1.0, "L_q_error": block["L_q"] / l_q - 1.0,
           "saliency_error": block["saliency"] / saliency - 1.0,
           "R_s_error": block["R_s"] / motor.R_s - 1.0 if block["R_s"] > 0.0 else None}
    if plant is not None:
        out.update({"noise_plant": plant.sensor_noise, "offset_a_plant": plant.sensor_offset_a,
                    "offset_b_plant": plant.sensor_offset_b,
                    "gain_ratio_plant": plant.sensor_gain_a / plant.sensor_gain_b})
    return out


def plant_settings(metrics: dict | None) -> PlantParams | None:
    """The plant's PlantParams of a run: the defaults with the start values of the component ``plant`` in its
    metrics.json settings that are PlantParams' fields (as ``cycle_energy.plant_params`` for the motor); None where
    one does not fit its field."""
    comps = ((metrics or {}).get("settings") or {}).get("components") or ()
    start = next((c.get("start") or {} for c in comps if isinstance(c, dict) and c.get("name") == "plant"), {})
    kw = {}
    for f in fields(PlantParams):
        if f.name in start:
            value = start[f.name]
            kw[f.name] = value if isinstance(value, str) else float(value) if f.type in ("float", float) else value
    try:
        return PlantParams(**kw)
    except (TypeError, ValueError):
        return None
