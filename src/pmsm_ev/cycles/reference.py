"""A drive cycle as the motor's speed reference (docs/cycles.md, "Following the trace").

The trace is given at 1 Hz and read as piecewise linear, so its acceleration jumps every second.
A driver does not drive that: the reference here is the **monotone piecewise-cubic Hermite
interpolant (PCHIP, Fritsch and Carlson 1980; the node slopes of Fritsch and Butland 1984, as
MATLAB's ``pchip`` and SciPy's ``PchipInterpolator``)** through the trace's points. Why this one:

* it passes through every point of the trace and is monotone between two points (it never
  overshoots, never undershoots): on each interval it stays between the interval's two speeds, so
  with points at most ``window`` apart (1 s for the shipped cycles, the band's +-1 s) it is inside
  the regulatory tolerance band (+-2 km/h over +-1 s; the application's ``trace_band``) everywhere,
  with the band's whole 2 km/h to spare, and it is never negative;
* where two consecutive points are zero (a stop) it is exactly zero between them, and at a point
  where the trace touches zero for one sample (UDDS at 766 s and 1100 s) it is zero there with zero
  slope: standstill is exactly 0, as a stop needs it to be (the sensorless unit's I-f start and
  hold read a reference of 0);
* it is C1: the acceleration is continuous (the trace's jumps each second become ramps: a jerk
  the driver can give), and its derivative, the acceleration feedforward's input, is given in closed
  form, with no numerical differentiation;
* its slope at a point is the harmonic mean of the two adjacent secant slopes (0 where they differ
  in sign or one is 0), never more than the larger of the two; inside an interval the cubic's slope
  is at most 1.5 times the largest |secant slope| of that interval and its two neighbours (the
  bound 1.5 is reached between two points of zero slope: ``ACCEL_MARGIN``).

A centred 1 s moving average of the linear trace would bound the acceleration by the trace's own
with no margin, but it is not zero at the first and last second of a stop and never at a
one-sample stop; a spline (not monotone) overshoots and goes negative before a stop.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .table import CycleError, frozen_array
from .trace import Cycle

#: the time step of the sampled reference [s] [chosen]: 0.1 s. The reference is a table for linear
#: interpolation (the engine's signal tables); between two samples the error of the chord to the
#: cubic is at most dt^2 / 8 |v''|: with the shipped cycles' |v''| <= 10 m/s^3 it is 0.0125 m/s
#: (0.045 km/h, 2 % of the band's 2 km/h); 18 001 points for the 1800 s of WLTC class 3b
REFERENCE_DT = 0.1
#: the bound on the reference's acceleration relative to the trace's own (module docstring): the
#: PCHIP slope on an interval is at most ACCEL_MARGIN times the largest |secant slope| of the
#: interval and its two neighbours (reached for a one-second blip between two flat points)
ACCEL_MARGIN = 1.5


def pchip_slopes(t: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The node slopes of the PCHIP interpolant through (t, v) (Fritsch-Butland weighted harmonic
    mean of the adjacent secants; 0 where they differ in sign or one is zero; the ends by the
    three-point formula, limited so that the end stays monotone), [unit of v per unit of t]."""
    t, v = np.asarray(t, dtype=float), np.asarray(v, dtype=float)
    h = np.diff(t)
    delta = np.diff(v) / h
    n = t.size
    d = np.zeros(n)
    if n == 2:
        d[:] = delta[0]
        return d
    h0, h1, d0, d1 = h[:-1], h[1:], delta[:-1], delta[1:]
    same = (d0 * d1) > 0.0
    w1, w2 = 2.0 * h1 + h0, h1 + 2.0 * h0
    with np.errstate(divide="ignore", invalid="ignore"):
        hm = (w1 + w2) / (w1 / d0 + w2 / d1)
    d[1:-1] = np.where(same, hm, 0.0)
    d[0] = _end_slope(h[0], h[1], delta[0], delta[1])
    d[-1] = _end_slope(h[-1], h[-2], delta[-1], delta[-2])
    return d


def _end_slope(h0: float, h1: float, m0: float, m1: float) -> float:
    """The end slope of PCHIP (a non-centred three-point formula, kept monotone)."""
    d = ((2.0 * h0 + h1) * m0 - h0 * m1) / (h0 + h1)
    if np.sign(d) != np.sign(m0):
        return 0.0
    if np.sign(m0) != np.sign(m1) and abs(d) > abs(3.0 * m0):
        return 3.0 * m0
    return float(d)


def pchip(t, v, at) -> tuple[np.ndarray, np.ndarray]:
    """The PCHIP interpolant through (t, v) and its derivative at the times ``at`` (clamped to the
    first and last point: the end values hold, with zero derivative, outside)."""
    t, v = np.asarray(t, dtype=float), np.asarray(v, dtype=float)
    at = np.asarray(at, dtype=float)
    d = pchip_slopes(t, v)
    inside = (at >= t[0]) & (at <= t[-1])
    x = np.clip(at, t[0], t[-1])
    i = np.clip(np.searchsorted(t, x, side="right") - 1, 0, t.size - 2)
    h = t[i + 1] - t[i]
    s = (x - t[i]) / h
    s2, s3 = s * s, s * s * s
    y0, y1, m0, m1 = v[i], v[i + 1], d[i] * h, d[i + 1] * h
    value = (2 * s3 - 3 * s2 + 1) * y0 + (s3 - 2 * s2 + s) * m0 + (-2 * s3 + 3 * s2) * y1 + (s3 - s2) * m1
    slope = ((6 * s2 - 6 * s) * y0 + (3 * s2 - 4 * s + 1) * m0 + (-6 * s2 + 6 * s) * y1 + (3 * s2 - 2 * s) * m1) / h
    # exactly the trace's value where two neighbouring points are equal (a stop: exactly 0)
    flat = (v[i] == v[i + 1]) & (d[i] == 0.0) & (d[i + 1] == 0.0)
    value = np.where(flat, v[i], value)
    slope = np.where(flat | ~inside, 0.0, slope)
    return value, slope


@dataclass(frozen=True, eq=False)
class SpeedReference:
    """A cycle as the motor's speed reference on a time grid: ``time`` [s] (from 0 to the cycle's
    duration, step ``dt``, the last point exactly the duration), the vehicle speed ``v`` [m/s] and
    acceleration ``a`` [m/s^2] (PCHIP through the trace, module docstring), the motor speed
    ``omega`` = v n_g / r_w [rad/s] and its derivative ``domega`` [rad/s^2]; ``r_w`` [m], ``n_g``
    [-] used. For linear interpolation between the points (``REFERENCE_DT``)."""

    cycle: Cycle
    r_w: float
    n_g: float
    dt: float
    time: np.ndarray
    v: np.ndarray
    a: np.ndarray

    @property
    def omega(self) -> np.ndarray:
        """Motor speed reference [rad/s]: v n_g / r_w (eqs 6-7: the wheel speed v / r_w through the gear)."""
        return self.v * (self.n_g / self.r_w)

    @property
    def domega(self) -> np.ndarray:
        """Its derivative [rad/s^2]: a n_g / r_w (the acceleration feedforward's input)."""
        return self.a * (self.n_g / self.r_w)


def speed_reference(cycle: Cycle, r_w: float, n_g: float, dt: float = REFERENCE_DT) -> SpeedReference:
    """The motor speed reference of ``cycle`` through the wheel radius ``r_w`` [m] and the gear
    ratio ``n_g`` [-] (module docstring: PCHIP through the trace), sampled every ``dt`` [s] from 0 to
    the cycle's duration (its last point exactly there); a ``CycleError`` naming the bad value for
    a non-positive or non-finite r_w, n_g or dt."""
    for name, value, unit in (("r_w", r_w, " m"), ("n_g", n_g, ""), ("dt", dt, " s")):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not (math.isfinite(value) and value > 0):
            raise CycleError(f"{cycle.name}: speed reference: {name} must be a finite number > 0 (got {value!r}{unit})")
    n = max(1, int(math.ceil(cycle.duration / dt - 1e-9)))
    time = np.minimum(np.arange(n + 1) * float(dt), cycle.duration)
    v, a = pchip(cycle.time, cycle.speed, time)
    v = np.maximum(v, 0.0)  # rounding only: PCHIP between points >= 0 stays >= 0
    return SpeedReference(cycle, float(r_w), float(n_g), float(dt), frozen_array(time), frozen_array(v),
                          frozen_array(a))
