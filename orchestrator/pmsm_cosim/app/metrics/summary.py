"""One number per figure of merit of a run, for tables of many runs (a sweep's summary.csv).
"""

from __future__ import annotations

import math

#: the scalar figures of merit of a run (:func:`summary_metrics`), in this order
SUMMARY_METRICS = (
    "speed_rms_error", "omega_hat_rms_error", "theta_error_rms", "theta_error_max",
    "max_speed_deviation", "max_settling_time", "T_L_hat_error_max",
    "inside_share", "slipped_turns", "episodes", "roll_back_m", "fault_latched", "dc_Wh_per_km",
    "saliency_id", "saliency_plant", "blind",
)

#: their units
SUMMARY_UNITS = {
    "speed_rms_error": "rad/s", "omega_hat_rms_error": "rad/s", "theta_error_rms": "rad", "theta_error_max": "rad",
    "max_speed_deviation": "rad/s", "max_settling_time": "s", "T_L_hat_error_max": "N m",
    "inside_share": "-", "slipped_turns": "-", "episodes": "-", "roll_back_m": "m", "fault_latched": "-",
    "dc_Wh_per_km": "Wh/km", "saliency_id": "-", "saliency_plant": "-", "blind": "-",
}


def summary_metrics(m: dict) -> dict[str, float]:
    """One number per figure of merit of a run's metrics (e.g. a metrics.json), for tables
    of many runs: the RMS errors as they are, and over the elevation steps and plateaus:

    * ``max_speed_deviation`` [rad/s]: the largest speed dip after any step;
    * ``max_settling_time`` [s]: the longest settling into the band (inf if a step never
      settled within its segment);
    * ``T_L_hat_error_max`` [N m]: the largest |mean T_L_hat - mean T_L_mech| over the
      plateaus' end windows (how well the observer's load estimate tracks eq 31);
    * of a drive cycle (``docs/cycles.md``): ``inside_share`` [-], the share of the cycle inside the
      tolerance band (``trace``); ``slipped_turns`` [-], ``episodes`` [-] (the loss-of-synchronism episodes the
      unit itself reported: a slip with none went unseen), ``roll_back_m`` [m] (the largest travel against the
      driver's direction) and ``fault_latched`` [-] (1 if the safe state latched, else 0) of the sensorless unit
      (``synchronism``); ``dc_Wh_per_km`` [Wh/km], the DC link's
      energy per distance (``energy``);
    * of a unit that identified its motor (``identification``): ``saliency_id`` [-] as it measured it beside the
      plant's ``saliency_plant`` [-], and ``blind`` [-] (1 if it found itself blind, else 0).

    NaN where the run has no such figure (no steps, no plateau long enough, no metrics).
    """
    nan = float("nan")

    def num(x) -> float:
        return float(x) if isinstance(x, (int, float)) and not isinstance(x, bool) else nan

    out = {k: num(m.get(k)) for k in SUMMARY_METRICS[:4]}
    steps = [s for s in m.get("steps") or () if isinstance(s, dict)]
    plateaus = [p for p in m.get("plateaus") or () if isinstance(p, dict)]
    out["max_speed_deviation"] = max((num(s.get("max_speed_deviation")) for s in steps), default=nan)
    out["max_settling_time"] = max((math.inf if s.get("settling_time") is None else num(s["settling_time"])
                                    for s in steps), default=nan)
    out["T_L_hat_error_max"] = max((abs(num(p.get("T_L_hat_mean")) - num(p.get("T_L_mech_mean")))
                                    for p in plateaus), default=nan)
    trace, sync, energy = (m.get(k) if isinstance(m.get(k), dict) else {} for k in ("trace", "synchronism", "energy"))
    out["inside_share"] = num(trace.get("inside_share"))
    out["slipped_turns"] = num(sync.get("slipped_turns"))
    out["episodes"] = num(sync.get("episodes"))
    out["roll_back_m"] = num(sync.get("roll_back_m"))
    latched = sync.get("fault_latched")
    out["fault_latched"] = float(latched) if isinstance(latched, bool) else nan
    out["dc_Wh_per_km"] = num(energy.get("dc_Wh_per_km"))
    ident = m.get("identification") if isinstance(m.get("identification"), dict) else {}
    out["saliency_id"] = num(ident.get("saliency"))
    out["saliency_plant"] = num(ident.get("saliency_plant"))
    blind = ident.get("blind")
    out["blind"] = float(blind) if isinstance(blind, bool) else nan
    return out
