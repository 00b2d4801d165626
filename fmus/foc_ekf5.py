"""Slave of FocEkf5.fmu: FOC with the paper's fifth-order EKF (observer "ekf5")."""

from __future__ import annotations

from pmsm_ev_fmus.foc_slave import FocSlave


class FocEkf5(FocSlave):
    """ControlUnit with observer "ekf5"."""

    def __init__(self, **kwargs):
        super().__init__(
            "ekf5",
            "the paper's fifth-order EKF (eqs 21-27, appendix A1-A33), state i_d, i_q, omega_m, "
            "theta_e, T_L, measuring i_d, i_q in the controller's frame",
            parameter_notes={"q_omega_ekf4": "not used by this observer"},
            **kwargs)
