"""Slave of FocSensorless.fmu: the truly sensorless unit from standstill (observer
"sensorless"): the stationary-frame EKF5 with alignment, I-f start-up and handover."""

from __future__ import annotations

from pmsm_ev_fmus.foc_slave import FocSlave


class FocSensorless(FocSlave):
    """ControlUnit with observer "sensorless"."""

    def __init__(self, **kwargs):
        super().__init__(
            "sensorless",
            "the stationary-frame fifth-order EKF (state i_d, i_q, omega_m, theta_e, T_L; mechanical model "
            "on J_model, by default the drive's whole inertia J_eq) and a low-speed range of its own: at "
            "standstill a two-step alignment of the rotor (current vector ramped up on +90 deg, swept to 0 deg), "
            "then an I-f (current-frequency) start following omega_ref, handover to FOC on the EKF's angle and "
            "speed once omega_hat agrees with the I-f speed above omega_up, and back to I-f below omega_down "
            "(stop and hold on a slope). Truly sensorless: the inputs theta_meas and omega_meas are never read. "
            "Start-up: t_ramp + t_hold + t_sweep + t_settle (2.3 s by default) of alignment before the rotor "
            "turns, so a route should hold omega_ref = 0 that long",
            parameter_notes={"q_omega_ekf4": "not used by this observer",
                             "x0_omega": "not used (the EKF restarts at rest after the alignment)",
                             "x0_theta": "not used (the EKF restarts at the aligned angle)",
                             "angle_source": "not used: the sensorless unit always uses its estimate"},
            **kwargs)
