"""A run's energy figures: the plant's bookkeeping (``pmsm_ev.results.energy_balance``, ``battery_balance``)
with what the application makes of it, per kilometre where the run went far enough for that
(``ENERGY_MIN_DISTANCE``), and the battery's terminal voltage range."""

from __future__ import annotations

import numpy as np

from pmsm_ev.results import battery_balance, energy_balance

#: the least distance [m] for a figure per kilometre: 10 m, a car's length or two (below it, a run
#: that stands, aligns or creeps would divide by almost nothing)
ENERGY_MIN_DISTANCE = 10.0


def energy_metrics(r: dict[str, np.ndarray]) -> dict:
    """The energy figures of a run that recorded ``pmsm_ev.results.ENERGY_COLUMNS`` [Wh], from its first to its
    last row: ``energy_balance`` (dc, drawn, regen, the losses by kind, the road work, the brake's, the changes
    of the stored energies, the balance residual, ``distance_m``) and, where the distance is at least
    ``ENERGY_MIN_DISTANCE``, ``dc_Wh_per_km`` and ``drawn_Wh_per_km`` [Wh/km] (None otherwise)."""
    e = energy_balance(r)
    if "distance_m" not in e:
        return e
    distance = e["distance_m"]
    per_km = distance >= ENERGY_MIN_DISTANCE
    e["dc_Wh_per_km"] = e["dc_Wh"] / (distance / 1000.0) if per_km else None
    e["drawn_Wh_per_km"] = e["drawn_Wh"] / (distance / 1000.0) if per_km else None
    return e


def battery_metrics(r: dict[str, np.ndarray], energy: dict) -> dict:
    """The battery's figures of a run that recorded ``pmsm_ev.results.BATTERY_COLUMNS`` and ``ENERGY_COLUMNS``
    (``energy``: its ``energy_metrics``): ``battery_balance`` (the state of charge at both ends, the charge
    drawn, the terminal, chemical and loss energies, the RC pair's change, the battery's residual), the terminal
    voltage's least and largest over the rows, and Wh/km at the terminals and from the chemistry where ``energy``
    has a distance for it. The energy the friction brake took (``energy['brake_Wh']``) is the braking the
    battery refused (its charge acceptance) or the motor could not give."""
    b = battery_balance(r, energy)
    km = energy["distance_m"] / 1000.0 if energy.get("dc_Wh_per_km") is not None else None
    b.update({"v_bat_min": float(np.min(r["v_bat"])), "v_bat_max": float(np.max(r["v_bat"])),
              "terminal_Wh_per_km": energy["dc_Wh_per_km"],
              "chemical_Wh_per_km": b["chemical_Wh"] / km if km else None})
    return b
