"""The injection strategy's identification at enable (``pmsm_ev.kernels.identify``): what the unit measured of its
motor, beside the plant's truth.

The plant's algebraic flux model is built so that its incremental inductances at zero current are the motor's
L_d, L_q (``pmsm_ev.params.flux_model_coefficients``): the identification's truth is the plant's ``L_d``,
``L_q`` and their ratio, and its ``R_s`` (at 20 degC, the plant's default winding temperature)."""

from __future__ import annotations

import numpy as np

from pmsm_ev.params import MotorParams
from pmsm_ev.results import IDENTIFICATION_COLUMNS


def identification_metrics(r: dict[str, np.ndarray]) -> dict | None:
    """The identified L_d, L_q [H], saliency L_q / L_d [-], R_s [Ohm] and the blind flag at the end of a run that
    records ``IDENTIFICATION_COLUMNS``; None where it does not or the unit identified nothing (0: a unit without
    injection, or one whose identification could not finish)."""
    if not all(c in r for c in IDENTIFICATION_COLUMNS) or not len(r["L_d_id"]):
        return None
    l_d, l_q = float(r["L_d_id"][-1]), float(r["L_q_id"][-1])
    if not (l_d > 0.0 and l_q > 0.0):
        return None
    return {"L_d": l_d, "L_q": l_q, "saliency": float(r["saliency_id"][-1]), "R_s": float(r["R_s_id"][-1]),
            "blind": bool(r["blind"][-1] != 0.0)}


def identification_truth(motor: MotorParams, block: dict) -> dict:
    """The plant's truth (``motor``: its parameters) and the identified values' relative errors beside
    ``identification_metrics``' block."""
    saliency = motor.L_q / motor.L_d
    return {"L_d_plant": motor.L_d, "L_q_plant": motor.L_q, "saliency_plant": saliency, "R_s_plant": motor.R_s,
            "L_d_error": block["L_d"] / motor.L_d - 1.0, "L_q_error": block["L_q"] / motor.L_q - 1.0,
            "saliency_error": block["saliency"] / saliency - 1.0,
            "R_s_error": block["R_s"] / motor.R_s - 1.0 if block["R_s"] > 0.0 else None}
