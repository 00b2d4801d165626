"""Energy over a drive cycle (issue 24; docs/cycles.md, "Energy over a cycle"): the figures of a run that
recorded ``pmsm_ev.results.ENERGY_COLUMNS``, per phase of its cycle, and the two acceptance checks.

* ``phase_energy(r, cycle)``: per phase (WLTC class 3b: low, medium, high, extra_high; any other cycle one
  phase, ``whole``) the differences of the plant's cumulative energies from the phase's first row to its
  last (``energy.energy_metrics`` of those rows) with Wh/km at the DC link, the DC energy drawn and
  regenerated, the two regeneration shares (``regen_share``: regenerated / drawn; ``regen_of_braking``:
  regenerated / the braking energy at the wheels), the losses by kind, the wheel energy's traction and
  braking parts, the balance residual (absolute and relative to the DC throughput) and the controller's
  time in each mode.
* ``balance_check(r)``: the energy balance over the run, residual / DC throughput, against ``BALANCE_TOL``.
* ``wheel_check(r, vehicle)``: the wheel energy of the plant's accumulators against the road-load integral
  of the recorded speed and grade (eqs 1-5), against ``WHEEL_TOL``.

All energies in Wh. Rows are results.csv's (evenly spaced; a row at t holds the plant's state and energies
at t, so a difference of two rows is exactly what the plant integrated between them).
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from pmsm_ev import vehicle as veh
from pmsm_ev.params import MotorParams, VehicleParams
from pmsm_ev.results import ENERGY_COLUMNS

from .energy import energy_metrics

_WH = 1.0 / 3600.0  #: J -> Wh
#: the balance over a cycle must close to this, relative to the DC throughput (issue 24)
BALANCE_TOL = 1e-6
#: the wheel energy must agree with the road-load integral to this, relative (issue 24)
WHEEL_TOL = 0.01
#: the phase name of a cycle without phases
WHOLE = "whole"
#: the sensorless unit's modes (``pmsm_ev.control_unit.MODES``): 0 alignment, 1 I-f, 2 closed loop
MODE_NAMES = {0.0: "align", 1.0: "if", 2.0: "closed"}
#: a row this close to a phase boundary [s] belongs to it (row times are multiples of the output interval)
_T_TOL = 1e-6


@dataclass(frozen=True)
class Window:
    """A phase as measured on a run: name, the rows' time span [s], and whether the run covered all of it."""

    name: str
    start: float
    end: float
    complete: bool


def phase_windows(cycle, t_end: float) -> list[Window]:
    """The phases of ``cycle`` (its ``phases``; none: one phase ``WHOLE``, 0 to its duration) as far as a run
    ending at ``t_end`` [s] covers them: a phase starting at or after ``t_end`` is left out, one ending after
    it is cut there (``complete`` False)."""
    phases = [(p.name, float(p.start), float(p.end)) for p in cycle.phases] or \
             [(WHOLE, float(cycle.time[0]), float(cycle.time[-1]))]
    out = []
    for name, a, b in phases:
        if a >= t_end - _T_TOL:
            continue
        out.append(Window(name, a, min(b, t_end), b <= t_end + _T_TOL))
    return out


def plant_params(metrics: dict | None) -> tuple[MotorParams, VehicleParams]:
    """The plant's MotorParams and VehicleParams of a run: the project's defaults with the start values of
    the component ``plant`` in its metrics.json settings (the FMU's parameters are these dataclasses' fields,
    by name). ValueError (one line) for a start value that does not fit its field."""
    comps = ((metrics or {}).get("settings") or {}).get("components") or ()
    start = next((c.get("start") or {} for c in comps if isinstance(c, dict) and c.get("name") == "plant"), {})
    out = []
    for cls in (MotorParams, VehicleParams):
        kw = {}
        for f in fields(cls):
            if f.name not in start:
                continue
            value = start[f.name]
            default = getattr(cls(), f.name)
            try:
                kw[f.name] = type(default)(value) if not isinstance(default, bool) else bool(value)
            except (TypeError, ValueError):
                raise ValueError(f"plant start value {f.name} = {value!r} is not a {type(default).__name__}") from None
        p = cls(**kw)
        p.validate()
        out.append(p)
    return out[0], out[1]


def _wheel_increments(r: dict[str, np.ndarray], vehicle: VehicleParams) -> np.ndarray:
    """The plant's net wheel work [J] over each row interval (module ``wheel_check``)."""
    d = {k: np.diff(np.asarray(r[k], dtype=float)) for k in ENERGY_COLUMNS if k != "x_vehicle"}
    losses = d["E_copper"] + d["E_inverter"] + d["E_iron"] + d["E_friction"] + d["E_gear"]
    v = np.asarray(r["v_vehicle"], dtype=float)
    d_kin_vehicle = 0.5 * vehicle.m_v * np.diff(v * v)
    return d["E_dc"] - losses - d["W_magnetic"] - (d["E_kinetic"] - d_kin_vehicle) - d["E_brake"]


def road_load_increments(r: dict[str, np.ndarray], vehicle: VehicleParams) -> np.ndarray:
    """The road-load integral [J] over each row interval, from the recorded ``v_vehicle`` [m/s] and
    ``delta_deg`` [deg] alone (eqs 1-5, ``pmsm_ev.vehicle``, with ``vehicle``'s parameters):
    integral of (m_v a + f_f + f_a + f_g) v dt, the inertia term exactly 1/2 m_v (v_1^2 - v_0^2) (the
    trapezoidal rule on v dv), the road forces' power (f_f + f_a + f_g) v by the trapezoidal rule."""
    v = np.asarray(r["v_vehicle"], dtype=float)
    delta = np.deg2rad(np.asarray(r["delta_deg"], dtype=float))
    forces = np.array([veh.rolling_force(float(vi), float(di), vehicle) + veh.aero_force(float(vi), vehicle)
                       + veh.gradient_force(float(di), vehicle) for vi, di in zip(v, delta)])
    p_road = forces * v
    dt = np.diff(np.asarray(r["time"], dtype=float))
    return 0.5 * vehicle.m_v * np.diff(v * v) + 0.5 * (p_road[1:] + p_road[:-1]) * dt


def _parts(x: np.ndarray) -> dict:
    return {"net_Wh": float(np.sum(x)) * _WH, "traction_Wh": float(np.sum(np.maximum(x, 0.0))) * _WH,
            "braking_Wh": float(-np.sum(np.minimum(x, 0.0))) * _WH}


def _rel(a: float, b: float) -> float | None:
    return (a - b) / b if b != 0.0 else None


def wheel_check(r: dict[str, np.ndarray], vehicle: VehicleParams, tol: float = WHEEL_TOL) -> dict:
    """Does the wheel energy agree with the trace's road-load integral (issue 24: to 1 %)?

    * **wheel** (``wheel``, the plant's side): the net work the wheels do on the car, what the drive delivers
      through the gear minus what the friction brake takes, from the plant's accumulators alone:
      E_dc - (E_copper + E_inverter + E_iron + E_friction + E_gear) - Delta W_magnetic - Delta E_kin,rotor
      - E_brake, where E_kin,rotor = E_kinetic - 1/2 m_v v^2 is the kinetic energy of the rotating parts
      (1/2 J_m omega^2 with the power_flow gear; with the paper's gear E_kinetic is 1/2 J_eq omega^2 and the
      rest also holds (1/eta - 1) 1/2 m_v v^2, which cancels between two standstills). By the energy balance
      this is the plant's E_aero + E_rolling + E_grade + Delta (1/2 m_v v^2), to its residual.
    * **road-load integral** (``road_load``, the trace's side, ``road_load_increments``): integral of
      (m_v a + f_f + f_a + f_g) v dt at the speeds the car actually drove, recomputed from the recorded
      v_vehicle and delta_deg with eqs 1-5, independent of the plant's integrals.

    Each is given as ``net_Wh`` and its parts over the row intervals: ``traction_Wh`` (intervals of positive
    work) and ``braking_Wh`` (the negative work's magnitude: regeneration through the gear plus the friction
    brake). ``net_rel`` and ``traction_rel`` are (road_load - wheel) / wheel; ``passed``: both within ``tol``.
    ``brake_Wh``: the friction brake's share of the braking."""
    if len(r["time"]) < 2:
        return {"rows": len(r["time"]), "passed": None}
    w, t = _wheel_increments(r, vehicle), road_load_increments(r, vehicle)
    wheel, road = _parts(w), _parts(t)
    net_rel, traction_rel = _rel(road["net_Wh"], wheel["net_Wh"]), _rel(road["traction_Wh"], wheel["traction_Wh"])
    passed = all(x is not None and abs(x) <= tol for x in (net_rel, traction_rel))
    brake = float(r["E_brake"][-1] - r["E_brake"][0]) * _WH
    return {"wheel": wheel, "road_load": road, "net_rel": net_rel, "traction_rel": traction_rel,
            "brake_Wh": brake, "tol": tol, "passed": passed}


def balance_check(r: dict[str, np.ndarray], tol: float = BALANCE_TOL) -> dict:
    """The energy balance over the rows (``energy_metrics``' residual: E_dc minus every loss, the road
    work, the brake's and the changes of the stored energies, each integrated on its own) relative to the
    DC throughput, the integral of |P_dc| = drawn + regenerated: ``residual_Wh``, ``throughput_Wh``,
    ``relative`` (None without throughput) and ``passed`` (|relative| <= ``tol``; issue 24: 1e-6 over a
    WLTC)."""
    e = energy_metrics(r)
    if "residual_Wh" not in e:
        return {"rows": 0, "passed": None}
    through = e["drawn_Wh"] + e["regen_Wh"]
    rel = e["residual_Wh"] / through if through > 0 else None
    return {"residual_Wh": e["residual_Wh"], "throughput_Wh": through, "relative": rel, "tol": tol,
            "passed": None if rel is None else abs(rel) <= tol}


def _rows(r: dict[str, np.ndarray], a: float, b: float) -> dict[str, np.ndarray]:
    t = r["time"]
    keep = (t >= a - _T_TOL) & (t <= b + _T_TOL)
    return {k: v[keep] for k, v in r.items()}


def mode_times(r: dict[str, np.ndarray]) -> dict | None:
    """Time [s] the controller spent in each mode over the rows (``mode`` column; each row interval counted
    in the mode of its first row): ``align``, ``if``, ``closed``, and ``copper_if_Wh``: the copper loss over
    the I-f intervals. None without a ``mode`` column."""
    if "mode" not in r or len(r["time"]) < 2:
        return None
    mode, dt = np.asarray(r["mode"])[:-1], np.diff(r["time"])
    out = {name: float(np.sum(dt[mode == m])) for m, name in MODE_NAMES.items()}
    out["copper_if_Wh"] = interval_sum(r, "E_copper", mode == 1.0)
    return out


def interval_sum(r: dict[str, np.ndarray], column: str, mask: np.ndarray) -> float:
    """The increase of a cumulative energy column [J] summed over the row intervals where ``mask`` (one per
    interval: len(rows) - 1) is true, in Wh."""
    return float(np.sum(np.diff(np.asarray(r[column], dtype=float))[np.asarray(mask, dtype=bool)])) * _WH


def phase_energy(r: dict[str, np.ndarray], cycle, vehicle: VehicleParams | None = None) -> list[dict]:
    """The energy of each phase of ``cycle`` a run covered (``phase_windows``), from its rows with the
    ``ENERGY_COLUMNS`` (and ``v_vehicle``, ``delta_deg``): per phase ``name``, ``start``, ``end``, ``complete``,
    ``energy`` (``energy.energy_metrics`` of the phase's rows: ``dc_Wh_per_km``, ``drawn_Wh``,
    ``regen_Wh``, ``losses_Wh`` by kind, ``road_Wh``, ``brake_Wh``, ``residual_Wh``, ...), ``regen_share``
    (regenerated / drawn at the DC link: the share of the drawn energy that came back), ``regen_of_braking``
    (regenerated / the braking energy at the wheels, ``wheel_check``'s wheel ``braking_Wh``: the share of the
    energy the brakes took off the wheels that reached the DC link; None where there was no braking),
    ``wheel`` (the traction, braking and net wheel work), ``residual_rel`` (residual / DC throughput) and
    ``modes`` (``mode_times``; None without a mode column). The phases meet at a row, so their differences
    add up to the whole run's."""
    vehicle = vehicle or VehicleParams()
    t = np.asarray(r["time"], dtype=float)
    if len(t) < 2:
        return []
    out = []
    for w in phase_windows(cycle, float(t[-1])):
        rows = _rows(r, w.start, w.end)
        if len(rows["time"]) < 2:
            continue
        e = energy_metrics(rows)
        wheel = _parts(_wheel_increments(rows, vehicle))
        through = e["drawn_Wh"] + e["regen_Wh"]
        out.append({
            "name": w.name, "start": w.start, "end": w.end, "complete": w.complete, "energy": e,
            "regen_share": e["regen_Wh"] / e["drawn_Wh"] if e["drawn_Wh"] > 0 else None,
            "regen_of_braking": e["regen_Wh"] / wheel["braking_Wh"] if wheel["braking_Wh"] > 0 else None,
            "wheel": wheel,
            "residual_rel": e["residual_Wh"] / through if through > 0 else None,
            "modes": mode_times(rows),
        })
    return out


def whole_run(r: dict[str, np.ndarray], vehicle: VehicleParams | None = None) -> dict:
    """The run's energy figures over all its rows: ``energy`` (``energy_metrics``), ``regen_share``,
    ``regen_of_braking`` (as in ``phase_energy``), ``balance`` (``balance_check``) and ``wheel``
    (``wheel_check``)."""
    vehicle = vehicle or VehicleParams()
    e = energy_metrics(r)
    wc = wheel_check(r, vehicle)
    braking = (wc.get("wheel") or {}).get("braking_Wh") or 0.0
    drawn = e.get("drawn_Wh") or 0.0
    return {"energy": e, "regen_share": e["regen_Wh"] / drawn if drawn > 0 else None,
            "regen_of_braking": e["regen_Wh"] / braking if braking > 0 else None,
            "balance": balance_check(r), "wheel": wc}


