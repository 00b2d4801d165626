"""Slave of PmsmEvPlant.fmu: the vehicle and PMSM, ``pmsm_ev.plant.Plant``, as an FMI 2.0
co-simulation unit. No equations here: ``do_step(t, h)`` is ``Plant.step(v_alpha, v_beta,
delta, h)``, then the plant's outputs are copied into the output variables.
"""

from __future__ import annotations

import math

from pmsm_ev import __version__
from pmsm_ev.params import MotorParams, PlantParams, VehicleParams
from pmsm_ev.plant import Plant
from pmsm_ev_fmus.slave_support import DriveSlave, FmuUsageError, SimulationError

_MOTOR = ("N", "psi", "L_d", "L_q")  # the motor parameters of eq 12
_VEHICLE_LOAD = ("c_r", "g", "rho_a", "c_d", "A_f", "r_w", "eta", "n_g", "m_v", "v_a", "load_model", "v_eps")

DESCRIPTION = (
    "Vehicle and PMSM of a sensorless EV drive (Wicaksono, Harini, Yusivar, 'Sensorless PMSM "
    "Control using Fifth Order EKF in Electric Vehicle Application'): longitudinal vehicle, "
    "gear and road load (eqs 1-9, 28-29) driven by the dq model of the PMSM (eqs 10-13). "
    "fmi2DoStep(t, h) integrates over [t, t+h] with RK4 (rk4_substeps sub-steps) with the "
    "inputs v_alpha, v_beta (inverter voltage, stationary frame) and delta (road elevation) held; "
    "the outputs are the state at t+h, so no output depends directly on the inputs at the same "
    "communication point. Any step size, fixed or variable. Truth signals (i_d, i_q, omega_m, "
    "theta_e, T_e, T_L_mech, v_vehicle, x_vehicle) are outputs for recording and for a sensored controller. "
    "A Python FMU (pythonfmu): it needs a Python 3 interpreter with numpy; the project code it "
    "runs is bundled in resources/. A state whose speed or currents are not finite fails the step."
)


class PmsmEvPlant(DriveSlave):
    """FMU slave around ``pmsm_ev.plant.Plant``."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.description = DESCRIPTION
        self.version = __version__
        held = "held over the communication step"
        self.add_input("v_alpha", "V", f"stator voltage, alpha axis (stationary frame), {held}")
        self.add_input("v_beta", "V", f"stator voltage, beta axis (stationary frame), {held}")
        self.add_input("delta", "rad", f"road elevation angle, uphill positive, {held}", display_unit="deg")

        at_start = "; before the first step: from the initial-state parameters"
        state = ("i_d0", "i_q0", "theta_e0")
        self.add_output("i_alpha", "A", "measured stator current, alpha axis" + at_start,
                        start=None, start_dependencies=state)
        self.add_output("i_beta", "A", "measured stator current, beta axis" + at_start,
                        start=None, start_dependencies=state)
        self.add_output("i_d", "A", "true d-axis current (rotor frame)" + at_start,
                        start=None, start_dependencies=("i_d0",))
        self.add_output("i_q", "A", "true q-axis current (rotor frame)" + at_start,
                        start=None, start_dependencies=("i_q0",))
        self.add_output("omega_m", "rad/s", "true mechanical rotor speed" + at_start,
                        start=None, start_dependencies=("omega_m0",), display_unit="rpm")
        self.add_output("theta_e", "rad", "true electrical rotor angle, wrapped to [-pi, pi)" + at_start,
                        start=None, start_dependencies=("theta_e0",))
        self.add_output("T_e", "N.m", "electromagnetic torque (eq 12)" + at_start,
                        start=None, start_dependencies=("i_d0", "i_q0") + _MOTOR)
        self.add_output("T_L_mech", "N.m",
                        "road load torque on the motor shaft (eq 29) at the elevation held over the "
                        "last step; before the first step: at the initial speed on a level road",
                        start=None, start_dependencies=("omega_m0",) + _VEHICLE_LOAD)
        self.add_output("v_vehicle", "m/s", "vehicle speed" + at_start,
                        start=None, start_dependencies=("omega_m0", "r_w", "n_g"), display_unit="km/h")
        self.add_output("x_vehicle", "m", "distance travelled since the start, forward positive "
                                          "(vehicle position; 0 before the first step)",
                        start=None, start_dependencies=())

        self.add_parameters(MotorParams, VehicleParams, PlantParams)
        self._plant = None

    # -- physics hooks ---------------------------------------------------------------
    def build(self) -> None:
        self._plant = Plant(self.parameters(MotorParams), self.parameters(VehicleParams),
                            self.parameters(PlantParams))  # validates all three groups
        self.mark_built()
        self._copy_outputs()

    def physics_state(self):
        """The plant's state (``Plant.get_state``: named fields)."""
        return self._plant.get_state()

    def restore_physics(self, snapshot) -> None:
        if self._plant is None or self.needs_rebuild():
            self.build()
        self._plant.set_state(snapshot)
        self._copy_outputs()

    def forget_physics(self) -> None:
        self._plant = None

    def _copy_outputs(self) -> None:
        p = self._plant
        self.i_alpha = p.i_alpha
        self.i_beta = p.i_beta
        self.i_d = p.i_d
        self.i_q = p.i_q
        self.omega_m = p.omega_m
        self.theta_e = p.theta_e
        self.T_e = p.T_e
        self.T_L_mech = p.T_L_mech
        self.v_vehicle = p.v_vehicle
        self.x_vehicle = p.x_vehicle

    # -- FMI -------------------------------------------------------------------------
    def do_step(self, current_time, step_size):
        try:
            if not self._initialized:
                raise FmuUsageError("fmi2DoStep before fmi2ExitInitializationMode")
            if not step_size > 0.0:
                raise FmuUsageError(f"communication step size must be > 0 s (got {step_size!r})")
            (self.i_d, self.i_q, self.omega_m, self.theta_e, self.i_alpha, self.i_beta, self.T_e,
             self.T_L_mech, self.v_vehicle) = self._plant.step(self.v_alpha, self.v_beta, self.delta, step_size)
            self.x_vehicle = self._plant.x_vehicle
            if not math.isfinite(self.omega_m + self.i_d + self.i_q):
                raise SimulationError(f"plant state is not finite at t = {current_time + step_size!r} s "
                                      f"(omega_m={self.omega_m!r}, i_d={self.i_d!r}, i_q={self.i_q!r})")
        except Exception as exc:
            self._fail("fmi2DoStep", exc)
            raise
        return True
