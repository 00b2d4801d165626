"""The plant: vehicle (eqs 1-9, 28-29) driven by the PMSM (eqs 10-13).

Its physical interface is the stationary frame: it takes the inverter voltage
(v_alpha, v_beta), held constant over a step, and the road elevation delta, and gives
the measured phase currents (i_alpha, i_beta). Inside it integrates the dq model at the
true rotor angle with RK4 sub-steps. Truth signals are exposed for recording.
"""

from __future__ import annotations

import math

from .params import MotorParams, PlantParams, VehicleParams, equivalent_inertia
from .pmsm import current_derivatives, electromagnetic_torque, friction_torque
from .transforms import inverse_park, wrap_angle
from .vehicle import load_torque, vehicle_speed


class Plant:
    """Vehicle + PMSM with state (i_d, i_q, omega_m, theta_e)."""

    def __init__(self, motor: MotorParams | None = None, vehicle: VehicleParams | None = None,
                 plant: PlantParams | None = None):
        self.motor = motor or MotorParams()
        self.vehicle = vehicle or VehicleParams()
        self.params = plant or PlantParams()
        for group in (self.motor, self.vehicle, self.params):
            group.validate()
        self.J_eq = equivalent_inertia(self.motor, self.vehicle)  # eq 9, left side
        self.reset()

    def reset(self) -> None:
        p = self.params
        self.i_d = p.i_d0
        self.i_q = p.i_q0
        self.omega_m = p.omega_m0
        self.theta_e = wrap_angle(p.theta_e0)
        self.delta = 0.0
        self._update_outputs()

    # -- state as a tuple, for save/restore by wrappers --------------------------
    def get_state(self) -> tuple:
        return (self.i_d, self.i_q, self.omega_m, self.theta_e, self.delta)

    def set_state(self, state) -> None:
        self.i_d, self.i_q, self.omega_m, self.theta_e, self.delta = (float(x) for x in state)
        self._update_outputs()

    def derivatives(self, i_d, i_q, omega_m, theta_e, v_alpha, v_beta, delta):
        """d/dt of (i_d, i_q, omega_m, theta_e) for a stationary-frame voltage."""
        m = self.motor
        c = math.cos(theta_e)
        s = math.sin(theta_e)
        v_d = c * v_alpha + s * v_beta  # Park at the true angle
        v_q = -s * v_alpha + c * v_beta
        did, diq = current_derivatives(i_d, i_q, omega_m, v_d, v_q, m)  # (10), (11)
        t_e = electromagnetic_torque(i_d, i_q, m)  # (12)
        t_l = load_torque(omega_m, delta, self.vehicle)  # (29)
        t_f = friction_torque(omega_m, m, self.vehicle.load_model)  # (8): B_m w + T_m0
        dw = (t_e - t_f - t_l) / self.J_eq  # (9) = (28)
        dth = m.N * omega_m  # (13)
        return did, diq, dw, dth

    def step(self, v_alpha: float, v_beta: float, delta: float, dt: float) -> None:
        """Advance by dt with the voltage and elevation held (RK4, ``rk4_substeps``)."""
        self.delta = delta
        n = self.params.rk4_substeps
        h = dt / n
        x0, x1, x2, x3 = self.i_d, self.i_q, self.omega_m, self.theta_e
        f = self.derivatives
        for _ in range(n):
            k1 = f(x0, x1, x2, x3, v_alpha, v_beta, delta)
            k2 = f(x0 + 0.5 * h * k1[0], x1 + 0.5 * h * k1[1], x2 + 0.5 * h * k1[2],
                   x3 + 0.5 * h * k1[3], v_alpha, v_beta, delta)
            k3 = f(x0 + 0.5 * h * k2[0], x1 + 0.5 * h * k2[1], x2 + 0.5 * h * k2[2],
                   x3 + 0.5 * h * k2[3], v_alpha, v_beta, delta)
            k4 = f(x0 + h * k3[0], x1 + h * k3[1], x2 + h * k3[2], x3 + h * k3[3],
                   v_alpha, v_beta, delta)
            x0 += h / 6.0 * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0])
            x1 += h / 6.0 * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1])
            x2 += h / 6.0 * (k1[2] + 2.0 * k2[2] + 2.0 * k3[2] + k4[2])
            x3 += h / 6.0 * (k1[3] + 2.0 * k2[3] + 2.0 * k3[3] + k4[3])
        self.i_d, self.i_q, self.omega_m = x0, x1, x2
        self.theta_e = wrap_angle(x3)
        self._update_outputs()

    def _update_outputs(self) -> None:
        m = self.motor
        self.i_alpha, self.i_beta = inverse_park(self.i_d, self.i_q, self.theta_e)
        self.T_e = electromagnetic_torque(self.i_d, self.i_q, m)
        self.T_L_mech = load_torque(self.omega_m, self.delta, self.vehicle)
        self.v_vehicle = vehicle_speed(self.omega_m, self.vehicle)
