"""Following a drive cycle: the regulatory tolerance band (issue 24; docs/cycles.md, "Following the trace") and
how a run kept to it.
"""

from __future__ import annotations

import math

import numpy as np

from .rows import KMH, runs_of

#: the speed tolerance of a chassis-dynamometer test [km/h] and the time window it is taken over [s]: the
#: upper limit is the trace's highest point within +-1 s of the time plus 2 km/h, the lower its lowest within
#: +-1 s minus 2 km/h (WLTP: UN GTR No. 15, Annex 6, paragraph 2.6.8.3; EU 2017/1151, Annex XXI, Sub-Annex 6,
#: 2.6.8.3). The EPA's schedules define the same band with 2 mph = 3.2 km/h (40 CFR 86.115-78(b)(1);
#: 40 CFR 600.109-08(b)(2) for the HWFET): ``EPA_BAND_KMH``. Issue 24 holds every cycle to the 2 km/h.
TRACE_BAND_KMH = 2.0
TRACE_WINDOW_S = 1.0
#: 2 mph [km/h] (1 mile = 1609.344 m): the EPA cycles' own band (40 CFR 86.115-78(b)(1))
EPA_BAND_KMH = 2.0 * 1.609344
#: a speed this close to a limit [m/s] counts as on it (rounding of the limits' arithmetic only)
_BAND_TOL = 1e-9


def _trace_extreme(t_trace: np.ndarray, v_trace: np.ndarray, at: np.ndarray, window_s: float, op) -> np.ndarray:
    """The highest (``op`` = np.maximum) or lowest (np.minimum) value of the piecewise-linear trace over
    [at - window_s, at + window_s] at each time of ``at``: the extreme of a piecewise-linear function over an
    interval is at the interval's ends or at a point of the trace inside it. Before the first point and after
    the last the end value holds."""
    ext = op(np.interp(at - window_s, t_trace, v_trace), np.interp(at + window_s, t_trace, v_trace))
    lo = np.searchsorted(t_trace, at - window_s, side="right")
    hi = np.searchsorted(t_trace, at + window_s, side="left")
    count = hi - lo
    for k in range(int(count.max(initial=0))):
        idx = lo + k
        valid = idx < hi
        ext = np.where(valid, op(ext, v_trace[np.minimum(idx, v_trace.size - 1)]), ext)
    return ext


def trace_band(t_trace, v_trace, band_kmh: float = TRACE_BAND_KMH, window_s: float = TRACE_WINDOW_S,
               time=None) -> tuple[np.ndarray, np.ndarray]:
    """The tolerance band of a speed trace (``TRACE_BAND_KMH``: GTR No. 15 Annex 6 2.6.8.3, 40 CFR 86.115-78):
    (lower, upper) [m/s] at the times ``time`` [s] (default: the trace's own), the trace's lowest value
    within +-``window_s`` of each time minus ``band_kmh`` and its highest plus ``band_kmh``. The trace
    (``t_trace`` [s] increasing, ``v_trace`` [m/s]) is read as linear between its points, as the
    regulations' "smooth trace drawn through the points" at 1 Hz."""
    t_trace, v_trace = np.asarray(t_trace, dtype=float), np.asarray(v_trace, dtype=float)
    if t_trace.ndim != 1 or t_trace.shape != v_trace.shape or t_trace.size < 2 or np.any(np.diff(t_trace) <= 0):
        raise ValueError("trace_band: t_trace and v_trace must be 1-D, of one length >= 2, t_trace increasing")
    if not (band_kmh >= 0 and window_s >= 0 and math.isfinite(band_kmh) and math.isfinite(window_s)):
        raise ValueError(f"trace_band: band_kmh and window_s must be finite and >= 0 (got {band_kmh}, {window_s})")
    at = t_trace if time is None else np.asarray(time, dtype=float)
    band = band_kmh / KMH
    return (_trace_extreme(t_trace, v_trace, at, window_s, np.minimum) - band,
            _trace_extreme(t_trace, v_trace, at, window_s, np.maximum) + band)


def trace_figures(time, v_actual, cycle, band_kmh: float = TRACE_BAND_KMH,
                  window_s: float = TRACE_WINDOW_S) -> dict:
    """How a run followed a drive cycle (``cycle``: a ``pmsm_ev.cycles.Cycle``, or anything with ``time`` [s]
    and ``speed`` [m/s] arrays), from its rows ``time`` [s] (evenly spaced, as results.csv) and the vehicle
    speed ``v_actual`` [m/s], over the rows from 0 to the end of the cycle or of the run, whichever is first:

    * ``inside_share``: the share of that time the speed is inside the band (``trace_band``), each row
      standing for one row interval;
    * ``excursions``: the number of stretches of consecutive rows outside it, ``excursion_lengths_s`` their
      lengths [s] (rows x row interval), ``longest_excursion_s`` and ``t_longest_excursion`` [s] (its first
      row; both None without an excursion);
    * ``rmse_kmh``: the RMS of the speed's deviation from the trace (linear between its points) [km/h];
      ``max_deviation_kmh`` the deviation of largest magnitude (signed, + faster than the trace) and
      ``t_max_deviation`` [s] where;
    * ``t_end`` [s], ``band_kmh``, ``window_s``: what was measured."""
    t, v = np.asarray(time, dtype=float), np.asarray(v_actual, dtype=float)
    t_trace, v_trace = np.asarray(cycle.time, dtype=float), np.asarray(cycle.speed, dtype=float)
    if t.ndim != 1 or t.shape != v.shape or t.size < 2:
        raise ValueError("trace_figures: time and v_actual must be 1-D, of one length >= 2")
    t_end = float(min(t[-1], t_trace[-1]))
    keep = (t >= t_trace[0]) & (t <= t_end + 1e-9)
    t, v = t[keep], v[keep]
    dt_row = float(np.median(np.diff(t))) if t.size > 1 else 0.0
    lower, upper = trace_band(t_trace, v_trace, band_kmh, window_s, t)
    outside = (v < lower - _BAND_TOL) | (v > upper + _BAND_TOL)
    runs = runs_of(outside)
    lengths = [float((b - a) * dt_row) for a, b in runs]
    dev = (v - np.interp(t, t_trace, v_trace)) * KMH
    i_dev = int(np.argmax(np.abs(dev)))
    longest = int(np.argmax(lengths)) if lengths else None
    return {"t_end": t_end, "band_kmh": float(band_kmh), "window_s": float(window_s),
            "inside_share": float(1.0 - np.count_nonzero(outside) / outside.size),
            "excursions": len(runs), "excursion_lengths_s": lengths,
            "longest_excursion_s": None if longest is None else lengths[longest],
            "t_longest_excursion": None if longest is None else float(t[runs[longest][0]]),
            "rmse_kmh": float(np.sqrt(np.mean(dev * dev))),
            "max_deviation_kmh": float(dev[i_dev]), "t_max_deviation": float(t[i_dev])}
