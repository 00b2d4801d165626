"""Slave of FocEkf4.fmu: FOC with the fourth-order EKF (observer "ekf4")."""

from __future__ import annotations

from pmsm_ev_fmus.foc_slave import FocSlave


class FocEkf4(FocSlave):
    """ControlUnit with observer "ekf4"."""

    def __init__(self, **kwargs):
        super().__init__(
            "ekf4",
            "a fourth-order EKF (state i_d, i_q, omega_m, theta_e, no load torque; the speed is a "
            "random walk with variance q_omega_ekf4), measuring i_d, i_q in the controller's frame",
            parameter_notes={name: "not used by this observer" for name in ("q_omega", "q_TL", "p0_TL")},
            **kwargs)
