"""The reference generator from Python: the current references, the torque-speed envelope and the
operating points of a controller's motor and limits, for figures and studies (docs/speed-range.md).

The formulas are ``pmsm_ev.kernels.references`` (MTPA, field weakening, MTPV, the current and torque
limits; the regenerative limit), the same the controllers run at every period; these functions call them
(as plain Python) with the parameters of a ``ControllerParams`` and the controller's ``MotorParams``. Units:
torque N m (k_dq x eq 12), mechanical speed rad/s, currents A, voltages V; the voltage limit is
``fw_margin`` x the controller's voltage limit (v_dc / sqrt(3), or u_max) in the mode "fw", none in "mtpa"
(the mode "paper" is taken as "fw" here when ``v_dc`` is given, else as "mtpa": the envelope of the motor
and the limits, whichever references a run uses).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import kernels as _k
from .params import ControllerParams, MotorParams

#: region names by code (``pmsm_ev.kernels.references`` REGION_*)
REGIONS = ("MTPA", "field weakening", "MTPV", "current and voltage limits", "torque or current limit on MTPA",
           "no torque within the limits")


@dataclass(frozen=True)
class Limits:
    """What the generator works with: the controller's motor model and limits."""

    k: float  #: k_dq N, eq 12's factor [-]
    psi: float  #: magnet flux [Wb]
    L_d: float  #: d inductance [H]
    L_q: float  #: q inductance [H]
    N: int  #: pole pairs [-]
    R_s: float  #: stator resistance [Ohm] (the voltages of ``operating_points`` only)
    i_max: float  #: current-magnitude limit [A]
    T_max: float  #: torque limit [N m] (resolved: MTPA at i_max when not given)
    u_fw: float  #: the voltage field weakening plans with [V] (0: no voltage limit)
    P_regen_max: float  #: regenerative power limit [W] (0: none)
    brake_gain: float  #: n_g eta: a shaft torque's friction-brake torque at the wheels [-]


def limits(controller: ControllerParams | None = None, motor: MotorParams | None = None) -> Limits:
    """The ``Limits`` of a controller (validated) and its motor model (defaults: the package's)."""
    p = controller or ControllerParams()
    m = motor or MotorParams()
    p.validate()
    m.validate()
    p.validate_limits(m)
    voltage = p.reference == "fw" or (p.reference == "paper" and p.v_dc > 0)
    return Limits(k=m.k_dq * m.N, psi=m.psi, L_d=m.L_d, L_q=m.L_q, N=m.N, R_s=m.R_s, i_max=float(p.i_max),
                  T_max=float(p.T_max or p.torque_at_current_limit(m)),
                  u_fw=p.fw_margin * p.u_limit if voltage else 0.0, P_regen_max=float(p.P_regen_max),
                  brake_gain=p.n_g * p.eta)


@dataclass(frozen=True)
class Reference:
    """One output of the generator."""

    i_d: float  #: d-current reference [A]
    i_q: float  #: q-current reference [A]
    T: float  #: the torque of the references, the demand limited [N m]
    T_avail: float  #: the most torque of either sign at this speed (within T_max) [N m]
    region: int  #: region code (``REGIONS``)


def reference(T: float, omega: float, lim: Limits) -> Reference:
    """The references for the torque demand ``T`` [N m] at the mechanical speed ``omega`` [rad/s]
    (``pmsm_ev.kernels.reference_point``; no regenerative limit: see ``motor_share``)."""
    i_d, i_q, t, t_avail, region = _k.reference_point(float(T), float(omega), lim.k, lim.psi, lim.L_d, lim.L_q,
                                                      float(lim.N), lim.i_max, lim.T_max, lim.u_fw)
    return Reference(i_d, i_q, t, t_avail, int(region))


def motor_share(T: float, omega: float, lim: Limits) -> tuple[float, float]:
    """The blending of a torque demand ``T`` [N m] at ``omega`` [rad/s]: (the motor's torque [N m], the
    friction brake's demand at the wheels [N m, >= 0]): a braking demand goes to the motor up to
    P_regen_max / |omega| and the envelope, the rest x n_g eta to the friction brake."""
    t_motor = _k.regen_limit(float(T), float(omega), lim.P_regen_max)
    given = reference(t_motor, omega, lim).T
    return given, _k.friction_brake(float(T), given, float(omega), lim.brake_gain)


def torque_envelope(omega, lim: Limits) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The envelope at the mechanical speeds ``omega`` [rad/s] (array-like): (the most motoring torque [N m,
    >= 0], the most braking torque of the motor [N m, <= 0: within the regenerative limit P_regen_max /
    |omega| too], the region at the most torque (``REGIONS``: 4 where MTPA at T_max or I_max holds))."""
    w = np.atleast_1d(np.asarray(omega, dtype=float))
    motoring = np.empty_like(w)
    braking = np.empty_like(w)
    region = np.empty(w.shape, dtype=int)
    for i, wi in enumerate(w):
        r = reference(math.copysign(math.inf, wi) if wi != 0 else math.inf, wi, lim)
        motoring[i] = abs(r.T)
        region[i] = r.region
        t_brake = _k.regen_limit(-math.copysign(r.T_avail, wi) if wi != 0 else -r.T_avail, wi, lim.P_regen_max)
        braking[i] = -abs(reference(t_brake, wi, lim).T)
    return motoring, braking, region


def _flux(i_d: float, i_q: float, lim: Limits) -> float:
    return math.hypot(lim.psi + lim.L_d * i_d, lim.L_q * i_q)


def region_speeds(lim: Limits, omega_top: float = 1.0e5) -> dict[str, float]:
    """The speeds where the envelope's regions change [rad/s, mechanical]: ``base_speed``, where MTPA at the
    torque limit reaches the voltage limit (field weakening above); ``limit_speed``, where the torque limit
    gives way to the limits meeting (MTPV or the current circle; equal to ``base_speed`` when T_max is what
    i_max gives); ``mtpv_speed``, where MTPV begins (inf if never: psi / L_d > I_max); ``max_speed``, where
    no torque is left, u_fw / (N (psi - L_d I_max)) (inf if psi / L_d <= I_max). All inf without a voltage
    limit. Found from the kernels' envelope by bisection (to 1e-9 relative) up to ``omega_top``."""
    if lim.u_fw <= 0:
        return {"base_speed": math.inf, "limit_speed": math.inf, "mtpv_speed": math.inf, "max_speed": math.inf}
    i_q = _k.mtpa_q_current(lim.T_max, lim.k, lim.psi, lim.L_d, lim.L_q)
    i_d = _k.mtpa_d_current(i_q, lim.psi, lim.L_d, lim.L_q)
    base = lim.u_fw / (lim.N * _flux(i_d, i_q, lim))

    def env(w):
        return _k.envelope(w, lim.k, lim.psi, lim.L_d, lim.L_q, float(lim.N), lim.i_max, lim.u_fw)

    def first(pred, lo, hi):  # the least speed in (lo, hi] where pred holds (pred monotonic), else inf
        if not pred(hi):
            return math.inf
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            if pred(mid):
                hi = mid
            else:
                lo = mid
            if hi - lo <= 1e-9 * hi:
                break
        return hi

    limit = first(lambda w: env(w)[0] < lim.T_max * (1 - 1e-12), base * (1 - 1e-9), omega_top)
    mtpv = first(lambda w: env(w)[3] == _k.REGION_MTPV, base * (1 - 1e-9), omega_top)
    lam_min = lim.psi - lim.L_d * lim.i_max
    top = lim.u_fw / (lim.N * lam_min) if lam_min > 0 else math.inf
    return {"base_speed": base, "limit_speed": min(limit, top), "mtpv_speed": mtpv, "max_speed": top}


@dataclass(frozen=True)
class OperatingPoints:
    """The generator over a grid of torque demands and speeds (arrays of shape (len(T), len(omega)))."""

    T_demand: np.ndarray  #: the demands [N m], (n_T,)
    omega: np.ndarray  #: the mechanical speeds [rad/s], (n_omega,)
    i_d: np.ndarray  #: d-current references [A]
    i_q: np.ndarray  #: q-current references [A]
    T: np.ndarray  #: the torque given [N m]
    region: np.ndarray  #: region codes (``REGIONS``)
    v: np.ndarray  #: steady-state voltage magnitude with the R_s drop [V] (eqs 10-11 at di/dt = 0)
    i: np.ndarray  #: current magnitude [A]


def operating_points(T, omega, lim: Limits) -> OperatingPoints:
    """The references for each (torque demand [N m], mechanical speed [rad/s]) of the grid ``T`` x ``omega``,
    with the steady-state voltage v_d = R_s i_d - omega_e L_q i_q, v_q = R_s i_q + omega_e (psi + L_d i_d)."""
    ts = np.atleast_1d(np.asarray(T, dtype=float))
    ws = np.atleast_1d(np.asarray(omega, dtype=float))
    shape = (ts.size, ws.size)
    out = {name: np.empty(shape) for name in ("i_d", "i_q", "T", "v")}
    region = np.empty(shape, dtype=int)
    for a, t in enumerate(ts):
        for b, w in enumerate(ws):
            r = reference(t, w, lim)
            w_e = lim.N * w
            v_d = lim.R_s * r.i_d - w_e * lim.L_q * r.i_q
            v_q = lim.R_s * r.i_q + w_e * (lim.psi + lim.L_d * r.i_d)
            out["i_d"][a, b], out["i_q"][a, b], out["T"][a, b] = r.i_d, r.i_q, r.T
            out["v"][a, b] = math.hypot(v_d, v_q)
            region[a, b] = r.region
    return OperatingPoints(ts, ws, out["i_d"], out["i_q"], out["T"], region, out["v"],
                           np.hypot(out["i_d"], out["i_q"]))
