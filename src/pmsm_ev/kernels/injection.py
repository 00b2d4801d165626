"""High-frequency injection at and near zero speed: the square wave, its demodulation to an angle
error, the fundamental current without the ripple, the tracking observer and the blend with the EKF
(``pmsm_ev.params.InjectionParams``; docs/sensorless.md, "Closed loop at zero speed"). The unit's
modes, which call these, are ``pmsm_ev.kernels.modes``.

The signal. The voltage +-V on the estimated d axis, held m control periods a sign (a square wave of
frequency 1 / (2 m dt)), changes the currents by m dt L^-1 v in a half-wave (eqs 10-11 with the
back-EMF and the resistance's drop, which change slowly, left out), L the incremental inductance
matrix. Seen from a frame whose angle trails the rotor's by e, with L = diag(L_d, L_q) in the rotor's
frame, the answer to (v, 0) is

    di_d = m dt v (Y_s + Y_x cos 2e),   di_q = m dt v Y_x sin 2e,
    Y_s = (1/L_d + 1/L_q) / 2,          Y_x = (1/L_d - 1/L_q) / 2                        (I1)

(Table I: Y_x = 751 1/H). The second difference of the currents at three half-wave ends cancels
what the fundamental adds, the same in both half-waves, and doubles the injection's part:

    D = (i_k - i_(k-m)) - (i_(k-m) - i_(k-2m)) = m dt (v_1 - v_2) L^-1 e_d,             (I2)

v_1, v_2 the signed voltages of the last two half-waves. ``demodulate`` returns D_q / (m dt (v_1 - v_2)
Y_x) = sin 2e, the angle error signal (Y_x the motor's as identified at enable, ``error_gain``), and
D_d / (m dt (v_1 - v_2)), the d axis's admittance (the
polarity test's measure, larger where the d axis saturates). The error signal sees the axis, not its
direction (sin 2e is the same at e and e + pi): the polarity is the modes' test.

The fundamental. The square wave's current is a triangle whose samples alternate about its mean: the
mean of the last 2 m samples is the fundamental (``fundamental``), which the current PIs control.

The tracking observer (``track``): electrical angle, mechanical speed and load torque with the drive's
mechanical model (eqs 9, 13), corrected by the error e = asin(sin 2e) / 2:

    theta' = N omega + l1 e,  omega' = (T_e - T_L) / J + l2 e,  T_L' = -l3 e               (I3)

whose error dynamics have the characteristic polynomial s^3 + l1 s^2 + N l2 s + N l3 / J; all three
poles at -a (``InjectionParams.inj_bandwidth``): l1 = 3 a, l2 = 3 a^2 / N, l3 = a^3 J / N.
"""

from __future__ import annotations

import math

from .jit import kernel
from .layout import (
    C_BLEND_HI,
    C_BLEND_LO,
    C_CROSS,
    C_DT,
    C_INJ_M,
    C_INJ_V,
    C_INJ_Y,
    C_N,
    C_TRK_J,
    C_TRK_L,
    CROSS_POINTS,
    S_AVG,
    S_AVG_POS,
    S_BLEND,
    S_INJ_ADM,
    S_INJ_AMP,
    S_INJ_COUNT,
    S_INJ_ERR,
    S_INJ_I1,
    S_INJ_I2,
    S_INJ_NEW,
    S_INJ_SIGN,
    S_INJ_SKIP,
    S_INJ_V1,
    S_INJ_V2,
    S_INJ_YX,
    S_TRK,
)
from .transforms import park, wrap_angle

#: the answer is used only where the voltage stepped by at least this share of 2 ``C_INJ_V`` (the amplitude
#: fades with the blend): below it the second difference is mostly noise
_LEAST_STEP = 0.2
#: how many entries S_AVG holds for each axis: m <= 8
AVG_LENGTH = 16
#: the half-waves whose answer is not used after the square wave starts, or its amplitude or its axis steps: an
#: answer's second difference (I2) spans the two half-waves before it, which straddle the step
SKIP_HALF_WAVES = 2.0


@kernel()
def start_injection(s):
    """Begin the square wave afresh: positive first, no answers kept (the first two half-waves give
    none), the ripple filter's memory cleared."""
    s[S_INJ_SIGN] = 1.0
    s[S_INJ_COUNT] = 0.0
    s[S_INJ_AMP] = 0.0
    s[S_INJ_V1] = 0.0
    s[S_INJ_V2] = 0.0
    s[S_INJ_SKIP] = SKIP_HALF_WAVES
    s[S_INJ_NEW] = 0.0
    s[S_INJ_ERR] = 0.0
    s[S_INJ_ADM] = 0.0


@kernel()
def error_gain(s, c):
    """The error signal's gain Y_x of (I1) [1/H]: the identified one (``S_INJ_YX``, ``kernels.modes.identify``)
    once the unit has measured its motor, else the model's (``C_INJ_Y``). With the measured gain the error
    signal is sin 2e itself, so that the tracking observer keeps the poles its gains were placed for (I3)."""
    y = s[S_INJ_YX]
    return y if y > 0.0 else c[C_INJ_Y]


@kernel()
def demodulate(s, c, i_alpha, i_beta, theta):
    """At the end of a half-wave (every m periods): the second difference (I2) of the currents at the
    last three half-wave ends, in the frame at ``theta`` (the injection's axis), turned into the angle
    error signal sin 2e (``S_INJ_ERR``) and the d admittance (``S_INJ_ADM``) of (I1); ``S_INJ_NEW`` says
    whether this period brought them. The half-wave's sign then flips. Call once a period, before
    ``injection_voltage``."""
    s[S_INJ_NEW] = 0.0
    if s[S_INJ_COUNT] < c[C_INJ_M]:
        return
    v1 = s[S_INJ_AMP] * s[S_INJ_SIGN]  # the half-wave that ends with this sample
    d1_d, d1_q = park(i_alpha - s[S_INJ_I1], i_beta - s[S_INJ_I1 + 1], theta)
    d2_d, d2_q = park(s[S_INJ_I1] - s[S_INJ_I2], s[S_INJ_I1 + 1] - s[S_INJ_I2 + 1], theta)
    step = c[C_INJ_M] * c[C_DT] * (v1 - s[S_INJ_V1])  # m dt (v_1 - v_2)
    if s[S_INJ_SKIP] > 0.0:
        s[S_INJ_SKIP] -= 1.0
    elif abs(v1 - s[S_INJ_V1]) >= _LEAST_STEP * 2.0 * c[C_INJ_V]:
        s[S_INJ_ERR] = (d1_q - d2_q) / (step * error_gain(s, c))
        s[S_INJ_ADM] = (d1_d - d2_d) / step
        s[S_INJ_NEW] = 1.0
    s[S_INJ_I2] = s[S_INJ_I1]
    s[S_INJ_I2 + 1] = s[S_INJ_I1 + 1]
    s[S_INJ_I1] = i_alpha
    s[S_INJ_I1 + 1] = i_beta
    s[S_INJ_V2] = s[S_INJ_V1]
    s[S_INJ_V1] = v1
    s[S_INJ_SIGN] = -s[S_INJ_SIGN]
    s[S_INJ_COUNT] = 0.0


@kernel()
def injection_voltage(s, c, amplitude):
    """The square wave's d voltage for this period [V]: +-``amplitude``, latched at the start of each
    half-wave (a half-wave has one amplitude, so that (I2) holds)."""
    if s[S_INJ_COUNT] == 0.0:
        s[S_INJ_AMP] = amplitude
    s[S_INJ_COUNT] += 1.0
    return s[S_INJ_AMP] * s[S_INJ_SIGN]


@kernel()
def fundamental(s, c, i_alpha, i_beta):
    """The currents without the square wave's ripple: the mean of the last 2 m samples (alpha, beta) [A]
    (this one included)."""
    n = int(2.0 * c[C_INJ_M])
    k = int(s[S_AVG_POS])
    s[S_AVG + k] = i_alpha
    s[S_AVG + AVG_LENGTH + k] = i_beta
    s[S_AVG_POS] = float((k + 1) % n)
    a = 0.0
    b = 0.0
    for j in range(n):
        a += s[S_AVG + j]
        b += s[S_AVG + AVG_LENGTH + j]
    return a / n, b / n


@kernel()
def seed_fundamental(s, c, i_alpha, i_beta):
    """Fill the ripple filter's memory with one sample (its mean is then that sample)."""
    for j in range(AVG_LENGTH):
        s[S_AVG + j] = i_alpha
        s[S_AVG + AVG_LENGTH + j] = i_beta
    s[S_AVG_POS] = 0.0


@kernel()
def angle_error(signal):
    """The angle error e [rad] of an error signal sin 2e (I1), the signal clipped to +-1 (noise and a
    mismatched Y_x can take it beyond)."""
    x = min(max(signal, -1.0), 1.0)
    return 0.5 * math.asin(x)


@kernel()
def track(s, c, t_e, share, answer, e_ekf):
    """One control period of the tracking observer (I3): the prediction with the torque ``t_e`` [N m]
    (the model's, from the fundamental currents), then the correction by the error

        e = share e_inj + (1 - share) e_ekf,

    e_inj the angle error of the injection's last answer (where ``answer``), e_ekf [rad] the EKF's angle
    (plus the cross-saturation's offset) less the observer's, ``share`` the square wave's amplitude as a
    share of its full one (``injection_share``: 1 at rest, 0 from the blend's middle). The observer keeps
    its poles; what it follows moves from the injection to the EKF with the speed."""
    dt = c[C_DT]
    s[S_TRK] = wrap_angle(s[S_TRK] + c[C_N] * s[S_TRK + 1] * dt)
    s[S_TRK + 1] += (t_e - s[S_TRK + 2]) / c[C_TRK_J] * dt
    e = (1.0 - share) * e_ekf
    if answer:
        e += share * angle_error(s[S_INJ_ERR])
    if e != 0.0:
        s[S_TRK] = wrap_angle(s[S_TRK] + c[C_TRK_L] * e * dt)
        s[S_TRK + 1] += c[C_TRK_L + 1] * e * dt
        s[S_TRK + 2] -= c[C_TRK_L + 2] * e * dt


@kernel()
def seat_tracker(s, theta, omega, t_l):
    """Put the tracking observer on an angle [rad], a speed [rad/s] and a load [N m]."""
    s[S_TRK] = theta
    s[S_TRK + 1] = omega
    s[S_TRK + 2] = t_l


#: the current step of the cross-saturation table ``C_CROSS`` [A]
CROSS_STEP = 50.0


@kernel()
def cross_offset(c, i_q):
    """The injection's axis less the rotor's d axis [rad] at the q current ``i_q`` [A]: cross-saturation tilts
    the incremental inductance's axes, and the injection locks onto the one nearest d (no q answer there),
    not onto d. Linear in the table ``C_CROSS`` (the controller's model), odd in i_q, held beyond its last point."""
    x = min(abs(i_q) / CROSS_STEP, CROSS_POINTS - 1.0)
    j = min(int(x), CROSS_POINTS - 2)
    phi = c[C_CROSS + j] + (x - j) * (c[C_CROSS + j + 1] - c[C_CROSS + j])
    return phi if i_q >= 0.0 else -phi


@kernel()
def injection_share(w):
    """The square wave's amplitude as a share of ``C_INJ_V`` at the EKF's weight ``w``: 1 at 0, falling to 0
    at w = 1/2 (the EKF then carries at least half the frame, and the tracking observer follows it, ``track``)."""
    return max(1.0 - 2.0 * w, 0.0)


@kernel()
def blend_weight(c, omega):
    """The EKF's weight in the control frame at the speed |omega| [rad/s]: 0 below ``C_BLEND_LO``, 1 from
    ``C_BLEND_HI``, linear between."""
    w = (abs(omega) - c[C_BLEND_LO]) / (c[C_BLEND_HI] - c[C_BLEND_LO])
    return min(max(w, 0.0), 1.0)


@kernel()
def blended_frame(s, theta_ekf, omega_ekf, phi):
    """The control frame's angle [rad] and speed [rad/s]: the tracking observer's less the cross-saturation's
    offset ``phi`` (``cross_offset``), moved towards the EKF's by the weight ``S_BLEND``."""
    w = s[S_BLEND]
    theta_inj = s[S_TRK] - phi
    theta = wrap_angle(theta_inj + w * wrap_angle(theta_ekf - theta_inj))
    return theta, s[S_TRK + 1] + w * (omega_ekf - s[S_TRK + 1])
