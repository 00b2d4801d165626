"""The plant: vehicle (eqs 1-9, 28-29) driven by the PMSM (eqs 10-13).

Its physical interface is the stationary frame: it takes the inverter voltage
(v_alpha, v_beta), held constant over a step, and the road elevation delta, and gives
the measured phase currents (i_alpha, i_beta). Inside it integrates the dq model at the
true rotor angle with RK4 sub-steps. Truth signals are exposed for recording.

Optional realism, all off by default (``PlantParams``): current sensors with white
noise, offset, gain error and ADC quantisation per phase (two phase sensors, a and b;
the truth outputs stay clean), and an inverter with a DC-link voltage limit and an
actuation delay of one switching period. A motor that is not its data sheet: inverter dead
time (a per-phase voltage error in the sign of the current), magnetic saturation of L_d, L_q
(flux-form eqs 10-12) and the winding and magnet temperatures (R_s(T), psi(T): constants over a
run, unless the thermal model heats them: the winding alone with ``thermal_R``, both with the lumped-parameter thermal
network ``thermal_model`` 'lptn', in the kernels' step).
The inverter's switching period (``PlantParams.switching_period``), not the communication
step, sets the dead time's voltage error and the delay: a plant stepped at a fraction of the
control period sees the same inverter. The controllers keep their own nominal parameters, so
each is a model mismatch for the observers.

The friction brake (input ``T_brake`` of ``step``, N m at the wheels), the gear model
(``VehicleParams.gear_model``: 'paper', eq 9 as printed, or 'power_flow') and the inverter's
conduction and switching losses (``PlantParams.inverter_losses``, off by default) are in the
kernels too, and so is the energy accounting: ``energy`` holds the DC-link energy, the losses by
kind, the wheel's work by road force and the brake's energy since the start, integrated with the
RK4 stages of the state; ``stored`` the magnetic and kinetic energies of the state; ``energies``
all of them by name (docs/speed-range.md).

The RK4 step, the model (eqs 8-13, 29) and the outputs are ``pmsm_ev.kernels.plant_step``
(compiled with numba when available, see ``pmsm_ev.accel``), with the current sensors'
``plant_step_measured``; this class holds the state and the parameters and adds the optional
sensors and inverter.
"""

from __future__ import annotations

import math

from . import accel
from . import kernels as _k
from .kernels.layout import LayoutError, restore_fields
from .params import (
    TEMPERATURE_REF,
    BatteryParams,
    MotorParams,
    PlantParams,
    VehicleParams,
    equivalent_inertia,
    flux_model_coefficients,
    magnet_flux,
    thermal_network,
    winding_resistance,
)
from .transforms import wrap_angle

#: the energies of ``Plant.energy`` by name (the plant FMU's outputs of the same names) [J]; E_dc_abs is the
#: throughput (the integral of |P_dc|), E_regen what went back into the DC link, E_shaft omega T_e
ENERGY_SLOTS = {"E_dc": _k.E_DC, "E_dc_abs": _k.E_DC_ABS, "E_regen": _k.E_REGEN, "E_copper": _k.E_COPPER,
                "E_friction": _k.E_FRICTION, "E_shaft": _k.E_SHAFT, "E_gear": _k.E_GEAR, "E_aero": _k.E_AERO,
                "E_rolling": _k.E_ROLL, "E_grade": _k.E_GRADE, "E_brake": _k.E_BRAKE,
                "E_inverter": _k.E_INVERTER, "E_iron": _k.E_IRON}
#: the battery's outputs by name (``BatteryParams.battery`` 'ecm'; 0 with the ideal link): its state of charge
#: [-], terminal voltage [V] and current [A], its charge acceptance and discharge power [W], the charge drawn [C],
#: its chemical energy, losses and the energy in its RC pair's capacitor [J] (docs/speed-range.md, "The battery")
BATTERY_SLOTS = {"soc": _k.E_BAT_SOC, "v_bat": _k.E_BAT_V, "i_bat": _k.E_BAT_I, "P_charge_max": _k.E_BAT_P_CHG,
                 "P_discharge_max": _k.E_BAT_P_DIS, "Q_bat": _k.E_BAT_Q, "E_chemical": _k.E_BAT_CHEM,
                 "E_battery": _k.E_BAT_LOSS, "W_battery": _k.E_BAT_W}
#: the thermal network's outputs by name (``PlantParams.thermal_model``; docs/speed-range.md, "A motor that warms"):
#: the temperatures of its nodes [degC] (the start values, constant, with it off), the heat put in by the losses and
#: given to the coolant [J], the over-temperature flags (``pmsm_ev.kernels.TH_OVER_WINDING`` + ``TH_OVER_MAGNET``)
THERMAL_SLOTS = {"T_yoke": _k.E_TH_T + _k.TH_Y, "T_tooth": _k.E_TH_T + _k.TH_T, "T_wdg": _k.E_TH_T + _k.TH_W,
                 "T_pm": _k.E_TH_T + _k.TH_M, "Q_heat": _k.E_TH_IN, "Q_coolant": _k.E_TH_OUT,
                 "over_temperature": _k.E_TH_OVER}
#: the terms whose sum is E_dc (the energy balance, docs/speed-range.md)
BALANCE_TERMS = ("E_copper", "E_inverter", "E_iron", "E_friction", "E_gear", "E_aero", "E_rolling", "E_grade",
                 "E_brake", "dE_kinetic", "dW_magnetic")


def substep_angle_slot(p: PlantParams) -> float:
    """The plant vector's ``P_SUBSTEP_ANGLE``: ``substep_angle`` in the rotor's frame, ``stationary_substep_angle``
    negated with ``integrator`` 'rk6_stationary' (``pmsm_ev.kernels.stationary_frame``: the sign tells the frame)."""
    if p.integrator == "rk6_stationary":
        return -p.stationary_substep_angle
    return p.substep_angle


def inverter_loss_voltage(p: PlantParams) -> float:
    """The inverter's per-phase loss voltage [V] (``pmsm_ev.kernels.inverter_loss``): the mean of the IGBT's
    and the diode's knees, (``inv_v0`` + ``inv_vf0``) / 2, plus the switching losses per ampere,
    f_sw E_sw v_dc / (V_ref I_ref); 0 when ``inverter_losses`` is off."""
    if not p.inverter_losses:
        return 0.0
    return 0.5 * (p.inv_v0 + p.inv_vf0) + p.inv_e_sw * p.v_dc / (p.switching_period * p.inv_v_ref * p.inv_i_ref)


def inverter_slot_values(p: PlantParams) -> dict:
    """The inverter's slots of the plant's vector: the loss voltage (``inverter_loss_voltage``), the mean
    slope (r_CE + r_F) / 2, the IGBT's knee and slope less the diode's and 1 / v_dc
    (``pmsm_ev.kernels.inverter_modulation_loss``); all 0 when ``inverter_losses`` is off."""
    if not p.inverter_losses:
        return {_k.P_INV_V: 0.0, _k.P_INV_R: 0.0, _k.P_INV_DV: 0.0, _k.P_INV_DR: 0.0, _k.P_INV_VDC: 0.0}
    return {_k.P_INV_V: inverter_loss_voltage(p), _k.P_INV_R: 0.5 * (p.inv_r_on + p.inv_r_f),
            _k.P_INV_DV: p.inv_v0 - p.inv_vf0, _k.P_INV_DR: p.inv_r_on - p.inv_r_f, _k.P_INV_VDC: 1.0 / p.v_dc}


def battery_slot_values(b: BatteryParams, p: PlantParams) -> dict:
    """The battery's slots of the plant's vector (``pmsm_ev.kernels.battery_step``) and the inverter's figures that
    follow its voltage each step (``pmsm_ev.kernels.battery_link``): the mean knee, the switching losses' loss
    voltage per volt, the dead time's t_d / T_s."""
    socs, volts = b.ocv_table()
    values = {_k.P_BAT: 1.0, _k.P_BAT_Q: 3600.0 * b.bat_capacity, _k.P_BAT_SOC0: b.bat_soc0, _k.P_BAT_R0: b.bat_R0,
              _k.P_BAT_R1: b.bat_R1, _k.P_BAT_TAU: b.bat_R1 * b.bat_C1, _k.P_BAT_C1: b.bat_C1,
              _k.P_BAT_I_CHG: b.bat_i_charge_max, _k.P_BAT_I_DIS: b.bat_i_discharge_max,
              _k.P_BAT_V_MAX: b.bat_v_max, _k.P_BAT_V_MIN: b.bat_v_min, _k.P_BAT_SOC_TAPER: b.bat_soc_taper,
              _k.P_BAT_N: float(len(socs)),
              _k.P_DT_K: p.dead_time / p.switching_period if p.dead_time else 0.0}
    for j, (z, v) in enumerate(zip(socs, volts)):
        values[_k.P_BAT_OCV + j] = z
        values[_k.P_BAT_OCV + _k.BAT_OCV_MAX + j] = v
    if p.inverter_losses:
        values[_k.P_INV_V0] = 0.5 * (p.inv_v0 + p.inv_vf0)
        values[_k.P_INV_KSW] = p.inv_e_sw / (p.switching_period * p.inv_v_ref * p.inv_i_ref)
    return values


#: the slots of ``io`` that hold ``step``'s results (i_alpha .. v_vehicle, in the layout's order)
_OUTPUTS = slice(_k.PIO_I_ALPHA, _k.PIO_V_VEHICLE + 1)


def _io_slot(slot: int, doc: str) -> property:
    """An attribute of ``Plant`` held in its buffer ``io`` at ``slot``."""
    def get(self) -> float:
        return self._io_items[slot]

    def set_(self, value: float) -> None:
        self._io_items[slot] = value

    return property(get, set_, doc=doc)


class Plant:
    """Vehicle + PMSM with state (i_d, i_q, omega_m, theta_e).

    Its state and outputs after the last step live in its buffer ``io`` (``pmsm_ev.kernels.PLANT_IO_LAYOUT``),
    the attributes of the same names read and write it: the plant FMU's compiled step and the whole loop step the
    plant on it (``pmsm_ev.kernels.plant_fmu_step``), ``step`` with the same kernel, ``plant_advance``."""

    i_d = _io_slot(_k.PIO_I_D, "d current [A]")
    i_q = _io_slot(_k.PIO_I_Q, "q current [A]")
    omega_m = _io_slot(_k.PIO_OMEGA_M, "mechanical rotor speed [rad/s]")
    theta_e = _io_slot(_k.PIO_THETA_E, "electrical rotor angle, wrapped to [-pi, pi) [rad]")
    i_alpha = _io_slot(_k.PIO_I_ALPHA, "alpha current as measured [A]")
    i_beta = _io_slot(_k.PIO_I_BETA, "beta current as measured [A]")
    T_e = _io_slot(_k.PIO_T_E, "electromagnetic torque [N m]")
    T_L_mech = _io_slot(_k.PIO_T_L_MECH, "road load torque on the motor shaft [N m]")
    v_vehicle = _io_slot(_k.PIO_V_VEHICLE, "vehicle speed [m/s]")
    x_vehicle = _io_slot(_k.PIO_X_VEHICLE, "distance travelled since the start [m] (eqs 1, 6 integrated)")
    delta = _io_slot(_k.PIO_PLANT_DELTA, "the road elevation of the last step [rad]")
    T_brake = _io_slot(_k.PIO_PLANT_T_BRAKE, "the friction-brake torque of the last step [N m at the wheels], >= 0")
    clock = _io_slot(_k.PIO_CLOCK, "time since the start [s]: the sum of the steps (the inverter delay's clock)")
    v_alpha_applied = _io_slot(_k.PIO_V_ALPHA_APPLIED, "the alpha voltage applied over the last step [V]")
    v_beta_applied = _io_slot(_k.PIO_V_BETA_APPLIED, "the beta voltage applied over the last step [V]")
    i_alpha_true = _io_slot(_k.PIO_I_ALPHA_TRUE, "alpha current, true [A]")
    i_beta_true = _io_slot(_k.PIO_I_BETA_TRUE, "beta current, true [A]")

    @property
    def samples(self) -> int:
        """The measurements taken so far (the noise counter)."""
        return int(self._io_items[_k.PIO_SAMPLES])

    @samples.setter
    def samples(self, value: int) -> None:
        self._io_items[_k.PIO_SAMPLES] = value

    def __init__(self, motor: MotorParams | None = None, vehicle: VehicleParams | None = None,
                 plant: PlantParams | None = None, battery: BatteryParams | None = None):
        self.motor = motor or MotorParams()
        self.vehicle = vehicle or VehicleParams()
        self.params = plant or PlantParams()
        self.battery = battery or BatteryParams()
        for group in (self.motor, self.vehicle, self.params, self.battery):
            group.validate()
        #: the DC link is the battery's equivalent circuit (``BatteryParams.battery`` 'ecm')
        self.has_battery = self.battery.enabled
        self.J_eq = equivalent_inertia(self.motor, self.vehicle)  # eq 9, left side
        p = self.params
        self._sensors = (p.sensor_noise > 0 or p.sensor_offset_a != 0 or p.sensor_offset_b != 0
                         or p.sensor_gain_a != 1 or p.sensor_gain_b != 1 or p.adc_bits > 0)
        self._lsb = 2.0 * p.adc_range / 2 ** int(p.adc_bits) if p.adc_bits else 0.0
        self._u_lim = p.v_dc / math.sqrt(3.0)
        self._kernels = accel.kernels()
        m, v = self.motor, self.vehicle
        # the winding's and the magnet's temperature (Table I's values hold at 20 degC)
        self.R_s = winding_resistance(m.R_s, p.T_winding, p.alpha_R) if p.T_winding != TEMPERATURE_REF else m.R_s
        self.psi = magnet_flux(m.psi, p.T_magnet, p.alpha_psi) if p.T_magnet != TEMPERATURE_REF else m.psi
        values = {_k.P_R_S: self.R_s, _k.P_L_D: m.L_d, _k.P_L_Q: m.L_q, _k.P_PSI: self.psi, _k.P_N: m.N,
                  _k.P_B_M: m.B_m, _k.P_T_M0: m.T_m0, _k.P_OMEGA_EPS: m.omega_eps, _k.P_J_EQ: self.J_eq,
                  _k.P_M_V: v.m_v, _k.P_G: v.g, _k.P_C_R: v.c_r, _k.P_RHO_A: v.rho_a, _k.P_C_D: v.c_d,
                  _k.P_A_F: v.A_f, _k.P_R_W: v.r_w, _k.P_ETA: v.eta, _k.P_N_G: v.n_g, _k.P_V_A: v.v_a,
                  _k.P_V_EPS: v.v_eps, _k.P_PAPER: 1.0 if v.load_model == "paper" else 0.0,
                  _k.P_SUBSTEPS: p.rk4_substeps, _k.P_DT_I0: p.dead_time_i0,
                  _k.P_K_DQ: m.k_dq, _k.P_SUBSTEP_ANGLE: substep_angle_slot(p),
                  _k.P_GEAR_PF: 1.0 if v.gear_model == "power_flow" else 0.0, _k.P_J_M: m.J_m,
                  _k.P_M_R: v.m_v * v.r_w**2 / v.n_g**2,
                  _k.P_INV: 1.0 if p.inverter_losses else 0.0, **inverter_slot_values(p),
                  _k.P_INV_K: m.k_dq / 1.5, _k.P_FE_H: p.iron_c_h, _k.P_K_W: m.k_wind,
                  _k.P_FE_E: p.iron_c_e,
                  _k.P_SAT: 1.0 if (p.sat_i_d > 0 or p.sat_i_q > 0) else 0.0,
                  _k.P_SAT_AD: 1.0 / p.sat_i_d if p.sat_i_d > 0 else 0.0,
                  _k.P_SAT_AQ: 1.0 / p.sat_i_q if p.sat_i_q > 0 else 0.0,
                  # the dead time's per-phase voltage error: the volt-seconds v_dc t_d it takes per switching period
                  _k.P_DT_V: p.v_dc * p.dead_time / p.switching_period if p.dead_time else 0.0}
        #: the actuation delay [s]: inverter_delay switching periods
        self.delay = p.inverter_delay * p.switching_period
        #: the thermal model on: the losses heat the motor, R_s and psi follow (``kernels.thermal_network_step``)
        self._thermal = p.thermal
        if self._thermal:
            g, c = thermal_network(p)
            values.update({_k.P_TH: 1.0, _k.P_TH_RES: 1.0 if p.thermal_model == "lptn" else 0.0,
                           _k.P_TH_ROTOR: p.lptn_rotor_share, _k.P_TH_YOKE: p.lptn_yoke_share,
                           _k.P_TH_AMB: p.T_ambient, _k.P_TH_LIM_W: p.T_winding_max, _k.P_TH_LIM_M: p.T_magnet_max,
                           _k.P_R_S20: m.R_s, _k.P_ALPHA_R: p.alpha_R, _k.P_PSI20: m.psi, _k.P_ALPHA_PSI: p.alpha_psi})
            for j, value in enumerate(g):
                values[_k.P_TH_G + j] = value
            for j, value in enumerate(c):
                values[_k.P_TH_INV_C + j] = 1.0 / value if value > 0 else 0.0
        if p.flux_model == "algebraic":  # the algebraic magnetic model, its coefficients at the magnet's psi
            values[_k.P_FLUX] = 1.0
            for j, value in enumerate(flux_model_coefficients(m, p, self.psi)):
                values[_k.P_FLUX_C + j] = value
        if self.has_battery:
            values.update(battery_slot_values(self.battery, p))
        self._pp = accel.vector(_k.PLANT_PARAMS)
        for slot, value in values.items():
            self._pp[slot] = float(value)
        #: the energies since the start [J] (``pmsm_ev.kernels.PLANT_ENERGY_LAYOUT``, ``energies`` by name)
        self.energy = accel.vector(_k.PLANT_ENERGY)
        self._advance = accel.direct(self._kernels.plant_advance)
        #: the current sensors' noise: stream sensor_seed (its low 64 bits), sample k at the k-th measurement
        self._seed64 = int(p.sensor_seed) & _k.MASK64
        self._measured = accel.direct(self._kernels.measured_currents)
        self._sensor_args = tuple(float(x) for x in (p.sensor_gain_a, p.sensor_offset_a, p.sensor_gain_b,
                                                     p.sensor_offset_b, p.sensor_noise, self._lsb, p.adc_range))
        #: the state, the outputs and the constants of the step (``PLANT_IO_LAYOUT``); the plant FMU's inputs
        #: are written there by the FMU
        self.io = accel.vector(_k.PLANT_IO)
        #: ``io`` read and written from Python: a memoryview of the numpy vector, whose items are Python floats
        #: (the same doubles, without numpy's scalar per read), or the list
        self._io_items = self.io if isinstance(self.io, list) else memoryview(self.io)
        io = self._io_items
        io[_k.PIO_U_LIM] = self._u_lim
        io[_k.PIO_SENSORS] = 1.0 if self._sensors else 0.0
        io[_k.PIO_SEED] = float(self._seed64 >> 32)
        io[_k.PIO_SEED + 1] = float(self._seed64 & 0xFFFFFFFF)
        for i, value in enumerate(self._sensor_args):
            io[_k.PIO_SENSOR_ARGS + i] = value
        self.reset()

    def reset(self) -> None:
        p = self.params
        self.i_d = p.i_d0
        self.i_q = p.i_q0
        self.omega_m = p.omega_m0
        self.theta_e = wrap_angle(p.theta_e0)
        self.delta = 0.0
        self.x_vehicle = 0.0  # distance travelled since the start [m] (eqs 1, 6 integrated)
        self.samples = 0  # measurements taken so far (the noise counter)
        self.clock = 0.0  # time since the start [s]: the sum of the steps (the inverter delay's clock)
        self._pending = []  # voltages received, (time, v_alpha, v_beta), not yet superseded (inverter delay)
        self.v_alpha_applied = self.v_beta_applied = 0.0
        self.T_brake = 0.0  # the friction-brake torque of the last step [N m at the wheels], >= 0
        self._pp[_k.P_T_BRAKE] = 0.0
        for i in range(_k.PLANT_ENERGY):
            self.energy[i] = 0.0
        if self.has_battery:  # at rest at its initial state of charge
            self._kernels.battery_reset(self._pp, self.energy)
        # the thermal network's nodes at their start temperatures (the stator's at the winding's); constants without it
        for node, value in ((_k.TH_Y, p.T_winding), (_k.TH_T, p.T_winding), (_k.TH_W, p.T_winding),
                            (_k.TH_M, p.T_magnet)):
            self.energy[_k.E_TH_T + node] = value
        if self._thermal:  # R_s, psi at the start temperatures
            self._kernels.thermal_apply(self._pp, self.energy)
        self._update_outputs()
        #: the stored energies at the start (W_mag, E_kin) [J]
        self.stored0 = self.stored

    # -- state as named fields, for save/restore by wrappers ---------------------
    #: the fields of ``get_state`` (None: a number; 0: a list of any length)
    STATE_FIELDS = {"i_d": None, "i_q": None, "omega_m": None, "theta_e": None, "delta": None,
                    "samples": None, "clock": None, "pending": 0, "x_vehicle": None, "T_winding": None,
                    "energy": _k.PLANT_ENERGY, "stored0": 2}

    def get_state(self) -> dict:
        """The plant's state as {name: value} (JSON-serialisable): the dq state, the elevation, the
        sensor samples taken, the inverter's clock and pending voltages, the distance, the winding's
        temperature, the energies and the stored energies at the start."""
        return {"i_d": self.i_d, "i_q": self.i_q, "omega_m": self.omega_m, "theta_e": self.theta_e,
                "delta": self.delta, "samples": self.samples, "clock": self.clock,
                "pending": [list(entry) for entry in self._pending], "x_vehicle": self.x_vehicle,
                "T_winding": self.T_winding, "energy": [float(e) for e in self.energy],
                "stored0": list(self.stored0)}

    def set_state(self, state) -> None:
        """Restore a ``get_state`` dict; ``LayoutError`` if its fields are not these."""
        state = restore_fields("plant state", state, self.STATE_FIELDS)
        pending = [tuple(float(x) for x in entry) for entry in state["pending"]]
        if any(len(entry) != 3 for entry in pending):
            raise LayoutError("plant state: field 'pending' must hold (time, v_alpha, v_beta) triples")
        self.i_d, self.i_q, self.omega_m, self.theta_e, self.delta, self.x_vehicle = (
            float(state[name]) for name in ("i_d", "i_q", "omega_m", "theta_e", "delta", "x_vehicle"))
        self.clock = float(state["clock"])
        self._pending = pending
        for i, value in enumerate(state["energy"]):
            self.energy[i] = float(value)
        self.T_winding = float(state["T_winding"])
        self.stored0 = tuple(float(x) for x in state["stored0"])
        if self._thermal:  # R_s, psi at the restored temperatures
            self._kernels.thermal_apply(self._pp, self.energy)
        self.samples = int(state["samples"]) - 1  # _update_outputs takes the present sample again
        self._update_outputs()

    def derivatives(self, i_d, i_q, omega_m, theta_e, v_alpha, v_beta, delta):
        """d/dt of (i_d, i_q, omega_m, theta_e) for a stationary-frame voltage."""
        return _k.plant_derivatives(i_d, i_q, omega_m, theta_e, v_alpha, v_beta, delta, self._pp)

    # -- the magnetic model --------------------------------------------------------------
    def flux_linkages(self, i_d: float, i_q: float) -> tuple[float, float]:
        """(psi_d, psi_q) [Wb] at the currents (i_d, i_q) [A]: the algebraic model's (``flux_model``
        'algebraic', ``pmsm_ev.kernels.flux_linkages``), else psi + L_d i_d, L_q i_q (per axis
        saturated with ``sat_i_d``, ``sat_i_q``)."""
        pp = self._pp
        if pp[_k.P_FLUX] != 0.0:
            return self._kernels.flux_linkages(float(i_d), float(i_q), pp, _k.P_FLUX_C)
        f_d, _ = _k.saturated_flux(i_d, pp[_k.P_L_D], pp[_k.P_SAT_AD])
        f_q, _ = _k.saturated_flux(i_q, pp[_k.P_L_Q], pp[_k.P_SAT_AQ])
        return pp[_k.P_PSI] + f_d, f_q

    def incremental_inductances(self, i_d: float, i_q: float) -> tuple[float, float, float]:
        """The incremental inductance matrix (L_dd, L_dq, L_qq) [H] at (i_d, i_q) [A]: d psi / d i, what a
        high-frequency voltage sees (``pmsm_ev.kernels.incremental_inductances``; the linear models: the
        per-axis slopes, L_dq = 0)."""
        pp = self._pp
        if pp[_k.P_FLUX] != 0.0:
            return self._kernels.incremental_inductances(float(i_d), float(i_q), pp, _k.P_FLUX_C)
        _, l_d = _k.saturated_flux(i_d, pp[_k.P_L_D], pp[_k.P_SAT_AD])
        _, l_q = _k.saturated_flux(i_q, pp[_k.P_L_Q], pp[_k.P_SAT_AQ])
        return l_d, 0.0, l_q

    def step(self, v_alpha: float, v_beta: float, delta: float, dt: float, T_brake: float = 0.0) -> tuple:
        """Advance by dt with the voltage, the elevation and the friction-brake torque ``T_brake``
        [N m at the wheels] held (RK4, ``rk4_substeps``); a negative (or NaN) ``T_brake`` is taken
        as 0: a brake only opposes the motion.

        Returns (i_d, i_q, omega_m, theta_e, i_alpha, i_beta, T_e, T_L_mech, v_vehicle)
        after the step, also set as attributes (i_alpha, i_beta as measured). The step is the kernel
        ``plant_advance`` on ``io``, which the plant FMU's compiled step (``pmsm_ev.kernels.plant_fmu_step``)
        calls too (the thermal network included: ``plant_step`` heats the motor with the step's losses); what is here,
        the inverter's delay and limit, the compiled step does not take (it declines a voltage at or near the limit)."""
        if self.delay:
            v_alpha, v_beta = self._delayed(v_alpha, v_beta, dt)
        u_lim = self._u_lim
        if self.has_battery:  # the battery's terminal voltage of the step before
            u_lim = self._kernels.dc_link_limit(self._pp, self.energy, u_lim)
        if u_lim:  # linear range of the inverter: |v| <= v_dc / sqrt(3)
            mag = math.hypot(v_alpha, v_beta)
            if mag > u_lim:
                v_alpha *= u_lim / mag
                v_beta *= u_lim / mag
        self._advance(self.io, self._pp, self.energy, v_alpha, v_beta, delta, T_brake, dt, False)
        i_alpha, i_beta, i_d, i_q, omega_m, theta_e, T_e, T_L_mech, v_vehicle = self._io_items[_OUTPUTS]
        return i_d, i_q, omega_m, theta_e, i_alpha, i_beta, T_e, T_L_mech, v_vehicle

    # -- temperatures ----------------------------------------------------------------
    @property
    def T_winding(self) -> float:
        """The winding's temperature [degC] (the thermal network's node; ``PlantParams.T_winding`` without it)."""
        return float(self.energy[_k.E_TH_T + _k.TH_W])

    @T_winding.setter
    def T_winding(self, value: float) -> None:
        self.energy[_k.E_TH_T + _k.TH_W] = value

    @property
    def T_magnet(self) -> float:
        """The magnet's temperature [degC] (the thermal network's node; ``PlantParams.T_magnet`` without it)."""
        return float(self.energy[_k.E_TH_T + _k.TH_M])

    def thermal(self) -> dict[str, float]:
        """The thermal network's outputs by name (``THERMAL_SLOTS``), R_s [Ohm] and psi [Wb] now, and the heat it
        stores now over the start, sum C_i (T_i - T_i0) [J] (``stored_heat``)."""
        out = {name: float(self.energy[slot]) for name, slot in THERMAL_SLOTS.items()}
        out.update(R_s=float(self._pp[_k.P_R_S]), psi=float(self._pp[_k.P_PSI]), Q_stored=self.stored_heat())
        return out

    def stored_heat(self) -> float:
        """The heat the thermal network holds over its start [J]: sum over its nodes of C_i (T_i - T_i0)."""
        p = self.params
        _, c = thermal_network(p)
        start = (p.T_winding, p.T_winding, p.T_winding, p.T_magnet)
        return sum(ci * (float(self.energy[_k.E_TH_T + j]) - start[j]) for j, ci in enumerate(c))

    # -- energies ------------------------------------------------------------------
    @property
    def stored(self) -> tuple[float, float]:
        """(W_mag, E_kin) [J] of the present state (``pmsm_ev.kernels.stored_energies``)."""
        return self._kernels.stored_energies(self.i_d, self.i_q, self.omega_m, self._pp)

    @property
    def P_dc(self) -> float:
        """The mean DC-link power over the last step [W] (0 before the first)."""
        return float(self.energy[_k.E_P_DC])

    def energies(self) -> dict[str, float]:
        """The energies since the start [J], by name: ``ENERGY_NAMES`` from ``energy``, the stored
        energies ``E_kinetic``, ``W_magnetic`` now and their changes since the start
        (``dE_kinetic``, ``dW_magnetic``), and ``residual``: the balance E_dc - (losses + wheel
        work + brake + changes of the stored energies), each term integrated on its own."""
        out = {name: float(self.energy[slot]) for name, slot in ENERGY_SLOTS.items()}
        w_mag, e_kin = self.stored
        out.update(W_magnetic=w_mag, E_kinetic=e_kin, dW_magnetic=w_mag - self.stored0[0],
                   dE_kinetic=e_kin - self.stored0[1])
        out["residual"] = out["E_dc"] - sum(out[name] for name in BALANCE_TERMS)
        if self.has_battery:  # the battery's side: chemical = terminal (E_dc) + its losses + its capacitor's change
            out.update({name: float(self.energy[slot]) for name, slot in BATTERY_SLOTS.items()})
            out["residual_battery"] = out["E_chemical"] - (out["E_dc"] + out["E_battery"] + out["W_battery"])
        return out

    def _delayed(self, v_alpha: float, v_beta: float, dt: float) -> tuple[float, float]:
        """The voltage applied over the step from ``clock``: the last one received at least ``delay``
        before (to the nearest step; 0 V before any), given the one received now."""
        pending = self._pending
        pending.append((self.clock, v_alpha, v_beta))
        due = self.clock - self.delay + 0.5 * dt
        while len(pending) > 1 and pending[1][0] <= due:
            pending.pop(0)
        if pending[0][0] <= due:
            return pending[0][1], pending[0][2]
        return 0.0, 0.0

    def _update_outputs(self) -> None:
        """The outputs of the present state (after a reset or a restored state)."""
        (self.i_alpha, self.i_beta, self.T_e, self.T_L_mech,
         self.v_vehicle) = self._kernels.plant_outputs(self.i_d, self.i_q, self.omega_m, self.theta_e,
                                                       self.delta, self._pp)
        self.i_alpha_true, self.i_beta_true = self.i_alpha, self.i_beta
        if self._sensors:
            self.i_alpha, self.i_beta = self._measure(self.i_alpha, self.i_beta, self.samples)
        self.samples += 1

    def _measure(self, i_alpha: float, i_beta: float, sample: int) -> tuple[float, float]:
        """Phase currents a, b through the sensors and the ADC (noise of sample ``sample``),
        back to alpha-beta: the kernel ``measured_currents``."""
        return self._measured(i_alpha, i_beta, self._seed64, sample, *self._sensor_args)


def gaussian_pair(seed: int, n: int) -> tuple[float, float]:
    """Two independent standard normal numbers for sample n of stream ``seed`` (any integer: its
    low 64 bits), the kernel ``pmsm_ev.kernels.gaussian_pair`` (splitmix64 + Box-Muller)."""
    return _k.gaussian_pair(seed & _k.MASK64, n)
