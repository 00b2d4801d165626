"""Slave of FocSensored.fmu: FOC with measured speed and angle (observer "sensored")."""

from __future__ import annotations

from pmsm_ev_fmus.foc_slave import FocSlave

_UNUSED = ("q_i", "q_omega", "q_theta", "q_TL", "r_i", "p0_i", "p0_omega", "p0_theta", "p0_TL", "q_omega_ekf4",
           "x0_omega", "x0_theta")


class FocSensored(FocSlave):
    """ControlUnit with observer "sensored"."""

    def __init__(self, **kwargs):
        notes = {name: "not used by the sensored observer" for name in _UNUSED}
        notes["angle_source"] = "the sensored observer always uses the measured angle"
        super().__init__(
            "sensored",
            "the sensored baseline: the inputs theta_meas and omega_meas are the angle and speed "
            "estimates (no observer; T_L_hat is 0)",
            parameter_notes=notes,
            **kwargs)
