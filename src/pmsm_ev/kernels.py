"""The per-step numerics of the drive, written once, in a form numba can compile.

Every equation that runs at each control period lives here: the PMSM (eqs 10-13), the
road load (eqs 2-4, 8, 29), the plant's RK4 step, the controller (eqs 14-20), the EKFs
(eqs 23-27, A2-A33) and the control unit's step. The functions take floats and flat
float vectors (a numpy float64 array when compiled, a list of floats otherwise) whose
slots are named by the constants below; they allocate nothing.

``pmsm_ev.accel`` loads this module either as plain Python (this file as it is) or
compiled with numba (``JIT = True`` set before the module body runs), so the reference run,
the FMUs and the tests share one implementation whether numba is there or not. The other
modules keep the readable, dataclass-based interface (``pmsm.current_derivatives(..., m)``,
``Plant``, ``ControlUnit``, the observer classes) on top of these functions.

Floating-point results are the same compiled or not: the operations are written in the
order of the plain-Python formulas they replaced (numba does not reorder or fuse them
without fastmath), and only functions that numba and CPython compute identically are
used (sin, cos, tanh, sqrt, %; not math.hypot, whose CPython 3.10+ algorithm differs in
the last bit).
"""

from __future__ import annotations

import math

#: set to True by pmsm_ev.accel (in the module's namespace, before this body runs) to
#: compile the kernels with numba; CACHE likewise enables numba's on-disk cache
JIT = globals().get("JIT", False)
CACHE = globals().get("CACHE", False)

if JIT:
    from numba import njit

    def kernel(signature=None):
        """Compile with numba: eagerly for ``signature`` (a top-level kernel), else lazily
        when a compiled caller first needs it."""
        def wrap(fn):
            options = {"cache": CACHE}
            return njit(signature, **options)(fn) if signature else njit(**options)(fn)
        return wrap
else:
    def kernel(signature=None):
        """Plain Python: the function as written."""
        def wrap(fn):
            return fn
        return wrap

_TWO_PI = 2.0 * math.pi
_F = "float64"
_V = "float64[::1]"


def _sig(result: str, *args: str) -> str:
    return f"{result}({', '.join(args)})"


# -- parameter vector of the plant ----------------------------------------------------------------
(P_R_S, P_L_D, P_L_Q, P_PSI, P_N, P_B_M, P_T_M0, P_OMEGA_EPS, P_J_EQ,
 P_M_V, P_G, P_C_R, P_RHO_A, P_C_D, P_A_F, P_R_W, P_ETA, P_N_G, P_V_A, P_V_EPS, P_PAPER,
 P_SUBSTEPS) = range(22)
#: inverter dead time: per-phase voltage error amplitude v_dc t_d / T_s [V] (0 = off) and the
#: current scale of its soft sign [A] (``PlantParams.dead_time``, ``dead_time_i0``)
P_DT_V, P_DT_I0 = 22, 23
#: magnetic saturation: 1.0 = on, and 1/I_sat of the d and q axes [1/A] (``saturated_flux``)
P_SAT, P_SAT_AD, P_SAT_AQ = 24, 25, 26
PLANT_PARAMS = 27

# -- state vector of the control unit (controller + observer) ----------------------------------------
# unit: last command, the observer's voltage input of one period earlier (dq, or alpha-beta
# for the stationary-frame EKF5; used with a one-period actuation delay), the voltage held,
# the currents in the control frame and the q-current reference
S_V_D, S_V_Q, S_U_PREV_0, S_U_PREV_1, S_V_ALPHA, S_V_BETA, S_I_D, S_I_Q, S_I_QREF = range(9)
S_W_INT = 9  #: speed PI integral [A]
S_INT_D, S_INT_Q, S_I_DL, S_I_QL, S_SAT = range(10, 15)  #: current PIs, decoupling filters, limited
S_X = 15  #: observer estimates: i_d, i_q, omega_m, theta_e, T_L (EKF4: T_L stays 0)
S_THETA_PRIOR = 20  #: the observer's predicted angle
S_P = 21  #: EKF covariance, n x n row by row (n = 4 or 5)
S_PHT = 46  #: scratch: P H^T, n x 2
S_K = 56  #: scratch: Kalman gain, n x 2
S_A = 66  #: scratch: J_f P, n x n (J_f itself when P = I)
S_STARTED = 91  #: stationary-frame EKF5: 1.0 once past its first sample (x0 is the estimate there)
# sensorless start-up (``sensorless_step``): the mode (MODE_*), the periods since the first
# step, the current vector of alignment and I-f (angle in the stationary frame, magnitude,
# target magnitude), the I-f speed and how long omega_hat has agreed with it
S_MODE, S_CLOCK, S_PHI, S_I_MAG, S_I_TGT, S_OMEGA_IF, S_AGREE = range(92, 99)
S_SLIP = 99  #: I-f: omega_hat - omega_if, low-pass filtered (the damping's input) [rad/s]
S_V_OUT_ALPHA, S_V_OUT_BETA = 100, 101  #: with dead-time compensation: the vector sent to the inverter
S_PSI_RATIO = 102  #: with psi adaptation: the EKF's magnet flux over the nominal psi [-]
# the sensorless unit's synchronism (``sync_guard``, ``slip_detector``): 1.0 while the load-angle
# guard holds the I-f vector back; how long the slip has exceeded its bound [s]; the age of the
# present loss-of-synchronism episode [s] (0: none); how long it has been in synchronism since [s];
# the fault (FAULT_*); the control frame's angle [rad] and speed [rad/s] of the last period
S_GUARD, S_LOS, S_EPISODE, S_INSYNC, S_FAULT, S_THETA_CTRL, S_OMEGA_CTRL = range(103, 110)
#: the car standing in I-f (``C_STILL``): the EKF's angle when the stand began, and 1.0 while it stands
S_ANCHOR, S_ANCHORED = 110, 111
S_ANCHOR_TL = 112  #: ... and the EKF's load then [N m]
S_STILL_OUT = 113  #: how long |omega_hat| has been above C_STILL while standing [s] (the stand ends at C_SLIP_TIME / 2)
UNIT_STATE = 114

# -- parameter vector of the control unit ------------------------------------------------------
C_DT = 0
C_KP_W, C_KI_W, C_I_Q_MAX = 1, 2, 3
C_KP_ID, C_KI_ID, C_KP_IQ, C_KI_IQ, C_T_D, C_U_MAX = range(4, 10)
C_N, C_L_D, C_L_Q, C_PSI, C_PAPER_SIGNS = range(10, 15)  #: the controller's motor model
C_I_D_REF, C_ADVANCE, C_HALF_PERIOD_N, C_ZOH, C_DELAYED, C_ESTIMATED, C_OBSERVER = range(15, 22)
(C_A_RD, C_A_RQ, C_C_WQ, C_C_WD, C_C_WPSI, C_C_VD, C_C_VQ, C_C_TPSI, C_C_TDQ, C_C_TL, C_C_TH,
 C_R0, C_R1) = range(22, 35)  #: EKF model constants (A2-A32) and R
C_Q = 35  #: EKF Q diagonal, n entries
C_C_MID = 40  #: stationary-frame EKF5: d(mid-period angle)/d(omega_m) = N dt / 2
C_P0 = 41  #: EKF P0 diagonal, n entries
(C_T_RAMP, C_T_HOLD, C_T_SWEEP, C_T_SETTLE, C_I_ALIGN, C_I_IF, C_IF_ACCEL, C_I_RATE, C_W_UP, C_W_DOWN,
 C_AGREE_TOL, C_AGREE_TIME, C_IF_MARGIN) = range(46, 59)  #: ``pmsm_ev.params.StartupParams``
C_IF_DAMP = 59  #: I-f damping: 2 zeta sqrt(J / psi) [rad s sqrt(A)], divided by sqrt(i) in use
C_P0_ALIGNED = 60  #: EKF P0 diagonal at the restart after the alignment, 5 entries
C_SLIP_FILTER = 65  #: dt / time constant of the low-pass filter of the damping's input [-]
#: dead-time compensation: per-phase voltage amplitude [V] (0 = off) and its soft sign's
#: current scale [A] (``ControllerParams.dead_time_comp``, ``dead_time_comp_i0``)
C_DTC_V, C_DTC_I0 = 66, 67
#: psi adaptation of the stationary-frame EKF5 (``EkfParams.psi_adapt``): gain [1/s] (0 = off) and
#: the least |omega_hat| it adapts at [rad/s]
C_PSI_ADAPT, C_PSI_ADAPT_W = 68, 69
#: the sensorless unit's I-f sizing and synchronism (``pmsm_ev.params.StartupParams``): the EKF
#: model's inertia [kg m^2], the design load angle [rad] and its sine, the current rate when the
#: load exceeds the vector [A/s], the guard on (1.0) or off, the slip bound [rad/s] and time [s],
#: the time in synchronism that ends an episode [s], the episode's age that latches the fault [s],
#: the guard's angle [rad]
(C_J_IF, C_E_MAX, C_SIN_E, C_I_RATE_LOAD, C_GUARD, C_SLIP_TOL, C_SLIP_TIME, C_RECOVER_TIME,
 C_FAULT_TIME, C_E_GUARD) = range(70, 80)
C_ALIGN_DAMP = 80  #: 1.0: the alignment damped on the back-EMF (``StartupParams.align_damping``)
C_ALIGN_SLIP = 81  #: |omega_hat| that ends the alignment: the rotor runs away under its vector [rad/s]
C_ALIGN_SLIP_TIME = 82  #: ... for this long [s]
C_STILL = 83  #: below this |omega_hat| and |omega_if| in I-f the car stands: its angle is held [rad/s]
UNIT_PARAMS = 84

#: modes of the sensorless unit (``S_MODE``)
MODE_ALIGN, MODE_IF, MODE_EKF = 0.0, 1.0, 2.0
#: its fault output (``S_FAULT``): none; a loss of synchronism detected, recovery under way; the
#: recovery failed: the safe state (stop and hold at the current limit) latched
FAULT_NONE, FAULT_RECOVERING, FAULT_LATCHED = 0.0, 1.0, 2.0

#: observers (``C_OBSERVER``)
OBS_EKF5, OBS_EKF4, OBS_EKF5AB, OBS_SENSORED = 0, 1, 2, 3
OBSERVER_CODES = {"ekf5": OBS_EKF5, "ekf4": OBS_EKF4, "ekf5ab": OBS_EKF5AB, "sensored": OBS_SENSORED}


# -- transforms ------------------------------------------------------------------------------
@kernel()
def park(alpha, beta, theta):
    """alpha-beta -> dq at electrical angle theta (d axis on the magnet)."""
    c = math.cos(theta)
    s = math.sin(theta)
    return c * alpha + s * beta, -s * alpha + c * beta


@kernel()
def inverse_park(d, q, theta):
    """dq -> alpha-beta at electrical angle theta."""
    c = math.cos(theta)
    s = math.sin(theta)
    return c * d - s * q, s * d + c * q


@kernel()
def wrap_angle(theta):
    """Wrap an angle to [-pi, pi)."""
    return (theta + math.pi) % _TWO_PI - math.pi


# -- PMSM, eqs 10-13 ---------------------------------------------------------------------------
@kernel()
def current_derivatives(i_d, i_q, omega_m, v_d, v_q, R_s, L_d, L_q, psi, N):
    """(di_d/dt, di_q/dt) [A/s] of eqs 10-11; omega_m is mechanical [rad/s]."""
    w_e = N * omega_m
    did = (-R_s * i_d + w_e * L_q * i_q + v_d) / L_d  # (10)
    diq = (-R_s * i_q - w_e * L_d * i_d - w_e * psi + v_q) / L_q  # (11)
    return did, diq


@kernel()
def electromagnetic_torque(i_d, i_q, psi, L_d, L_q, N):
    """T_e = N psi i_q + N L_d i_d i_q - N L_q i_q i_d [N m] (eq 12)."""
    return N * (psi * i_q + (L_d - L_q) * i_d * i_q)


@kernel()
def friction_torque(omega_m, B_m, T_m0, omega_eps, paper):
    """B_m omega_m + T_m0 [N m] (eq 8); not ``paper``: T_m0 tanh(omega_m / omega_eps)."""
    if paper:
        return B_m * omega_m + T_m0
    return B_m * omega_m + T_m0 * math.tanh(omega_m / omega_eps)


# -- departures of a real motor and inverter from eqs 10-12 (plant only, each off by default) ----
_SQRT3_2 = 0.5 * math.sqrt(3.0)
_INV_SQRT3 = 1.0 / math.sqrt(3.0)


@kernel()
def dead_time_error(i_alpha, i_beta, v_err, i0):
    """Voltage error (alpha, beta) [V] of an inverter with dead time for the current vector
    (i_alpha, i_beta): each phase x = a, b, c loses v_err * tanh(i_x / i0) of its pole voltage
    (v_err = v_dc t_d / T_s, the volt-seconds the dead time takes per switching period, of the
    sign of the phase current: the free-wheeling diode conducts during the dead time; tanh is
    the soft sign of the switches' output capacitance, which makes the error fall to zero with
    the current). The common mode of the three errors does not reach the star-connected
    winding; the amplitude-invariant Clarke transform drops it."""
    i_b = -0.5 * i_alpha + _SQRT3_2 * i_beta
    i_c = -0.5 * i_alpha - _SQRT3_2 * i_beta
    e_a = -v_err * math.tanh(i_alpha / i0)
    e_b = -v_err * math.tanh(i_b / i0)
    e_c = -v_err * math.tanh(i_c / i0)
    return (2.0 * e_a - e_b - e_c) / 3.0, (e_b - e_c) * _INV_SQRT3


@kernel()
def saturated_flux(i, L0, a):
    """Flux linkage and incremental inductance of one axis with self-saturation, the
    Froehlich-Kennelly magnetisation curve psi(i) = L0 i / (1 + a |i|), a = 1/I_sat [1/A]:
    apparent inductance psi/i = L0 / (1 + a|i|), incremental dpsi/di = L0 / (1 + a|i|)^2.
    Returns (psi [Wb], L_inc [H]); a = 0 gives (L0 i, L0)."""
    k = 1.0 + a * abs(i)
    return L0 * i / k, L0 / (k * k)


@kernel()
def saturated_current_derivatives(i_d, i_q, omega_m, v_d, v_q, R_s, L_d, L_q, psi, N, a_d, a_q):
    """Eqs 10-11 in flux form with saturated inductances: d psi_d/dt = v_d - R i_d + w_e psi_q,
    d psi_q/dt = v_q - R i_q - w_e psi_d, psi_d = psi + psi_dd(i_d), psi_q = psi_qq(i_q)
    (``saturated_flux``, no cross-saturation), so di/dt = (d psi/dt) / L_inc. With a_d = a_q =
    0 these are eqs 10-11."""
    w_e = N * omega_m
    f_d, l_d = saturated_flux(i_d, L_d, a_d)
    f_q, l_q = saturated_flux(i_q, L_q, a_q)
    did = (-R_s * i_d + w_e * f_q + v_d) / l_d  # (10) with psi_q = L_q,app i_q
    diq = (-R_s * i_q - w_e * (psi + f_d) + v_q) / l_q  # (11) with psi_d = psi + L_d,app i_d
    return did, diq


@kernel()
def saturated_torque(i_d, i_q, psi, L_d, L_q, N, a_d, a_q):
    """T_e = N (psi_d i_q - psi_q i_d) [N m]: eq 12 in its flux form with the saturated fluxes
    (``saturated_flux``); it equals the co-energy derivative (no cross-saturation, no slot
    harmonics) and eq 12 for a_d = a_q = 0."""
    f_d, _ = saturated_flux(i_d, L_d, a_d)
    f_q, _ = saturated_flux(i_q, L_q, a_q)
    return N * ((psi + f_d) * i_q - f_q * i_d)


@kernel()
def winding_resistance(R_s20, T, alpha_R, T_ref):
    """R_s(T) = R_s20 (1 + alpha_R (T - T_ref)) [Ohm]: copper's linear law."""
    return R_s20 * (1.0 + alpha_R * (T - T_ref))


@kernel()
def winding_thermal_step(T, i_d, i_q, R_s20, alpha_R, T_ref, T_amb, R_th, C_th, dt):
    """The winding heated over dt by its copper losses R_s(T) (i_d^2 + i_q^2) (``thermal_step``; the
    model's power scaling, p = v_d i_d + v_q i_q); returns the new temperature [degC] and R_s there."""
    r_s = winding_resistance(R_s20, T, alpha_R, T_ref)
    T_new = thermal_step(T, r_s * (i_d * i_d + i_q * i_q), T_amb, R_th, C_th, dt)
    return T_new, winding_resistance(R_s20, T_new, alpha_R, T_ref)


@kernel()
def thermal_step(T, P, T_amb, R_th, C_th, dt):
    """Winding temperature after dt [degC] of the first-order model C_th dT/dt = P - (T - T_amb) / R_th
    with the losses P [W] held over the step (exact solution: T relaxes to T_amb + P R_th with the
    time constant R_th C_th)."""
    T_inf = T_amb + P * R_th
    return T_inf + (T - T_inf) * math.exp(-dt / (R_th * C_th))


# -- road load, eqs 2-4 and 29 ---------------------------------------------------------------
@kernel()
def gradient_force(delta, m_v, g):
    """f_g = m_v g sin(delta) [N] (eq 2)."""
    return m_v * g * math.sin(delta)


@kernel()
def rolling_force(v_v, delta, c_r, m_v, g, v_eps, paper):
    """f_f = c_r m_v g cos(delta) [N] (eq 3); not ``paper``: times tanh(v_v / v_eps)."""
    f = c_r * m_v * g * math.cos(delta)
    if paper:
        return f
    return f * math.tanh(v_v / v_eps)


@kernel()
def aero_force(v_v, rho_a, c_d, A_f, v_a, paper):
    """f_a = 0.5 rho_a c_d A_f (v_v + v_a)^2 [N] (eq 4); not ``paper``: (v+v_a)|v+v_a|."""
    v_rel = v_v + v_a
    k = 0.5 * rho_a * c_d * A_f
    if paper:
        return k * v_rel * v_rel
    return k * v_rel * abs(v_rel)


@kernel()
def load_torque(omega_m, delta, m_v, g, c_r, rho_a, c_d, A_f, r_w, eta, n_g, v_a, v_eps, paper):
    """T_L-mech = r_w / (eta n_g) (f_g + f_f + f_a) [N m] (eq 29): the road load on the shaft."""
    v_v = r_w * omega_m / n_g
    forces = (gradient_force(delta, m_v, g) + rolling_force(v_v, delta, c_r, m_v, g, v_eps, paper)
              + aero_force(v_v, rho_a, c_d, A_f, v_a, paper))
    return r_w / (eta * n_g) * forces


# -- the plant ---------------------------------------------------------------------------------
@kernel()
def plant_load_torque(omega_m, delta, pp):
    """Eq 29 with the plant's parameter vector."""
    return load_torque(omega_m, delta, pp[P_M_V], pp[P_G], pp[P_C_R], pp[P_RHO_A], pp[P_C_D], pp[P_A_F],
                       pp[P_R_W], pp[P_ETA], pp[P_N_G], pp[P_V_A], pp[P_V_EPS], pp[P_PAPER] != 0.0)


@kernel()
def plant_derivatives(i_d, i_q, omega_m, theta_e, v_alpha, v_beta, delta, pp):
    """d/dt of (i_d, i_q, omega_m, theta_e) for a stationary-frame voltage."""
    c = math.cos(theta_e)
    s = math.sin(theta_e)
    if pp[P_DT_V] != 0.0:  # the inverter's dead time: the applied voltage loses its error
        e_alpha, e_beta = dead_time_error(c * i_d - s * i_q, s * i_d + c * i_q, pp[P_DT_V], pp[P_DT_I0])
        v_alpha = v_alpha + e_alpha
        v_beta = v_beta + e_beta
    v_d = c * v_alpha + s * v_beta  # Park at the true angle
    v_q = -s * v_alpha + c * v_beta
    N = pp[P_N]
    if pp[P_SAT] != 0.0:  # saturated inductances
        did, diq = saturated_current_derivatives(i_d, i_q, omega_m, v_d, v_q, pp[P_R_S], pp[P_L_D], pp[P_L_Q],
                                                 pp[P_PSI], N, pp[P_SAT_AD], pp[P_SAT_AQ])
        t_e = saturated_torque(i_d, i_q, pp[P_PSI], pp[P_L_D], pp[P_L_Q], N, pp[P_SAT_AD], pp[P_SAT_AQ])
    else:
        did, diq = current_derivatives(i_d, i_q, omega_m, v_d, v_q,
                                       pp[P_R_S], pp[P_L_D], pp[P_L_Q], pp[P_PSI], N)  # (10), (11)
        t_e = electromagnetic_torque(i_d, i_q, pp[P_PSI], pp[P_L_D], pp[P_L_Q], N)  # (12)
    t_l = plant_load_torque(omega_m, delta, pp)  # (29)
    t_f = friction_torque(omega_m, pp[P_B_M], pp[P_T_M0], pp[P_OMEGA_EPS], pp[P_PAPER] != 0.0)  # (8)
    dw = (t_e - t_f - t_l) / pp[P_J_EQ]  # (9) = (28)
    dth = N * omega_m  # (13)
    return did, diq, dw, dth


@kernel(_sig(f"UniTuple({_F}, 5)", _F, _F, _F, _F, _F, _V))
def plant_outputs(i_d, i_q, omega_m, theta_e, delta, pp):
    """(i_alpha, i_beta, T_e, T_L_mech, v_vehicle) of a plant state."""
    i_alpha, i_beta = inverse_park(i_d, i_q, theta_e)
    if pp[P_SAT] != 0.0:
        t_e = saturated_torque(i_d, i_q, pp[P_PSI], pp[P_L_D], pp[P_L_Q], pp[P_N], pp[P_SAT_AD], pp[P_SAT_AQ])
    else:
        t_e = electromagnetic_torque(i_d, i_q, pp[P_PSI], pp[P_L_D], pp[P_L_Q], pp[P_N])  # (12)
    t_l = plant_load_torque(omega_m, delta, pp)  # (29)
    v_v = pp[P_R_W] * omega_m / pp[P_N_G]  # (1), (6)
    return i_alpha, i_beta, t_e, t_l, v_v


@kernel(_sig(f"UniTuple({_F}, 10)", _F, _F, _F, _F, _F, _F, _F, _F, _V))
def plant_step(i_d, i_q, omega_m, theta_e, v_alpha, v_beta, delta, dt, pp):
    """Advance the state by dt with the voltage and elevation held (RK4, ``P_SUBSTEPS``
    sub-steps); return the new (i_d, i_q, omega_m, theta_e) and the outputs at the new
    state: (i_alpha, i_beta) (clean), T_e, T_L_mech at ``delta``, v_vehicle; and the
    distance the vehicle moved [m]: r_w / (n_g N) times the (unwrapped) RK4 angle step of
    eq 13, i.e. eqs 1, 6 integrated by the same RK4."""
    n = int(pp[P_SUBSTEPS])
    h = dt / n
    x0, x1, x2, x3 = i_d, i_q, omega_m, theta_e
    for _ in range(n):
        a0, a1, a2, a3 = plant_derivatives(x0, x1, x2, x3, v_alpha, v_beta, delta, pp)
        b0, b1, b2, b3 = plant_derivatives(x0 + 0.5 * h * a0, x1 + 0.5 * h * a1, x2 + 0.5 * h * a2,
                                           x3 + 0.5 * h * a3, v_alpha, v_beta, delta, pp)
        c0, c1, c2, c3 = plant_derivatives(x0 + 0.5 * h * b0, x1 + 0.5 * h * b1, x2 + 0.5 * h * b2,
                                           x3 + 0.5 * h * b3, v_alpha, v_beta, delta, pp)
        d0, d1, d2, d3 = plant_derivatives(x0 + h * c0, x1 + h * c1, x2 + h * c2, x3 + h * c3,
                                           v_alpha, v_beta, delta, pp)
        x0 += h / 6.0 * (a0 + 2.0 * b0 + 2.0 * c0 + d0)
        x1 += h / 6.0 * (a1 + 2.0 * b1 + 2.0 * c1 + d1)
        x2 += h / 6.0 * (a2 + 2.0 * b2 + 2.0 * c2 + d2)
        x3 += h / 6.0 * (a3 + 2.0 * b3 + 2.0 * c3 + d3)
    dx = pp[P_R_W] / (pp[P_N_G] * pp[P_N]) * (x3 - theta_e)
    x3 = wrap_angle(x3)
    i_alpha, i_beta, t_e, t_l, v_v = plant_outputs(x0, x1, x2, x3, delta, pp)
    return x0, x1, x2, x3, i_alpha, i_beta, t_e, t_l, v_v, dx


# -- controller, eqs 14-20 -----------------------------------------------------------------------
@kernel(_sig(_F, _V, _V, _F, _F))
def speed_step(s, c, omega_ref, omega_est):
    """Speed PI, eq 14, i_qref limited to +-i_q_max, with conditional integration."""
    i_q_max = c[C_I_Q_MAX]
    e = omega_ref - omega_est
    unsat = c[C_KP_W] * e + s[S_W_INT]  # (14)
    i_qref = min(max(unsat, -i_q_max), i_q_max)
    # anti-windup: integrate unless the output is clamped and e pushes further out
    if i_qref == unsat or (unsat > i_q_max) != (e > 0):
        s[S_W_INT] += c[C_KI_W] * e * c[C_DT]
    return i_qref


@kernel(_sig(f"UniTuple({_F}, 2)", _V, _V, _F, _F, _F, _F, _F))
def current_step(s, c, i_dref, i_qref, i_d, i_q, omega_est):
    """Current PIs (15-16), decoupling filters (17-18) and terms (19-20); the voltage
    vector limited to u_max, the integrators held while it is limited."""
    dt = c[C_DT]
    e_d = i_dref - i_d
    e_q = i_qref - i_q
    u_d = c[C_KP_ID] * e_d + s[S_INT_D]  # (15)
    u_q = c[C_KP_IQ] * e_q + s[S_INT_Q]  # (16)
    w_e = c[C_N] * omega_est
    v_d = u_d - w_e * c[C_L_Q] * s[S_I_QL]  # (19)
    if c[C_PAPER_SIGNS] != 0.0:
        v_q = u_q - w_e * c[C_L_D] * s[S_I_DL] - w_e * c[C_PSI]  # (20) as printed
    else:
        v_q = u_q + w_e * c[C_L_D] * s[S_I_DL] + w_e * c[C_PSI]  # (20) corrected to cancel (11)
    s[S_I_DL] += dt / c[C_T_D] * (i_dref - s[S_I_DL])  # (17)
    s[S_I_QL] += dt / c[C_T_D] * (i_qref - s[S_I_QL])  # (18)
    u_max = c[C_U_MAX]
    mag = math.sqrt(v_d * v_d + v_q * v_q)
    if mag > u_max:
        s[S_SAT] = 1.0
        if mag == math.inf:  # the squares overflowed (|v| > 1e154 V): the length of the
            big = max(abs(v_d), abs(v_q))  # scaled vector; NaN if a component is infinite
            mag = big * math.sqrt((v_d / big) * (v_d / big) + (v_q / big) * (v_q / big))
        scale = u_max / mag
        v_d *= scale
        v_q *= scale
    else:
        s[S_SAT] = 0.0
        s[S_INT_D] += c[C_KI_ID] * e_d * dt
        s[S_INT_Q] += c[C_KI_IQ] * e_q * dt
    return v_d, v_q


# -- observers, eqs 23-27 ------------------------------------------------------------------------
@kernel()
def ekf5_time_update(s, c, v_d, v_q, f03, f13, c_mid):
    """EKF5 time update (23)-(24): x^f = f(x^e), P^f = J_f P J_f^T + Q, J_f at x^e (A8-A32).

    J_f rows: r0 = [f00 f01 f02 f03 0], r1 = [f10 f11 f12 f13 0], r2 = [f20 f21 1 0 f24],
    r3 = [0 0 f32 1 0], r4 = [0 0 0 0 1]. f03, f13 (the voltage's dependence on theta) and
    c_mid (that of its angle on omega) are zero for the dq EKF5, whose voltage input does
    not depend on its state; see ``ekf5ab_predict``.
    """
    i_d = s[S_X]
    i_q = s[S_X + 1]
    w = s[S_X + 2]
    th = s[S_X + 3]
    t_l = s[S_X + 4]
    c_wq, c_wd, c_wpsi = c[C_C_WQ], c[C_C_WD], c[C_C_WPSI]
    c_tpsi, c_tdq, c_th = c[C_C_TPSI], c[C_C_TDQ], c[C_C_TH]
    if c[C_PSI_ADAPT] != 0.0:  # the adapted magnet flux (``adapt_psi``) in A3, A4 and their Jacobian
        c_wpsi = c_wpsi * s[S_PSI_RATIO]
        c_tpsi = c_tpsi * s[S_PSI_RATIO]
    f00, f01, f02 = c[C_A_RD], c_wq * w, c_wq * i_q + f03 * c_mid  # (A8-A10)
    f10, f11, f12 = -c_wd * w, c[C_A_RQ], -c_wd * i_d - c_wpsi + f13 * c_mid  # (A13-A15)
    f20, f21, f24 = c_tdq * i_q, c_tpsi + c_tdq * i_d, c[C_C_TL]  # (A18, A19, A22)
    f32 = c_th  # (A25)
    s[S_X] = c[C_A_RD] * i_d + c_wq * w * i_q + c[C_C_VD] * v_d  # (A2)
    s[S_X + 1] = c[C_A_RQ] * i_q - c_wd * w * i_d - c_wpsi * w + c[C_C_VQ] * v_q  # (A3)
    s[S_X + 2] = w + c_tpsi * i_q + c_tdq * i_d * i_q + c[C_C_TL] * t_l  # (A4)
    s[S_X + 3] = th + c_th * w  # (A5); T_L: (A6)
    for j in range(5):  # A = J_f P, column by column
        p0 = s[S_P + j]
        p1 = s[S_P + 5 + j]
        p2 = s[S_P + 10 + j]
        p3 = s[S_P + 15 + j]
        p4 = s[S_P + 20 + j]
        s[S_A + j] = f00 * p0 + f01 * p1 + f02 * p2 + f03 * p3
        s[S_A + 5 + j] = f10 * p0 + f11 * p1 + f12 * p2 + f13 * p3
        s[S_A + 10 + j] = f20 * p0 + f21 * p1 + p2 + f24 * p4
        s[S_A + 15 + j] = f32 * p2 + p3
        s[S_A + 20 + j] = p4
    for i in range(5):  # P^f = A J_f^T + Q: column k of A J_f^T is A (row k of J_f)
        a0 = s[S_A + 5 * i]
        a1 = s[S_A + 5 * i + 1]
        a2 = s[S_A + 5 * i + 2]
        a3 = s[S_A + 5 * i + 3]
        a4 = s[S_A + 5 * i + 4]
        r = S_P + 5 * i
        s[r] = f00 * a0 + f01 * a1 + f02 * a2 + f03 * a3
        s[r + 1] = f10 * a0 + f11 * a1 + f12 * a2 + f13 * a3
        s[r + 2] = f20 * a0 + f21 * a1 + a2 + f24 * a4
        s[r + 3] = f32 * a2 + a3
        s[r + 4] = a4
        s[r + i] += c[C_Q + i]
    s[S_THETA_PRIOR] = s[S_X + 3]


@kernel()
def adapt_psi(s, c):
    """Adapt the stationary-frame EKF5's magnet flux (after its measurement update; on while
    |omega_hat| > ``C_PSI_ADAPT_W``). The estimated angle tracks the rotor, so over time it turns
    at the true electrical speed; with a wrong psi the model's back-EMF omega_hat psi_hat can match
    the currents only with a wrong omega_hat, and the Kalman gain then corrects the angle by the
    difference at every step: corr = theta_post - theta_prior has the mean N (omega - omega_hat) dt.
    The law d(psi_hat/psi)/dt = -gain corr / (N dt |omega_hat|) sign(omega_hat) raises psi_hat while
    omega_hat runs ahead of the angle's rate (psi_hat too small) and settles where the two agree;
    psi_hat/psi is kept within 0.5 .. 1.5."""
    w = s[S_X + 2]
    if abs(w) <= c[C_PSI_ADAPT_W]:
        return
    corr = wrap_angle(s[S_X + 3] - s[S_THETA_PRIOR])
    rate = -c[C_PSI_ADAPT] * corr / (c[C_N] * c[C_DT] * w)  # the sign of omega_hat via the division
    s[S_PSI_RATIO] = min(max(s[S_PSI_RATIO] + rate * c[C_DT], 0.5), 1.5)


@kernel()
def ekf5_predict(s, c, v_d, v_q):
    """The paper's EKF5 time update with the dq voltage command of the period."""
    ekf5_time_update(s, c, v_d, v_q, 0.0, 0.0, 0.0)


@kernel()
def ekf5ab_predict(s, c, v_alpha, v_beta):
    """Stationary-frame EKF5 time update with the alpha-beta vector the inverter held over
    the period, turned into the filter's own frame at mid-period,
    (v_d, v_q) = Park(v_alpha, v_beta, theta + N omega dt / 2), then A2-A6 as the EKF5.
    The angle thus enters J_f through the voltage: d v_d/d theta = v_q, d v_q/d theta = -v_d
    (f03, f13), and via the mid-period angle also d/d omega (c_mid). x0 is the estimate at
    the first sample, so the first call (the period before it) is no time update; see
    ``pmsm_ev.observers.Ekf5AlphaBeta``."""
    if s[S_STARTED] == 0.0:
        s[S_STARTED] = 1.0
        return
    c_mid = c[C_C_MID]
    v_d, v_q = park(v_alpha, v_beta, s[S_X + 3] + c_mid * s[S_X + 2])
    ekf5_time_update(s, c, v_d, v_q, c[C_C_VD] * v_q, -c[C_C_VQ] * v_d, c_mid)


@kernel()
def ekf4_predict(s, c, v_d, v_q):
    """EKF4 time update: the EKF5 model without T_L, omega a random walk (dw/dt = 0).

    J_f rows: r0 = [f00 f01 f02 0], r1 = [f10 f11 f12 0], r2 = [0 0 1 0], r3 = [0 0 f32 1].
    """
    i_d = s[S_X]
    i_q = s[S_X + 1]
    w = s[S_X + 2]
    th = s[S_X + 3]
    c_wq, c_wd, c_wpsi, c_th = c[C_C_WQ], c[C_C_WD], c[C_C_WPSI], c[C_C_TH]
    f00, f01, f02 = c[C_A_RD], c_wq * w, c_wq * i_q
    f10, f11, f12 = -c_wd * w, c[C_A_RQ], -c_wd * i_d - c_wpsi
    f32 = c_th
    s[S_X] = c[C_A_RD] * i_d + c_wq * w * i_q + c[C_C_VD] * v_d  # (A2)
    s[S_X + 1] = c[C_A_RQ] * i_q - c_wd * w * i_d - c_wpsi * w + c[C_C_VQ] * v_q  # (A3)
    s[S_X + 3] = th + c_th * w  # (A5)
    for j in range(4):
        p0 = s[S_P + j]
        p1 = s[S_P + 4 + j]
        p2 = s[S_P + 8 + j]
        p3 = s[S_P + 12 + j]
        s[S_A + j] = f00 * p0 + f01 * p1 + f02 * p2
        s[S_A + 4 + j] = f10 * p0 + f11 * p1 + f12 * p2
        s[S_A + 8 + j] = p2
        s[S_A + 12 + j] = f32 * p2 + p3
    for i in range(4):
        a0 = s[S_A + 4 * i]
        a1 = s[S_A + 4 * i + 1]
        a2 = s[S_A + 4 * i + 2]
        a3 = s[S_A + 4 * i + 3]
        r = S_P + 4 * i
        s[r] = f00 * a0 + f01 * a1 + f02 * a2
        s[r + 1] = f10 * a0 + f11 * a1 + f12 * a2
        s[r + 2] = a2
        s[r + 3] = f32 * a2 + a3
        s[r + i] += c[C_Q + i]
    s[S_THETA_PRIOR] = s[S_X + 3]


@kernel()
def ekf_update(s, n, s00, s01, s11, y0, y1):
    """Eqs 25-27 from P H^T (at ``S_PHT``), S = H P H^T + R and the innovation y."""
    det = s00 * s11 - s01 * s01
    i00, i01, i11 = s11 / det, -s01 / det, s00 / det  # S^-1
    for i in range(n):  # (25): K = P H^T S^-1; (26)
        a = s[S_PHT + 2 * i]
        b = s[S_PHT + 2 * i + 1]
        k0 = a * i00 + b * i01
        k1 = a * i01 + b * i11
        s[S_K + 2 * i] = k0
        s[S_K + 2 * i + 1] = k1
        s[S_X + i] += k0 * y0 + k1 * y1
    # (27): P - K (P H^T)^T, symmetric by construction; computed on the upper half
    for i in range(n):
        k0 = s[S_K + 2 * i]
        k1 = s[S_K + 2 * i + 1]
        for j in range(i, n):
            v = s[S_P + n * i + j] - k0 * s[S_PHT + 2 * j] - k1 * s[S_PHT + 2 * j + 1]
            s[S_P + n * i + j] = v
            s[S_P + n * j + i] = v
    s[S_X + 3] = wrap_angle(s[S_X + 3])


@kernel()
def ekf_correct_dq(s, c, n, i_d, i_q):
    """Eqs 25-27 with z = [i_d, i_q], h(x) = [x0, x1], J_h = [I_2 0] (A33)."""
    for i in range(n):
        s[S_PHT + 2 * i] = s[S_P + n * i]
        s[S_PHT + 2 * i + 1] = s[S_P + n * i + 1]
    ekf_update(s, n, s[S_P] + c[C_R0], s[S_P + 1], s[S_P + n + 1] + c[C_R1], i_d - s[S_X], i_q - s[S_X + 1])


@kernel()
def ekf5ab_correct(s, c, i_alpha, i_beta):
    """Eqs 25-27 with z = [i_alpha, i_beta], h(x) = inverse Park of (i_d, i_q) at theta.

    J_h rows: [c, -s, 0, h03, 0], [s, c, 0, h13, 0].
    """
    th = s[S_X + 3]
    cs, sn = math.cos(th), math.sin(th)
    xd = s[S_X]
    xq = s[S_X + 1]
    h03 = -sn * xd - cs * xq
    h13 = cs * xd - sn * xq
    for i in range(5):
        r = S_P + 5 * i
        s[S_PHT + 2 * i] = cs * s[r] - sn * s[r + 1] + h03 * s[r + 3]
        s[S_PHT + 2 * i + 1] = sn * s[r] + cs * s[r + 1] + h13 * s[r + 3]
    s00 = cs * s[S_PHT] - sn * s[S_PHT + 2] + h03 * s[S_PHT + 6] + c[C_R0]
    s01 = cs * s[S_PHT + 1] - sn * s[S_PHT + 3] + h03 * s[S_PHT + 7]
    s11 = sn * s[S_PHT + 1] + cs * s[S_PHT + 3] + h13 * s[S_PHT + 7] + c[C_R1]
    ekf_update(s, 5, s00, s01, s11, i_alpha - (cs * xd - sn * xq), i_beta - (sn * xd + cs * xq))


@kernel(_sig("none", _V, _V, _F, _F))
def observer_predict(s, c, u0, u1):
    """The time update of the observer ``C_OBSERVER`` (none for the sensored baseline) with
    the voltage of the period: (v_d, v_q), or (v_alpha, v_beta) for the stationary-frame EKF5."""
    kind = c[C_OBSERVER]
    if kind == OBS_EKF5:
        ekf5_predict(s, c, u0, u1)
    elif kind == OBS_EKF4:
        ekf4_predict(s, c, u0, u1)
    elif kind == OBS_EKF5AB:
        ekf5ab_predict(s, c, u0, u1)


@kernel(_sig("none", _V, _V, _F, _F, _F, _F, _F, _F))
def observer_correct(s, c, i_alpha, i_beta, i_d, i_q, theta_meas, omega_meas):
    """The measurement update of the observer ``C_OBSERVER``; the sensored baseline takes
    the measured currents, speed and angle."""
    kind = c[C_OBSERVER]
    if kind == OBS_EKF5:
        ekf_correct_dq(s, c, 5, i_d, i_q)
    elif kind == OBS_EKF4:
        ekf_correct_dq(s, c, 4, i_d, i_q)
    elif kind == OBS_EKF5AB:
        ekf5ab_correct(s, c, i_alpha, i_beta)
    else:
        s[S_X] = i_d
        s[S_X + 1] = i_q
        s[S_X + 2] = omega_meas
        s[S_X + 3] = theta_meas
        s[S_THETA_PRIOR] = theta_meas


@kernel()
def dead_time_compensated(c, v_alpha, v_beta, i_alpha, i_beta):
    """The voltage sent to the inverter with dead-time compensation: the command minus the
    error ``dead_time_error`` expects for the measured currents, so that the applied voltage
    is the command again. The observers keep the command (``S_V_ALPHA``, ``S_V_BETA``) as
    their voltage input: the compensation's aim is that the motor sees it."""
    e_alpha, e_beta = dead_time_error(i_alpha, i_beta, c[C_DTC_V], c[C_DTC_I0])
    return v_alpha - e_alpha, v_beta - e_beta


@kernel()
def compensate_dead_time(s, c, v_alpha, v_beta, i_alpha, i_beta):
    """``dead_time_compensated``, the result also kept in ``S_V_OUT_ALPHA``, ``S_V_OUT_BETA``."""
    v_alpha, v_beta = dead_time_compensated(c, v_alpha, v_beta, i_alpha, i_beta)
    s[S_V_OUT_ALPHA] = v_alpha
    s[S_V_OUT_BETA] = v_beta
    return v_alpha, v_beta


# -- the control unit ----------------------------------------------------------------------------
@kernel()
def store_command(s, c, i_alpha, i_beta, i_d, i_q, i_qref, v_d, v_q, v_alpha, v_beta):
    """End of a control period, every unit alike: keep the period's currents, references and
    command in the state; return the vector sent to the inverter (the command, plus the dead
    time's expected loss with dead-time compensation on)."""
    s[S_I_D] = i_d
    s[S_I_Q] = i_q
    s[S_I_QREF] = i_qref
    s[S_V_D] = v_d
    s[S_V_Q] = v_q
    s[S_V_ALPHA] = v_alpha
    s[S_V_BETA] = v_beta
    if c[C_DTC_V] != 0.0:
        return compensate_dead_time(s, c, v_alpha, v_beta, i_alpha, i_beta)
    return v_alpha, v_beta


@kernel(_sig(f"UniTuple({_F}, 12)", _V, _V, _F, _F, _F, _F, _F))
def control_step(s, c, i_alpha, i_beta, omega_ref, theta_meas, omega_meas):
    """One control period (see ``pmsm_ev.control_unit``); returns (v_alpha, v_beta, v_d,
    v_q, i_d, i_q, i_qref, i_d_hat, i_q_hat, omega_hat, theta_hat, T_L_hat)."""
    # (23)-(24) with the voltage applied over the last period: the last command, or with a
    # one-period actuation delay, the command before it; the dq command, or for the
    # stationary-frame EKF5 the alpha-beta vector sent to the inverter
    if c[C_OBSERVER] == OBS_EKF5AB:
        u0 = s[S_V_ALPHA]
        u1 = s[S_V_BETA]
    else:
        u0 = s[S_V_D]
        u1 = s[S_V_Q]
    if c[C_DELAYED] != 0.0:
        observer_predict(s, c, s[S_U_PREV_0], s[S_U_PREV_1])
        s[S_U_PREV_0] = u0
        s[S_U_PREV_1] = u1
    else:
        observer_predict(s, c, u0, u1)
    estimated = c[C_ESTIMATED] != 0.0
    theta_frame = s[S_THETA_PRIOR] if estimated else theta_meas
    i_d, i_q = park(i_alpha, i_beta, theta_frame)
    observer_correct(s, c, i_alpha, i_beta, i_d, i_q, theta_meas, omega_meas)  # (25)-(27)
    if c[C_PSI_ADAPT] != 0.0:
        adapt_psi(s, c)
    if estimated:
        theta_ctrl = s[S_X + 3]
        i_d, i_q = park(i_alpha, i_beta, theta_ctrl)
    else:
        theta_ctrl = theta_meas
    omega_hat = s[S_X + 2]
    i_qref = speed_step(s, c, omega_ref, omega_hat)  # (14)
    v_d, v_q = current_step(s, c, c[C_I_D_REF], i_qref, i_d, i_q, omega_hat)  # (15)-(20)
    half_arc = c[C_HALF_PERIOD_N] * omega_hat  # a = omega_e dt / 2
    gain = half_arc / math.sin(half_arc) if c[C_ZOH] != 0.0 and abs(half_arc) > 1e-6 else 1.0
    v_alpha, v_beta = inverse_park(gain * v_d, gain * v_q, theta_ctrl + c[C_ADVANCE] * omega_hat)
    v_alpha, v_beta = store_command(s, c, i_alpha, i_beta, i_d, i_q, i_qref, v_d, v_q, v_alpha, v_beta)
    return (v_alpha, v_beta, v_d, v_q, i_d, i_q, i_qref,
            s[S_X], s[S_X + 1], s[S_X + 2], s[S_X + 3], s[S_X + 4])


# -- the sensorless unit: alignment, I-f, handover to and from the stationary-frame EKF5 --------
_HALF_PI = 0.5 * math.pi


@kernel()
def seat_current_pis(s, c, theta, turn, i_dref, i_qref, i_d, i_q, omega_est):
    """Set the current PIs' integrators and decoupling filters so that ``current_step`` in the
    frame at ``theta`` (with these references, currents and speed) first returns the voltage
    held now, turned on by ``turn`` [rad] (the angle a rotor-synchronous vector turns in a
    period): a change of frame without a voltage jump. The filters start at the references,
    so that only the integrators carry the change (bumpless transfer)."""
    v_d, v_q = park(s[S_V_ALPHA], s[S_V_BETA], theta - turn)
    s[S_I_DL] = i_dref
    s[S_I_QL] = i_qref
    w_e = c[C_N] * omega_est
    s[S_INT_D] = v_d + w_e * c[C_L_Q] * i_qref - c[C_KP_ID] * (i_dref - i_d)  # (15), (19)
    back_emf = w_e * c[C_L_D] * i_dref + w_e * c[C_PSI]
    if c[C_PAPER_SIGNS] != 0.0:
        s[S_INT_Q] = v_q + back_emf - c[C_KP_IQ] * (i_qref - i_q)  # (16), (20) as printed
    else:
        s[S_INT_Q] = v_q - back_emf - c[C_KP_IQ] * (i_qref - i_q)  # (16), (20)


@kernel()
def restart_ekf(s, c, theta, i_d, i_q):
    """The EKF restarted at a known angle from standstill: x = [i_d, i_q, 0, theta, 0], P = the
    restart's P0 (``C_P0_ALIGNED``)."""
    s[S_X] = i_d
    s[S_X + 1] = i_q
    s[S_X + 2] = 0.0
    s[S_X + 3] = theta
    s[S_X + 4] = 0.0
    for i in range(25):
        s[S_P + i] = 0.0
    for i in range(5):
        s[S_P + 6 * i] = c[C_P0_ALIGNED + i]
    s[S_THETA_PRIOR] = theta


@kernel()
def seat_foc(s, c, omega_ref, omega_hat, i_alpha, i_beta, on_load):
    """Hand the drive to FOC on the EKF (mode EKF), seated on the present state: the speed PI's
    integral so that (14) returns the q current that gives the present torque once i_d is at its
    reference (eq 12: the I-f vector's d current adds a reluctance torque N (L_d - L_q) i_d i_q that
    FOC's i_d = 0 takes away), or with ``on_load`` the current of the load the EKF sees,
    T_L_hat / (N psi), after a loss of synchronism, when the present current says nothing of the
    load; the current PIs on the voltage held, turned by one period of the I-f vector's rotation
    (``seat_current_pis``)."""
    theta = s[S_X + 3]
    i_d, i_q = park(i_alpha, i_beta, theta)
    if on_load:
        i_seat = s[S_X + 4] / (c[C_N] * c[C_PSI])
    else:  # N i_q (psi + (L_d - L_q) i_d) = N i_seat (psi + (L_d - L_q) i_dref)
        i_seat = i_q * (c[C_PSI] + (c[C_L_D] - c[C_L_Q]) * i_d) / (c[C_PSI] + (c[C_L_D] - c[C_L_Q]) * c[C_I_D_REF])
    s[S_W_INT] = i_seat - c[C_KP_W] * (omega_ref - omega_hat)  # (14) returns i_seat now
    seat_current_pis(s, c, theta + c[C_ADVANCE] * omega_hat, c[C_N] * s[S_OMEGA_IF] * c[C_DT],
                     c[C_I_D_REF], i_seat, i_d, i_q, omega_hat)
    s[S_AGREE] = 0.0


@kernel()
def vector_torque(c, i, sin_e, cos_e):
    """Eq 12 for a current vector of magnitude ``i`` leading the rotor's d axis by e:
    T_e = N (psi i sin e + (L_d - L_q) i^2 sin e cos e) [N m] (the controller's motor model); with
    L_q > L_d the reluctance term takes torque below e = 90 deg and adds it above."""
    return c[C_N] * i * sin_e * (c[C_PSI] + (c[C_L_D] - c[C_L_Q]) * i * cos_e)


@kernel()
def vector_current(c, torque, sin_e, cos_e):
    """The least magnitude whose vector at the load angle e gives ``torque`` [A] (``vector_torque``
    solved for i, the smaller root); inf if no current does."""
    a = (c[C_L_Q] - c[C_L_D]) * cos_e  # N sin e (psi i - a i^2) = torque
    t = abs(torque) / (c[C_N] * sin_e)
    if abs(a) < 1e-12:
        return t / c[C_PSI]
    disc = c[C_PSI] * c[C_PSI] - 4.0 * a * t
    if disc < 0.0:
        return math.inf
    return 2.0 * t / (c[C_PSI] + math.sqrt(disc))  # = (psi - sqrt(disc)) / (2 a), without cancellation


@kernel()
def if_vector_step(s, c, omega_ref, t_l):
    """I-f: turn the vector and size its current from the torque it can give (eq 12 with the rotor
    lagging the vector by the load angle e, ``vector_torque``; docs/sensorless.md).

    The I-f speed follows ``omega_ref`` with at most ``C_IF_ACCEL`` and at most what the vector's
    torque at the design load angle ``C_E_MAX`` leaves over the load the EKF sees,
    J dw/dt = T_e(i, e_max) - T_L_hat (never forced to turn against the reference by it: a load
    beyond the vector is the guard's, ``sync_guard``; at the current limit, the torque at 90 deg,
    the reserve spent). The target current is at least what the
    acceleration asked for and that load need at e_max, and ``C_IF_MARGIN`` times the load's
    current; it never falls in I-f. The magnitude ramps at ``C_I_RATE``, at ``C_I_RATE_LOAD``
    while the guard holds the vector back (the load exceeds the vector). ``t_l``: the load [N m]."""
    dt = c[C_DT]
    sin_e = c[C_SIN_E]
    cos_e = math.cos(c[C_E_MAX])
    j = c[C_J_IF]
    if s[S_I_MAG] < c[C_I_Q_MAX]:
        t_cap = vector_torque(c, s[S_I_MAG], sin_e, cos_e)
    else:  # at the current limit the reserve is spent: the torque at 90 deg (up to the soft guard)
        t_cap = c[C_N] * c[C_PSI] * s[S_I_MAG]
    step = c[C_IF_ACCEL] * dt
    hi = min(step, max((t_cap - t_l) / j * dt, 0.0))
    lo = max(-step, min((-t_cap - t_l) / j * dt, 0.0))
    w_if = s[S_OMEGA_IF]
    want = min(max(omega_ref - w_if, -step), step)  # the step the reference asks for
    s[S_OMEGA_IF] = w_if + min(max(want, lo), hi)
    s[S_PHI] = wrap_angle(s[S_PHI] + c[C_N] * s[S_OMEGA_IF] * dt)  # (13)
    need = vector_current(c, t_l + j * want / dt, sin_e, cos_e)
    load_current = c[C_IF_MARGIN] * abs(t_l) / (c[C_N] * c[C_PSI])  # eq 12 with i_d = 0, times the margin
    s[S_I_TGT] = min(max(s[S_I_TGT], need, load_current), c[C_I_Q_MAX])
    rate = (c[C_I_RATE_LOAD] if s[S_GUARD] != 0.0 else c[C_I_RATE]) * dt
    s[S_I_MAG] += min(max(s[S_I_TGT] - s[S_I_MAG], -rate), rate)


#: the guard: beyond this lead of the vector over the EKF's angle [rad] the vector turns no faster than
#: the rotor away from it (90 deg: past it, more lead gives more torque only through the reluctance term)
_SOFT_GUARD = 0.5 * math.pi
#: it counts as holding the vector until the vector is back by this much [rad]: 3 deg, so that a vector
#: held there and turning with the rotor does not flicker in and out
_GUARD_BAND = math.radians(3.0)
#: ``S_GUARD`` values: the soft limit holds the vector's speed, the hard one its angle
GUARD_SOFT, GUARD_HARD = 1.0, 2.0


@kernel()
def sync_guard(s, c, omega_hat, lag, theta):
    """Keep the applied I-f vector (``S_PHI`` less ``lag``, the damping's pull-back) within
    +-``C_E_GUARD`` of the rotor's angle ``theta`` (electrical: the EKF's, or while the car stands
    the one it had when the stand began): a vector that would lead (or trail) the
    rotor by more is held there and turns at the rotor's speed, so the rotor cannot fall out of
    step while the EKF holds its angle (``GUARD_HARD``). Beyond ``_SOFT_GUARD`` its speed is held to
    the rotor's (``GUARD_SOFT``): the lead stops growing before the EKF, whose load state lags a
    sudden load, shows the rotor slowing. ``S_GUARD`` is released once the vector is back within
    ``_SOFT_GUARD`` by ``_GUARD_BAND``."""
    e = wrap_angle(s[S_PHI] - lag - theta)
    e_max = c[C_E_GUARD]
    if e > e_max or e < -e_max:
        s[S_PHI] = wrap_angle(theta + lag + (e_max if e > 0.0 else -e_max))
        s[S_OMEGA_IF] = omega_hat
        s[S_GUARD] = GUARD_HARD
    elif (e > _SOFT_GUARD and s[S_OMEGA_IF] > omega_hat) or (e < -_SOFT_GUARD and s[S_OMEGA_IF] < omega_hat):
        s[S_OMEGA_IF] = omega_hat
        s[S_GUARD] = GUARD_SOFT
    elif abs(e) < _SOFT_GUARD - _GUARD_BAND:
        s[S_GUARD] = 0.0


@kernel()
def relock(s, c, omega_hat, omega_ref):
    """Recovery at low speed (a loss of synchronism, or a rotor running away under the alignment):
    the vector put on the EKF's angle, leading it by the design load angle in the direction of the
    torque needed to hold the load the EKF sees and to bring the speed to the reference within
    ``_RELOCK_TIME``, turning at the EKF's speed, its current set to the limit at once."""
    push = s[S_X + 4] + c[C_J_IF] * (omega_ref - omega_hat) / _RELOCK_TIME
    s[S_PHI] = wrap_angle(s[S_X + 3] + (c[C_E_MAX] if push >= 0.0 else -c[C_E_MAX]))
    s[S_OMEGA_IF] = omega_hat
    s[S_I_TGT] = c[C_I_Q_MAX]
    s[S_I_MAG] = c[C_I_Q_MAX]  # at once: the rotor is running away (the current PIs follow in ~5 ms)
    s[S_SLIP] = 0.0


#: the time in which a relocked vector's torque is meant to bring the speed to the reference [s]
_RELOCK_TIME = 0.5


@kernel(_sig(f"UniTuple({_F}, 16)", _V, _V, _F, _F, _F))
def sensorless_step(s, c, i_alpha, i_beta, omega_ref):
    """One control period of the sensorless unit (``pmsm_ev.control_unit``, observer
    "sensorless"): never reads the rotor angle or speed. Returns ``control_step``'s outputs,
    the mode (``MODE_ALIGN``, ``MODE_IF``, ``MODE_EKF``), the fault (``FAULT_*``) and the control
    frame's angle [rad] and speed [rad/s].

    1. The stationary-frame EKF5 (eqs 23-27 with h = inverse Park) runs in every mode.
    2. Alignment (``C_T_RAMP`` .. ``C_T_SETTLE``): the current vector ramped up on +90 deg,
       held, swept to 0 deg, held (damped on the back-EMF); then the EKF restarts at the aligned
       angle, at rest. The speed reference is not read. A rotor that runs away under the vector
       (|omega_hat| > ``C_ALIGN_SLIP`` for ``C_ALIGN_SLIP_TIME``: a load beyond it) ends the alignment: I-f on the EKF's
       angle (``relock``), as a loss-of-synchronism episode.
    3. I-f: the vector turns at the I-f speed (the reference, slew-limited by what the vector's
       torque allows: ``if_vector_step``), within the guard angle of the EKF's angle
       (``sync_guard``); handover up once omega_hat agrees with the I-f speed.
    4. EKF: FOC (eqs 14-20) on the EKF's angle and speed; back to I-f at low speed.
    5. Loss of synchronism (I-f): |omega_hat - omega_if| (filtered) above ``C_SLIP_TOL`` +
       ``C_AGREE_TOL`` |omega_if| for ``C_SLIP_TIME`` (or a limit reached: the guard holding the
       vector with the current at ``C_I_Q_MAX`` and the rotor as far from the reference, that long:
       an episode, nothing more to give); recovery:
       a flying handover to FOC when |omega_hat| >= ``C_W_DOWN``, else ``relock``; the guard is on
       while an episode lasts (also when ``C_GUARD`` is off) and in the safe state. An episode
       ends after ``C_RECOVER_TIME`` in synchronism; one older than ``C_FAULT_TIME`` latches the
       fault: the safe state is a stop and hold (the reference taken as 0, the I-f current at the limit).
    In alignment and I-f the current PIs work in the vector's frame (reference on its d
    axis, no decoupling: the back-EMF is small there and the integrators carry it).
    """
    dt = c[C_DT]
    if c[C_DELAYED] != 0.0:
        ekf5ab_predict(s, c, s[S_U_PREV_0], s[S_U_PREV_1])
        s[S_U_PREV_0] = s[S_V_ALPHA]
        s[S_U_PREV_1] = s[S_V_BETA]
    else:
        ekf5ab_predict(s, c, s[S_V_ALPHA], s[S_V_BETA])
    ekf5ab_correct(s, c, i_alpha, i_beta)  # (25)-(27)
    # the rotor's speed above C_STILL counts only once it lasts (the EKF's speed noise at a stand with
    # 1 A of sensor noise crosses 0.5 rad/s for a few periods at a time)
    s[S_STILL_OUT] = s[S_STILL_OUT] + c[C_DT] if abs(s[S_X + 2]) >= c[C_STILL] else 0.0
    if (s[S_MODE] == MODE_IF and abs(s[S_OMEGA_IF]) < c[C_STILL]
            and (abs(s[S_X + 2]) < c[C_STILL] or (s[S_ANCHORED] != 0.0 and s[S_STILL_OUT] < 0.5 * c[C_SLIP_TIME]))):
        # the car stands on the I-f vector: no back-EMF shows the angle, and the EKF's (and with it its
        # load) drifts with the sensors' noise and offsets; the rotor is held, so the guard and the I-f
        # sizing take the angle and the load of when the stand began, and the EKF is put back there
        # when the stand ends
        if s[S_ANCHORED] == 0.0:
            s[S_ANCHOR] = s[S_X + 3]
            s[S_ANCHOR_TL] = s[S_X + 4]
            s[S_ANCHORED] = 1.0
    elif s[S_ANCHORED] != 0.0:  # the stand ends
        if abs(s[S_X + 2]) < c[C_STILL]:  # the vector starts to turn (a restart): the EKF restarted at
            i_d, i_q = park(i_alpha, i_beta, s[S_ANCHOR])  # the stand's angle, at rest (as after the
            restart_ekf(s, c, s[S_ANCHOR], i_d, i_q)  # alignment), on the stand's load
        else:  # the rotor moves (a load that changed): the EKF, which sees it, put back on that angle
            s[S_X + 3] = s[S_ANCHOR]
        s[S_X + 4] = s[S_ANCHOR_TL]
        s[S_ANCHORED] = 0.0
    if c[C_PSI_ADAPT] != 0.0 and s[S_MODE] == MODE_EKF:
        adapt_psi(s, c)
    if s[S_FAULT] == FAULT_LATCHED:  # the safe state: stop and hold
        omega_ref = 0.0
    t = s[S_CLOCK] * dt
    s[S_CLOCK] += 1.0
    mode = s[S_MODE]
    omega_hat = s[S_X + 2]
    if mode == MODE_ALIGN:  # how long the EKF has seen the rotor turn faster than C_ALIGN_SLIP
        s[S_LOS] = s[S_LOS] + dt if (c[C_ALIGN_SLIP] > 0.0 and abs(omega_hat) > c[C_ALIGN_SLIP]) else 0.0
    if mode == MODE_ALIGN and s[S_LOS] >= c[C_ALIGN_SLIP_TIME]:
        # the rotor runs away under the alignment's vector, faster than the alignment's own swing: a
        # load beyond the vector (a car parked on a slope). Its motion has shown the EKF the angle
        # (back-EMF): the EKF is kept (not restarted) and I-f takes over on its angle, the vector put
        # ahead of the rotor against the load at the current limit, as a loss-of-synchronism episode
        s[S_OMEGA_IF] = omega_hat
        relock(s, c, omega_hat, omega_ref)
        s[S_LOS] = 0.0
        s[S_EPISODE] = dt
        s[S_INSYNC] = 0.0
        s[S_AGREE] = 0.0
        mode = MODE_IF
    elif mode == MODE_ALIGN:
        t_hold = c[C_T_RAMP] + c[C_T_HOLD]
        t_sweep = t_hold + c[C_T_SWEEP]
        if t < t_sweep + c[C_T_SETTLE]:
            s[S_I_MAG] = c[C_I_ALIGN] * min(t / c[C_T_RAMP], 1.0) if c[C_T_RAMP] > 0.0 else c[C_I_ALIGN]
            if t < t_hold:
                s[S_PHI] = _HALF_PI
                s[S_OMEGA_IF] = 0.0
            elif t < t_sweep:
                s[S_PHI] = _HALF_PI * (1.0 - (t - t_hold) / c[C_T_SWEEP])
                s[S_OMEGA_IF] = -_HALF_PI / (c[C_T_SWEEP] * c[C_N])  # the sweep's speed [rad/s]
            else:
                s[S_PHI] = 0.0
                s[S_OMEGA_IF] = 0.0
        else:  # aligned: the magnet is on the vector; the EKF restarts there, at rest
            i_d, i_q = park(i_alpha, i_beta, s[S_PHI])
            restart_ekf(s, c, s[S_PHI], i_d, i_q)
            omega_hat = 0.0
            s[S_OMEGA_IF] = 0.0
            s[S_SLIP] = 0.0
            s[S_I_TGT] = max(c[C_I_IF], s[S_I_MAG])
            mode = MODE_IF
    elif mode == MODE_EKF and abs(omega_hat) < c[C_W_DOWN]:
        # handover down: the vector stays where the current is, its magnitude ramps up
        i_mag = math.sqrt(i_alpha * i_alpha + i_beta * i_beta)
        s[S_PHI] = math.atan2(i_beta, i_alpha)
        s[S_I_MAG] = i_mag
        s[S_I_TGT] = max(c[C_IF_MARGIN] * i_mag, c[C_I_IF])
        s[S_OMEGA_IF] = omega_hat
        s[S_AGREE] = 0.0
        s[S_SLIP] = 0.0
        seat_current_pis(s, c, s[S_PHI] + c[C_ADVANCE] * omega_hat, c[C_N] * omega_hat * dt,
                         i_mag, 0.0, i_mag, 0.0, 0.0)
        mode = MODE_IF
    trouble = False  # this period, in I-f: out of step, or a limit reached (the episode's clock)
    if mode == MODE_IF:
        if t > 0.0 and s[S_MODE] == MODE_IF:  # turn the vector (not in the period it was placed)
            if s[S_FAULT] == FAULT_LATCHED:
                s[S_I_TGT] = c[C_I_Q_MAX]
            anchored = s[S_ANCHORED] != 0.0
            if_vector_step(s, c, omega_ref, s[S_ANCHOR_TL] if anchored else s[S_X + 4])
            # the damping's input, omega_hat - omega_if low-pass filtered (see below)
            s[S_SLIP] += c[C_SLIP_FILTER] * (omega_hat - s[S_OMEGA_IF] - s[S_SLIP])
            if c[C_GUARD] != 0.0 or s[S_EPISODE] > 0.0 or s[S_FAULT] == FAULT_LATCHED:  # on while recovering
                sync_guard(s, c, omega_hat, c[C_IF_DAMP] / math.sqrt(max(s[S_I_MAG], 1.0)) * s[S_SLIP],
                           s[S_ANCHOR] if anchored else s[S_X + 3])
        w_if = s[S_OMEGA_IF]
        slipping = abs(s[S_SLIP]) > c[C_SLIP_TOL] + c[C_AGREE_TOL] * abs(w_if)
        # in trouble: out of step, or a limit reached: the guard holding the vector at the current
        # limit while the rotor does not follow the reference (a load beyond what the drive gives)
        trouble = slipping or (s[S_GUARD] != 0.0 and s[S_I_MAG] >= c[C_I_Q_MAX] and abs(omega_ref - omega_hat)
                               > c[C_SLIP_TOL] + c[C_AGREE_TOL] * abs(omega_ref))
        s[S_LOS] = s[S_LOS] + dt if trouble else 0.0
        if s[S_LOS] >= c[C_SLIP_TIME]:
            s[S_LOS] = 0.0
            s[S_INSYNC] = 0.0
            if s[S_EPISODE] == 0.0:
                s[S_EPISODE] = dt
            # at the limit (not slipping) there is nothing more to give: the episode runs on to the fault
            if slipping and abs(omega_hat) >= c[C_W_DOWN]:  # loss of synchronism, the rotor turns and the
                seat_foc(s, c, omega_ref, omega_hat, i_alpha, i_beta, True)  # EKF holds its angle: flying handover
                mode = MODE_EKF
            elif slipping:  # at low speed: the vector put back on the rotor
                relock(s, c, omega_hat, omega_ref)
            w_if = s[S_OMEGA_IF]
        if mode == MODE_IF:
            if abs(w_if) > c[C_W_UP] and abs(omega_hat - w_if) < c[C_AGREE_TOL] * abs(w_if):
                s[S_AGREE] += dt
            else:
                s[S_AGREE] = 0.0
            if s[S_AGREE] >= c[C_AGREE_TIME]:  # handover up: FOC on the EKF, seated on the present state
                seat_foc(s, c, omega_ref, omega_hat, i_alpha, i_beta, False)
                mode = MODE_EKF
    if s[S_EPISODE] > 0.0:  # a loss-of-synchronism episode: recovered, or the fault latched
        s[S_EPISODE] += dt
        s[S_INSYNC] = 0.0 if trouble else s[S_INSYNC] + dt
        if s[S_INSYNC] >= c[C_RECOVER_TIME]:
            s[S_EPISODE] = 0.0
        elif s[S_EPISODE] >= c[C_FAULT_TIME]:
            s[S_FAULT] = FAULT_LATCHED
    s[S_MODE] = mode
    if mode == MODE_EKF:
        theta_ctrl = s[S_X + 3]
        omega_ctrl = omega_hat
        i_d, i_q = park(i_alpha, i_beta, theta_ctrl)
        i_qref = speed_step(s, c, omega_ref, omega_hat)  # (14)
        v_d, v_q = current_step(s, c, c[C_I_D_REF], i_qref, i_d, i_q, omega_hat)  # (15)-(20)
    else:
        theta_ctrl = s[S_PHI]
        omega_ctrl = s[S_OMEGA_IF]
        if mode == MODE_IF:  # damp the rotor's swing on the vector: pull the vector back by
            # k (omega_hat - omega_if), filtered (updated with the vector's turn, above; 0 in the period
            # it is placed), k = 2 zeta sqrt(J / (psi i)) (docs/sensorless.md)
            theta_ctrl -= c[C_IF_DAMP] / math.sqrt(max(s[S_I_MAG], 1.0)) * s[S_SLIP]
        elif c[C_ALIGN_DAMP] != 0.0:  # alignment: the same damping on the speed the back-EMF shows
            # on the vector's q axis, v_q / (N psi) = omega_m cos(e) (e the vector's lead; the EKF's
            # angle is unknown here), less the sweep's own speed: the torque it adds is
            # -N psi i k omega_m cos^2(e), a damping whatever the angle (docs/sensorless.md)
            s[S_SLIP] += c[C_SLIP_FILTER] * (s[S_V_Q] / (c[C_N] * c[C_PSI]) - omega_ctrl - s[S_SLIP])
            theta_ctrl -= c[C_IF_DAMP] / math.sqrt(max(s[S_I_MAG], 1.0)) * s[S_SLIP]
        else:
            s[S_SLIP] = 0.0
        i_d, i_q = park(i_alpha, i_beta, theta_ctrl)
        i_qref = 0.0
        v_d, v_q = current_step(s, c, s[S_I_MAG], 0.0, i_d, i_q, 0.0)  # (15)-(16), no decoupling
    s[S_THETA_CTRL] = theta_ctrl
    s[S_OMEGA_CTRL] = omega_ctrl
    fault = s[S_FAULT] if s[S_FAULT] == FAULT_LATCHED else (FAULT_RECOVERING if s[S_EPISODE] > 0.0 else FAULT_NONE)
    v_alpha, v_beta = inverse_park(v_d, v_q, theta_ctrl + c[C_ADVANCE] * omega_ctrl)
    v_alpha, v_beta = store_command(s, c, i_alpha, i_beta, i_d, i_q, i_qref, v_d, v_q, v_alpha, v_beta)
    return (v_alpha, v_beta, v_d, v_q, i_d, i_q, i_qref,
            s[S_X], s[S_X + 1], s[S_X + 2], s[S_X + 3], s[S_X + 4], mode, fault, theta_ctrl, omega_ctrl)
