"""The plant: vehicle (eqs 1-9, 28-29) driven by the PMSM (eqs 10-13).

Its physical interface is the stationary frame: it takes the inverter voltage
(v_alpha, v_beta), held constant over a step, and the road elevation delta, and gives
the measured phase currents (i_alpha, i_beta). Inside it integrates the dq model at the
true rotor angle with RK4 sub-steps. Truth signals are exposed for recording.

Optional realism, all off by default (``PlantParams``): current sensors with white
noise, offset, gain error and ADC quantisation per phase (two phase sensors, a and b;
the truth outputs stay clean), and an inverter with a DC-link voltage limit and a
one-step actuation delay.
"""

from __future__ import annotations

import math

from .params import MotorParams, PlantParams, VehicleParams, equivalent_inertia
from .pmsm import current_derivatives, electromagnetic_torque, friction_torque
from .transforms import clarke, inverse_park, wrap_angle
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
        p = self.params
        self._sensors = (p.sensor_noise > 0 or p.sensor_offset_a != 0 or p.sensor_offset_b != 0
                         or p.sensor_gain_a != 1 or p.sensor_gain_b != 1 or p.adc_bits > 0)
        self._lsb = 2.0 * p.adc_range / 2 ** int(p.adc_bits) if p.adc_bits else 0.0
        self._u_lim = p.v_dc / math.sqrt(3.0)
        self.reset()

    def reset(self) -> None:
        p = self.params
        self.i_d = p.i_d0
        self.i_q = p.i_q0
        self.omega_m = p.omega_m0
        self.theta_e = wrap_angle(p.theta_e0)
        self.delta = 0.0
        self.samples = 0  # measurements taken so far (the noise counter)
        self._v_pending = (0.0, 0.0)  # voltage received, applied next step (inverter_delay)
        self.v_alpha_applied = self.v_beta_applied = 0.0
        self._update_outputs()

    # -- state as a tuple, for save/restore by wrappers --------------------------
    def get_state(self) -> tuple:
        return (self.i_d, self.i_q, self.omega_m, self.theta_e, self.delta,
                float(self.samples - 1), self._v_pending[0], self._v_pending[1])

    def set_state(self, state) -> None:
        (self.i_d, self.i_q, self.omega_m, self.theta_e, self.delta, samples,
         v_a, v_b) = (float(x) for x in state)
        self.samples = int(samples)  # _update_outputs takes the same sample again
        self._v_pending = (v_a, v_b)
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
        p = self.params
        if p.inverter_delay:
            (v_alpha, v_beta), self._v_pending = self._v_pending, (v_alpha, v_beta)
        if self._u_lim:  # linear range of the inverter: |v| <= v_dc / sqrt(3)
            mag = math.hypot(v_alpha, v_beta)
            if mag > self._u_lim:
                v_alpha *= self._u_lim / mag
                v_beta *= self._u_lim / mag
        self.v_alpha_applied, self.v_beta_applied = v_alpha, v_beta
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
        self.i_alpha_true, self.i_beta_true = self.i_alpha, self.i_beta
        if self._sensors:
            self.i_alpha, self.i_beta = self._measure(self.i_alpha, self.i_beta)
        self.samples += 1
        self.T_e = electromagnetic_torque(self.i_d, self.i_q, m)
        self.T_L_mech = load_torque(self.omega_m, self.delta, self.vehicle)
        self.v_vehicle = vehicle_speed(self.omega_m, self.vehicle)

    def _measure(self, i_alpha: float, i_beta: float) -> tuple[float, float]:
        """Phase currents a, b through the sensors and the ADC, back to alpha-beta."""
        p = self.params
        i_a = i_alpha
        i_b = -0.5 * i_alpha + 0.5 * math.sqrt(3.0) * i_beta
        m_a = p.sensor_gain_a * i_a + p.sensor_offset_a
        m_b = p.sensor_gain_b * i_b + p.sensor_offset_b
        if p.sensor_noise > 0:
            n_a, n_b = gaussian_pair(int(p.sensor_seed), self.samples)
            m_a += p.sensor_noise * n_a
            m_b += p.sensor_noise * n_b
        if self._lsb:
            m_a = self._quantise(m_a)
            m_b = self._quantise(m_b)
        return clarke(m_a, m_b, -m_a - m_b)  # two sensors: i_c = -i_a - i_b

    def _quantise(self, x: float) -> float:
        r = self.params.adc_range
        return min(max(round(x / self._lsb) * self._lsb, -r), r)


_MASK64 = (1 << 64) - 1


def _splitmix64(x: int) -> int:
    x = (x + 0x9E3779B97F4A7C15) & _MASK64
    x = ((x ^ (x >> 30)) * 0xBF58476D1CE4E5B9) & _MASK64
    x = ((x ^ (x >> 27)) * 0x94D049BB133111EB) & _MASK64
    return x ^ (x >> 31)


def gaussian_pair(seed: int, n: int) -> tuple[float, float]:
    """Two independent standard normal numbers for sample n of stream ``seed``.

    Counter-based (splitmix64 + Box-Muller): the n-th sample depends only on (seed, n),
    so a saved and restored plant continues the same noise sequence.
    """
    base = _splitmix64(seed & _MASK64) ^ ((n * 2) & _MASK64)
    u1 = 1.0 - (_splitmix64(base) >> 11) * (1.0 / 9007199254740992.0)  # (0, 1]
    u2 = (_splitmix64(base ^ 0xD1B54A32D192ED03) >> 11) * (1.0 / 9007199254740992.0)
    r = math.sqrt(-2.0 * math.log(u1))
    return r * math.cos(2.0 * math.pi * u2), r * math.sin(2.0 * math.pi * u2)
