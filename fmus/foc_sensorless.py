"""Slave of FocSensorless.fmu: the truly sensorless unit from standstill (observer
"sensorless"): FOC on the stationary-frame EKF5 at speed and, at and near zero speed (``low_speed``),
either alignment, an I-f start-up and handover (the default) or high-frequency injection."""

from __future__ import annotations

from pmsm_ev_fmus.foc_slave import FocSlave


class FocSensorless(FocSlave):
    """ControlUnit with observer "sensorless"."""

    def __init__(self, **kwargs):
        super().__init__(
            "sensorless",
            "the stationary-frame fifth-order EKF (state i_d, i_q, omega_m, theta_e, T_L; mechanical model "
            "on J_model, by default the drive's whole inertia J_eq) and a low-speed range of its own, one of two "
            "strategies (low_speed). \"injection\" (the shipped sensorless drives' on a saturating motor): at a stop "
            "the angle from the rotor's saliency (a square wave on the estimated d axis, acquisition), the "
            "magnet's polarity from the d axis's saturation (polarity test), FOC on the injection at zero speed, "
            "the EKF blended in from inj_blend_low and alone above inj_blend_high. \"if\" (the default): at "
            "standstill a two-step alignment of the rotor (current vector ramped up on +90 deg, swept to 0 deg), "
            "then an I-f (current-frequency) start following omega_ref, handover to FOC on the EKF's angle and "
            "speed once omega_hat agrees with the I-f speed above omega_up, and back to I-f below omega_down "
            "(stop and hold on a slope). Truly sensorless: the inputs theta_meas and omega_meas are never read. "
            "The speed reference may do anything from t = 0: during the alignment (t_ramp + t_hold + t_sweep + "
            "t_settle, 2.3 s by default) it is not read, and then the I-f speed starts from the rotor's and "
            "follows it as fast as the vector's torque allows (if_accel at most, the current sized for the load "
            "and the acceleration at the load angle if_load_angle); the vector never leads or trails the EKF's "
            "angle by more than guard_angle (the rotor cannot fall out of step); a loss of synchronism is "
            "detected (slip_tol, slip_time), recovered (a flying handover to FOC, or the vector put back on the "
            "rotor), and reported on the output fault, which latches the safe state (stop and hold at i_q_max) "
            "when the recovery fails within fault_time",
            parameter_notes={"q_omega_ekf4": "not used by this observer",
                             "x0_omega": "not used (the EKF restarts at rest after the alignment)",
                             "x0_theta": "not used (the EKF restarts at the aligned angle)",
                             "angle_source": "not used: the sensorless unit always uses its estimate"},
            **kwargs)
