"""Slave of FocEkf5AB.fmu: FOC with the fifth-order EKF measuring the stationary-frame
currents (observer "ekf5ab")."""

from __future__ import annotations

from pmsm_ev_fmus.foc_slave import FocSlave


class FocEkf5AB(FocSlave):
    """ControlUnit with observer "ekf5ab"."""

    def __init__(self, **kwargs):
        super().__init__(
            "ekf5ab",
            "the fifth-order EKF (state i_d, i_q, omega_m, theta_e, T_L) measuring the stationary-frame "
            "currents i_alpha, i_beta and stepped with the applied voltage v_alpha, v_beta turned into its own "
            "frame, so that the angle is observable from the currents alone (x0_theta may be far off at speed)",
            parameter_notes={"q_omega_ekf4": "not used by this observer"},
            **kwargs)
