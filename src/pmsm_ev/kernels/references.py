"""The reference generator's kernels: a torque demand, the speed and the voltage available turned into
the current references (i_dref, i_qref) of the whole speed range, with the current, torque and voltage
limits; the regenerative-braking limit and the friction brake's share (docs/speed-range.md).

Torque is k_dq x eq 12 of the controller's motor model, T = k i_q (psi + (L_d - L_q) i_d) with
k = k_dq N (``MotorParams.k_dq``); the voltage limit is steady state without the R_s drop (the margin of
``ControllerParams.fw_margin`` covers it): the flux linkage psi_dq = (psi + L_d i_d, L_q i_q) of eq 11
stays within the flux circle |psi_dq| <= lambda = u_fw / |omega_e|, omega_e = N omega.

* MTPA (Jahns, Kliman, Neumann, "Interior permanent-magnet synchronous motors for adjustable-speed
  drives", IEEE Trans. Ind. Appl. 22(4), 1986; Morimoto, Takeda, Hirasa, Taniguchi, "Expansion of
  operating limits for permanent magnet motor by current vector control considering inverter
  capacity", IEEE Trans. Ind. Appl. 26(5), 1990): dT/d(angle) = 0 at fixed |i| gives
  i_d = (psi - sqrt(psi^2 + 4 dL^2 i_q^2)) / (2 dL), dL = L_q - L_d (``mtpa_d_current``, written
  without cancellation: 0 for L_d = L_q); on it T(i_q) is odd and increasing, T >= k psi i_q, and is
  solved for i_q by a safeguarded Newton iteration (``mtpa_q_current``). At |i| = I_max:
  i_d = (psi - sqrt(psi^2 + 8 dL^2 I^2)) / (4 dL) (Morimoto's eq for the current limit).
* Field weakening: the point of least current on the flux circle |psi_dq| = lambda that gives the
  torque. On the circle psi_d = lambda cos(d), psi_q = lambda sin(d),
  T(d) = k lambda sin(d) (a cos(d) + b), a = lambda (1/L_q - 1/L_d), b = psi / L_d, which rises
  monotonically from d = 0 to the MTPV angle, cos(d_mtpv) = 2 a / (b + sqrt(b^2 + 8 a^2))
  (dT/dd = k lambda (a cos 2d + b cos d) = 0); the torque is solved for d by a safeguarded Newton
  iteration on [0, d_top] (``circle_angle``).
* The limits meet (``envelope``): beyond the speed where MTPA at I_max leaves the flux circle, the
  most torque is at the MTPV point if its current is within I_max (region 2; for motors with
  psi / L_d < I_max), else at the intersection of the current circle |i| = I_max with the flux
  circle (region 3): (L_d^2 - L_q^2) i_d^2 + 2 psi L_d i_d + psi^2 + L_q^2 I^2 - lambda^2 = 0, the
  root nearer the MTPA point. No point of the current disc within the flux circle: region 5, no
  torque (the current that weakens the flux most, i_d = -min(I_max, psi / L_d), is commanded).

Region codes (``REGION_*``): 0 MTPA, the torque as asked; 1 field weakening on the flux circle, the
torque as asked (or at T_max); 2 MTPV, at the torque available; 3 the current and the voltage limits
met (current-limited field weakening), at the torque available; 4 MTPA at the torque or current limit
(T_max, or I_max below the voltage limit); 5 beyond the reach of the voltage within the current limit.
A demand at the torque available or beyond counts as at the limit (2, 3 or 4).

Any demand, speed and sign: a demand beyond what the drive gives is limited (the torque given is
returned), never an error; torque and speed of either sign (the voltage limit depends on |omega|,
i_d is even and i_q odd in the torque).
"""

from __future__ import annotations

import math

from .jit import kernel

REGION_MTPA = 0.0  #: MTPA, torque as asked
REGION_FW = 1.0  #: field weakening on the flux circle, torque as asked (or at T_max)
REGION_MTPV = 2.0  #: MTPV: the most torque the voltage allows, within I_max
REGION_CURRENT_FW = 3.0  #: the current and voltage limits met: the most torque of both
REGION_LIMIT = 4.0  #: MTPA at the torque or current limit (T_max, I_max), below the voltage limit
REGION_NONE = 5.0  #: no torque: no current within I_max brings the flux within the voltage's reach

_ITERATIONS = 60  #: most Newton / bisection steps (converges in 3-8; bisection alone in < 60)


@kernel()
def dq_torque(k, i_d, i_q, psi, l_d, l_q):
    """k x eq 12: k i_q (psi + (L_d - L_q) i_d) [N m], k = k_dq N."""
    return k * i_q * (psi + (l_d - l_q) * i_d)


@kernel()
def mtpa_d_current(i_q, psi, l_d, l_q):
    """i_d on the MTPA locus for i_q [A] (Jahns 1986, Morimoto 1990): the root of
    dL i_d^2 - psi i_d - dL i_q^2 = 0 (dL = L_q - L_d) nearer 0, -2 dL i_q^2 / (psi + sqrt(psi^2 +
    4 dL^2 i_q^2)); 0 for a non-salient motor, negative for L_q > L_d."""
    dl = l_q - l_d
    return -2.0 * dl * i_q * i_q / (psi + math.sqrt(psi * psi + 4.0 * dl * dl * i_q * i_q))


@kernel()
def mtpa_limit_current(i_max, psi, l_d, l_q):
    """(i_d, i_q >= 0) of MTPA at |i| = i_max [A]: i_d = (psi - sqrt(psi^2 + 8 dL^2 I^2)) / (4 dL)
    (Morimoto 1990), written without cancellation."""
    dl = l_q - l_d
    i_d = -2.0 * dl * i_max * i_max / (psi + math.sqrt(psi * psi + 8.0 * dl * dl * i_max * i_max))
    return i_d, math.sqrt(max(i_max * i_max - i_d * i_d, 0.0))


@kernel()
def safeguarded_newton(x, f, slope, lo, hi):
    """The next iterate of a root search of an increasing function on the bracket (lo, hi): Newton's step
    x - f / slope, or the bracket's midpoint where the slope is not positive or the step leaves it."""
    nxt = x - f / slope if slope > 0.0 else 0.5 * (lo + hi)
    return nxt if lo < nxt < hi else 0.5 * (lo + hi)


@kernel()
def mtpa_q_current(t, k, psi, l_d, l_q):
    """The i_q >= 0 on MTPA that gives the torque t >= 0 [A]: safeguarded Newton on the bracket
    [0, t / (k psi)] (on MTPA T >= k psi i_q: the reluctance term adds), bisection when a step leaves it.
    dT/di_q = k (psi + (L_d - L_q) i_d) + k (L_d - L_q) i_q di_d/di_q, di_d/di_q = -2 dL i_q /
    sqrt(psi^2 + 4 dL^2 i_q^2)."""
    if not t > 0.0:
        return 0.0
    dl = l_q - l_d
    lo = 0.0
    hi = t / (k * psi)
    x = hi
    for _ in range(_ITERATIONS):
        root = math.sqrt(psi * psi + 4.0 * dl * dl * x * x)
        i_d = -2.0 * dl * x * x / (psi + root)
        f = k * x * (psi - dl * i_d) - t
        lo, hi = (lo, x) if f > 0.0 else (x, hi)
        if abs(f) <= 1e-13 * t:
            break
        nxt = safeguarded_newton(x, f, k * ((psi - dl * i_d) + 2.0 * dl * dl * x * x / root), lo, hi)
        if nxt == x:
            break
        x = nxt
    return x


@kernel()
def circle_current(delta, lam, psi, l_d, l_q):
    """(i_d, i_q) of the flux psi_dq = lam (cos delta, sin delta) [A]: i_d = (psi_d - psi) / L_d,
    i_q = psi_q / L_q (eq 11's flux linkages)."""
    return (lam * math.cos(delta) - psi) / l_d, lam * math.sin(delta) / l_q


@kernel()
def mtpv_angle(lam, psi, l_d, l_q):
    """The flux angle of MTPV on the circle |psi_dq| = lam [rad]: cos d = 2 a / (b + sqrt(b^2 + 8 a^2)),
    a = lam (1/L_q - 1/L_d), b = psi / L_d (pi/2 for L_d = L_q)."""
    a = lam * (1.0 / l_q - 1.0 / l_d)
    b = psi / l_d
    return math.acos(2.0 * a / (b + math.sqrt(b * b + 8.0 * a * a)))


@kernel()
def circle_angle(t, lam, k, psi, l_d, l_q, d_top):
    """The flux angle d in [0, d_top] on the circle |psi_dq| = lam whose torque is t >= 0 [rad]
    (T(d) = k lam sin d (a cos d + b) rises on [0, d_top], d_top <= the MTPV angle): safeguarded
    Newton, dT/dd = k lam (a cos 2d + b cos d), bisection when a step leaves the bracket."""
    a = lam * (1.0 / l_q - 1.0 / l_d)
    b = psi / l_d
    lo = 0.0
    hi = d_top
    t_top = k * lam * math.sin(d_top) * (a * math.cos(d_top) + b)
    if not t > 0.0:
        return 0.0
    if t >= t_top:
        return d_top
    x = d_top * t / t_top
    for _ in range(_ITERATIONS):
        f = k * lam * math.sin(x) * (a * math.cos(x) + b) - t
        lo, hi = (lo, x) if f > 0.0 else (x, hi)
        if abs(f) <= 1e-13 * t:
            break
        nxt = safeguarded_newton(x, f, k * lam * (a * math.cos(2.0 * x) + b * math.cos(x)), lo, hi)
        if nxt == x:
            break
        x = nxt
    return x


@kernel()
def envelope(omega, k, psi, l_d, l_q, n, i_max, u_fw):
    """The limits at the mechanical speed ``omega`` [rad/s]: returns (t_avail, lam, d_top, region_top):
    the most torque the current limit ``i_max`` [A] and the voltage ``u_fw`` [V] (<= 0: no voltage limit)
    allow [N m], the flux circle's radius lam = u_fw / (N |omega|) [Wb] (inf without a voltage limit or
    at standstill), the flux angle where the torque along the circle is largest within the limits [rad]
    (the MTPV angle, or the current circle's intersection) and the region there: REGION_LIMIT (MTPA at
    I_max is within the flux circle), REGION_MTPV, REGION_CURRENT_FW or REGION_NONE."""
    i_d, i_q = mtpa_limit_current(i_max, psi, l_d, l_q)
    t_mtpa = dq_torque(k, i_d, i_q, psi, l_d, l_q)
    w_e = abs(n * omega)
    if not (u_fw > 0.0 and w_e > 0.0):
        return t_mtpa, math.inf, 0.5 * math.pi, REGION_LIMIT
    lam = u_fw / w_e
    d_mtpv = mtpv_angle(lam, psi, l_d, l_q)
    psi_d = psi + l_d * i_d
    psi_q = l_q * i_q
    if psi_d * psi_d + psi_q * psi_q <= lam * lam:
        return t_mtpa, lam, d_mtpv, REGION_LIMIT
    i_d, i_q = circle_current(d_mtpv, lam, psi, l_d, l_q)
    if i_d * i_d + i_q * i_q <= i_max * i_max:
        return dq_torque(k, i_d, i_q, psi, l_d, l_q), lam, d_mtpv, REGION_MTPV
    # the current circle |i| = I_max meets the flux circle: the root nearer the MTPA point
    qa = l_d * l_d - l_q * l_q
    qb = 2.0 * psi * l_d
    qc = psi * psi + l_q * l_q * i_max * i_max - lam * lam
    disc = qb * qb - 4.0 * qa * qc
    if disc < 0.0:
        return 0.0, lam, 0.0, REGION_NONE
    i_d = -2.0 * qc / (qb + math.sqrt(disc))
    if not -i_max <= i_d <= i_max:
        return 0.0, lam, 0.0, REGION_NONE
    i_q = math.sqrt(i_max * i_max - i_d * i_d)
    d_top = math.atan2(l_q * i_q, psi + l_d * i_d)
    if d_top > d_mtpv:  # (rounding at the MTPV point)
        d_top = d_mtpv
    return dq_torque(k, i_d, i_q, psi, l_d, l_q), lam, d_top, REGION_CURRENT_FW


@kernel()
def reference_point(t_dem, omega, k, psi, l_d, l_q, n, i_max, t_max, u_fw):
    """The current references for the torque demand ``t_dem`` [N m] at the mechanical speed ``omega``
    [rad/s] (see the module doc): returns (i_dref, i_qref, t_given, t_avail, region), ``t_given`` the
    torque of the references (the demand limited) [N m], ``t_avail`` >= 0 the most torque of either sign
    at this speed (the envelope, within ``t_max``) [N m]. ``k`` = k_dq N; ``t_max`` [N m] the torque
    limit (<= 0: what ``i_max`` gives on MTPA); ``u_fw`` [V] the voltage for field weakening (<= 0: no
    voltage limit, MTPA only)."""
    t_env, lam, d_top, region_top = envelope(omega, k, psi, l_d, l_q, n, i_max, u_fw)
    return references_within(t_dem, k, psi, l_d, l_q, i_max, t_max, t_env, lam, d_top, region_top)


@kernel()
def references_within(t_dem, k, psi, l_d, l_q, i_max, t_max, t_env, lam, d_top, region_top):
    """``reference_point`` on the limits ``envelope`` gives at the speed (t_env, lam, d_top, region_top)."""
    t_cap = t_env
    if t_max > 0.0 and t_max < t_cap:
        t_cap = t_max
    if region_top == REGION_NONE:
        return -min(i_max, psi / l_d), 0.0, 0.0, 0.0, REGION_NONE
    t = abs(t_dem)
    limited = t >= t_cap  # at the limit (the speed PI's clamp gives the demand there)
    if limited:
        t = t_cap
    i_q = mtpa_q_current(t, k, psi, l_d, l_q)
    i_d = mtpa_d_current(i_q, psi, l_d, l_q)
    psi_d = psi + l_d * i_d
    psi_q = l_q * i_q
    if psi_d * psi_d + psi_q * psi_q <= lam * lam:
        region = REGION_LIMIT if limited else REGION_MTPA
    else:  # field weakening: the point of least current on the flux circle that gives t
        d = circle_angle(t, lam, k, psi, l_d, l_q, d_top)
        i_d, i_q = circle_current(d, lam, psi, l_d, l_q)
        t = dq_torque(k, i_d, i_q, psi, l_d, l_q)
        region = region_top if (limited and t_cap == t_env and region_top != REGION_LIMIT) else REGION_FW
    if t_dem < 0.0:
        return i_d, -i_q, -t, t_cap, region
    return i_d, i_q, t, t_cap, region


@kernel()
def regen_limit(t_dem, omega, p_regen):
    """The motor's share of a torque demand [N m]: a braking demand (torque opposing the motion,
    t_dem omega < 0) limited to the regenerative power ``p_regen`` [W], |T| <= p_regen / |omega|
    (``p_regen`` <= 0: no limit); any other demand as it is."""
    if p_regen > 0.0 and t_dem * omega < 0.0:
        cap = p_regen / abs(omega)
        if t_dem > cap:
            return cap
        if t_dem < -cap:
            return -cap
    return t_dem


@kernel()
def friction_brake(t_dem, t_given, omega, brake_gain):
    """The friction brake's demand at the wheels [N m, >= 0]: the braking shaft torque the motor does
    not give, (|t_dem| - |t_given|) x n_g eta (``brake_gain``; a wheel torque T_b acts on the shaft as
    T_b / (eta n_g), as the road load of eq 29); 0 when the demand is not braking (t_dem omega >= 0)."""
    if t_dem * omega < 0.0:
        rest = abs(t_dem) - abs(t_given)
        if rest > 0.0:
            return rest * brake_gain
    return 0.0
