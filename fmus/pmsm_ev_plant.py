"""Slave of PmsmEvPlant.fmu: the vehicle and PMSM, ``pmsm_ev.plant.Plant``, as an FMI 2.0
co-simulation unit. No equations here: ``do_step(t, h)`` is ``Plant.step(v_alpha, v_beta,
delta, h)``, then the plant's outputs are copied into the output variables. With the kernels compiled, the lean
binding runs the same step in compiled code instead (``pmsm_ev.kernels.plant_fmu_step`` on the buffers of
``compiled_step``; fmus/README.md, "The compiled step"): a change here is made there too.
"""

from __future__ import annotations

import math

from pmsm_ev import __version__
from pmsm_ev import kernels as _k
from pmsm_ev.params import BatteryParams, MotorParams, PlantParams, VehicleParams
from pmsm_ev.plant import BATTERY_SLOTS, ENERGY_SLOTS, THERMAL_SLOTS, Plant
from pmsm_ev_fmus.slave_support import (
    COMPILED_BUFFER,
    DriveSlave,
    FmuUsageError,
    SimulationError,
    compiled_offer,
)

_MOTOR = ("N", "psi", "L_d", "L_q")  # the motor parameters of eq 12
#: the algebraic flux model's parameters (``PlantParams.flux_model``): T_e and W_magnetic depend on them
_FLUX = ("flux_model", "flux_q_current", "flux_q_ratio", "flux_d_current", "flux_d_asymmetry", "flux_cross",
         "flux_S", "flux_T", "flux_U", "flux_V", "T_magnet", "alpha_psi")
_VEHICLE_LOAD = ("c_r", "g", "rho_a", "c_d", "A_f", "r_w", "eta", "n_g", "m_v", "v_a", "load_model", "v_eps")

DESCRIPTION = (
    "Vehicle and PMSM of a sensorless EV drive (Wicaksono, Harini, Yusivar, 'Sensorless PMSM "
    "Control using Fifth Order EKF in Electric Vehicle Application'): longitudinal vehicle, "
    "gear and road load (eqs 1-9, 28-29) driven by the dq model of the PMSM (eqs 10-13). "
    "fmi2DoStep(t, h) integrates over [t, t+h] with RK4 (rk4_substeps sub-steps) with the "
    "inputs v_alpha, v_beta (inverter voltage, stationary frame) and delta (road elevation) held; "
    "the outputs are the state at t+h, so no output depends directly on the inputs at the same "
    "communication point. Any step size, fixed or variable. Truth signals (i_d, i_q, omega_m, "
    "theta_e, T_e, T_L_mech, v_vehicle, x_vehicle) are outputs for recording and for a sensored controller; "
    "so are the energies since the start (J: DC link, losses by kind, the wheel's work by road force, the "
    "friction brake, the stored magnetic and kinetic energies) and the DC-link power. The input T_brake "
    "(friction brake at the wheels, N m, >= 0) is 0 when unconnected. "
    "A Python FMU (pythonfmu): it needs a Python 3 interpreter with numpy; the project code it "
    "runs is bundled in resources/. A state whose speed or currents are not finite fails the step."
)


#: the energy outputs read from the plant's energy vector: name -> description
_ENERGY_OUTPUTS = {
    "E_dc": "DC-link energy since the start: terminal power k_dq (v_d i_d + v_q i_q) at the winding's voltage "
            "(after the inverter's limit and dead time) plus the inverter's losses (negative: net regeneration)",
    "E_dc_abs": "the DC link's energy throughput since the start, the integral of |P_dc|",
    "E_regen": "energy returned to the DC link since the start, the integral of max(-P_dc, 0)",
    "E_copper": "copper losses since the start, k_dq R_s (i_d^2 + i_q^2)",
    "E_friction": "motor friction losses since the start, omega_m T_f (eq 8, and the windage k_wind "
                  "omega_m^2 |omega_m|)",
    "E_shaft": "electromagnetic work at the shaft since the start, omega_m T_e",
    "E_gear": "gear losses since the start (gear_model 'paper': (1/eta - 1) times the wheel forces' power, "
              "signed)",
    "E_aero": "work against the aerodynamic drag since the start, v f_a (eq 4)",
    "E_rolling": "work against the rolling resistance since the start, v f_f (eq 3)",
    "E_grade": "work against the gradient force since the start, v f_g (eq 2): the potential energy gained",
    "E_brake": "energy taken by the friction brake since the start",
    "E_inverter": "inverter conduction and switching losses since the start (inverter_losses)",
    "E_iron": "iron losses since the start (iron_c_h, iron_c_e), a drag on the shaft",
}

#: the battery's outputs (battery 'ecm'; 0 with the ideal link): name -> (unit, description, display unit)
_BATTERY_OUTPUTS = {
    "soc": (None, "the battery's state of charge: bat_soc0 less the charge drawn over bat_capacity", None),
    "v_bat": ("V", "the DC link's voltage, the battery's terminal voltage at the end of the last step (what the "
                  "inverter and a controller's v_dc_meas input see over the next)", None),
    "i_bat": ("A", "the battery's current over the last step, discharge positive", None),
    "P_charge_max": ("W", "the power the battery accepts now (charge acceptance: the charge current limit, tapered "
                          "above bat_soc_taper, within bat_v_max): a controller's P_charge_max input", "kW"),
    "P_discharge_max": ("W", "the power the battery gives now (the discharge current limit within bat_v_min): a "
                             "controller's P_discharge_max input", "kW"),
    "Q_bat": ("C", "the charge drawn from the battery since the start (negative: charged)", None),
    "E_chemical": ("J", "the battery's chemical energy since the start: the open-circuit voltage times its current, "
                        "integrated (E_dc + E_battery + W_battery)", "Wh"),
    "E_battery": ("J", "the battery's losses since the start: R0 i^2 and the RC pair's R1", "Wh"),
    "W_battery": ("J", "energy in the battery's RC pair's capacitor, C1 v_rc^2 / 2", "Wh"),
}

#: the thermal network's outputs (thermal_model 'lptn', or the one-node winding of thermal_R; without either the start
#: temperatures, constant): name -> (unit, description, display unit)
_THERMAL_OUTPUTS = {
    "T_yoke": ("degC", "the stator yoke's temperature (the thermal network's node)", None),
    "T_tooth": ("degC", "the stator tooth's temperature (the thermal network's node)", None),
    "T_wdg": ("degC", "the winding's temperature: R_s follows it (the parameter T_winding is its start)", None),
    "T_pm": ("degC", "the magnet's temperature: psi follows it (the parameter T_magnet is its start)", None),
    "Q_heat": ("J", "the heat the motor's losses put into the thermal network since the start (copper, and with "
                    "'lptn' iron and friction)", "Wh"),
    "Q_coolant": ("J", "the heat the thermal network gave to the coolant since the start", "Wh"),
    "over_temperature": (None, "over-temperature flags now: 1 the winding at or above T_winding_max, 2 the magnet "
                               "at or above T_magnet_max, 3 both; 0 none (a controller may derate on it)", None),
}

#: the slave's inputs and outputs in the compiled step's buffer, the plant's ``io``
#: (``pmsm_ev.kernels.PLANT_IO_LAYOUT``); the outputs are the plant's attributes of the same names there
_IO_SLOTS = {name: getattr(_k, "PIO_" + name.upper()) for name in (
    "v_alpha", "v_beta", "delta", "T_brake", "i_alpha", "i_beta", "i_d", "i_q", "omega_m", "theta_e", "T_e",
    "T_L_mech", "v_vehicle", "x_vehicle")}


class _Energy:
    """An output read from the plant when the master asks for it (no per-step copy): ``get`` of the
    plant; writes (the slave's declaration, a restored FMU state) are ignored, the plant has it."""

    def __init__(self, get):
        self.get = get

    def __get__(self, slave, owner=None):
        if slave is None:
            return self
        plant = slave.__dict__.get("_plant")
        return 0.0 if plant is None else self.get(plant)

    def __set__(self, slave, value):
        pass


def _energy_slot(slot):
    return _Energy(lambda plant: float(plant.energy[slot]))


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
        self.add_input("T_brake", "N.m", f"friction-brake torque at the wheels, >= 0 (a negative value is taken as "
                                         f"0), opposing the motion, {held}; 0 (unconnected): released")

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
        self.add_output("T_e", "N.m", "electromagnetic torque (eq 12; flux_model 'algebraic': its flux form)"
                        + at_start, start=None, start_dependencies=("i_d0", "i_q0") + _MOTOR + _FLUX)
        self.add_output("T_L_mech", "N.m",
                        "road load torque on the motor shaft (eq 29) at the elevation held over the "
                        "last step; before the first step: at the initial speed on a level road",
                        start=None, start_dependencies=("omega_m0",) + _VEHICLE_LOAD)
        self.add_output("v_vehicle", "m/s", "vehicle speed" + at_start,
                        start=None, start_dependencies=("omega_m0", "r_w", "n_g"), display_unit="km/h")
        self.add_output("x_vehicle", "m", "distance travelled since the start, forward positive "
                                          "(vehicle position; 0 before the first step)",
                        start=None, start_dependencies=())
        for name, text in _ENERGY_OUTPUTS.items():
            self.add_output(name, "J", text + " (0 before the first step)", start=None, start_dependencies=(),
                            display_unit="Wh")
        self.add_output("W_magnetic", "J", "magnetic field energy of the winding, k_dq (L_d i_d^2 + L_q i_q^2) / 2 "
                                           "(saturation: its Froehlich-Kennelly closed form; flux_model 'algebraic': "
                                           "the model's energy less the magnet's, zero at zero current)" + at_start,
                        start=None, start_dependencies=("i_d0", "i_q0", "L_d", "L_q", "sat_i_d", "sat_i_q",
                                                        "dq_convention", "psi") + _FLUX, display_unit="Wh")
        self.add_output("E_kinetic", "J", "kinetic energy: 1/2 J_eq omega_m^2 (gear_model 'paper', eq 9's inertia) or "
                                          "1/2 J_m omega_m^2 + 1/2 m_v v^2 ('power_flow')" + at_start,
                        start=None, start_dependencies=("omega_m0", "J_m", "m_v", "r_w", "n_g", "eta", "gear_model"),
                        display_unit="Wh")
        self.add_output("P_dc", "W", "mean DC-link power over the last step (0 before the first step)",
                        start=None, start_dependencies=(), display_unit="kW")
        for name, (unit, text, display) in _BATTERY_OUTPUTS.items():
            self.add_output(name, unit, text + " (battery 'ecm'; 0 with the ideal link; before the first step: at "
                                               "rest at bat_soc0)", start=None,
                            start_dependencies=("battery", "bat_soc0", "bat_ocv_soc", "bat_ocv_v"),
                            display_unit=display)

        for name, (unit, text, display) in _THERMAL_OUTPUTS.items():
            self.add_output(name, unit, text + " (before the first step: the start values)", start=None,
                            start_dependencies=("T_winding", "T_magnet"), display_unit=display)
        self.add_output("R_s_now", "Ohm", "the winding's resistance now, R_s (1 + alpha_R (T_wdg - 20 degC))"
                        + at_start,
                        start=None, start_dependencies=("R_s", "T_winding", "alpha_R"))
        self.add_output("psi_now", "Wb", "the magnet's flux linkage now, psi (1 + alpha_psi (T_pm - 20 degC))"
                        + at_start,
                        start=None, start_dependencies=("psi", "T_magnet", "alpha_psi"))

        self.add_parameters(MotorParams, VehicleParams, PlantParams, BatteryParams)
        self._plant = None

    # -- physics hooks ---------------------------------------------------------------
    def build(self) -> None:
        self._plant = Plant(self.parameters(MotorParams), self.parameters(VehicleParams),
                            self.parameters(PlantParams), self.parameters(BatteryParams))  # validates the groups
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

    def max_step(self) -> tuple[float, str]:
        """The longest communication step integrated to the plant's stated accuracy: each of its ``rk4_substeps``
        RK4 sub-steps may cover at most ``substep_angle`` (0.1, or 2 where that bound is off: RK4's stability) of
        the stator's time constant min(L_d, L_q) / R_s, as it may turn at most that electrical angle
        (``PlantParams.substep_angle``); 2.3 ms with the defaults. A longer step is discarded, not integrated
        into a state of 1e20."""
        motor, plant = self.parameters(MotorParams), self.parameters(PlantParams)
        share = plant.substep_angle if plant.substep_angle > 0 else 2.0
        tau = min(motor.L_d, motor.L_q) / motor.R_s
        limit = plant.rk4_substeps * share * tau
        return limit, (f"longer than the plant integrates to its accuracy ({limit!r} s: rk4_substeps = "
                       f"{plant.rk4_substeps} RK4 sub-steps of at most {share!r} of the stator's time constant "
                       f"{tau!r} s); take shorter steps or raise rk4_substeps")

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

    # -- the compiled step (``pmsm_ev.kernels.fmu``: ``plant_fmu_step`` on these buffers) ------------------------
    def compiled_slots(self) -> dict[str, int]:
        slots = dict(_IO_SLOTS)
        slots.update({name: 2 * COMPILED_BUFFER + slot for name, slot in ENERGY_SLOTS.items()})
        slots.update({name: 2 * COMPILED_BUFFER + slot for name, slot in BATTERY_SLOTS.items()})
        slots["P_dc"] = 2 * COMPILED_BUFFER + _k.E_P_DC
        slots.update({name: 2 * COMPILED_BUFFER + slot for name, slot in THERMAL_SLOTS.items()})
        slots["R_s_now"] = COMPILED_BUFFER + _k.P_R_S
        slots["psi_now"] = COMPILED_BUFFER + _k.P_PSI
        return slots

    def compiled_live(self) -> tuple[str, ...]:
        # the stored energies of the plant's state: ``Plant.stored`` reads its buffer ``io`` and vector ``pp``
        return ("W_magnetic", "E_kinetic")

    def compiled_step(self):
        """(the plant's C step, the plant's buffer ``Plant.io`` with the slave's inputs and outputs written into it,
        the plant's parameter and energy vectors: ``compiled_offer``); None where the kernels run as plain Python or
        the plant has an inverter delay (its state is Python's)."""
        p = self._plant
        if p is None or not getattr(p._kernels, "JIT", False) or p.delay:
            return None
        step = self.__dict__.get("_step_address")
        if step is None:
            step = self._step_address = p._kernels.fmu_step_address("plant")
        io = p.io
        for name, slot in _IO_SLOTS.items():
            io[slot] = getattr(self, name)
        return compiled_offer(step, io, p._pp, p.energy)

    def compiled_pull(self) -> None:
        values = self._plant.io.tolist()
        for name, slot in _IO_SLOTS.items():
            setattr(self, name, values[slot])

    # -- FMI -------------------------------------------------------------------------
    def do_step(self, current_time, step_size):
        try:
            if not self._initialized:
                raise FmuUsageError("fmi2DoStep before fmi2ExitInitializationMode")
            if not step_size > 0.0:
                raise FmuUsageError(f"communication step size must be > 0 s (got {step_size!r})")
            (self.i_d, self.i_q, self.omega_m, self.theta_e, self.i_alpha, self.i_beta, self.T_e,
             self.T_L_mech, self.v_vehicle) = self._plant.step(self.v_alpha, self.v_beta, self.delta, step_size,
                                                               self.T_brake)
            self.x_vehicle = self._plant.x_vehicle
            if not math.isfinite(self.omega_m + self.i_d + self.i_q):
                raise SimulationError(f"plant state is not finite at t = {current_time + step_size!r} s "
                                      f"(omega_m={self.omega_m!r}, i_d={self.i_d!r}, i_q={self.i_q!r})")
            if not math.isfinite(self._plant.energy[_k.E_BAT_V]):
                raise SimulationError(f"the battery cannot give the DC power the drive draws at t = "
                                      f"{current_time + step_size!r} s ({self._plant.P_dc!r} W, more than "
                                      f"OCV^2 / (4 R))")
        except Exception as exc:
            self._fail("fmi2DoStep", exc)
            raise
        return True


for _name, _slot in ENERGY_SLOTS.items():
    setattr(PmsmEvPlant, _name, _energy_slot(_slot))
PmsmEvPlant.W_magnetic = _Energy(lambda plant: plant.stored[0])
PmsmEvPlant.E_kinetic = _Energy(lambda plant: plant.stored[1])
PmsmEvPlant.P_dc = _Energy(lambda plant: plant.P_dc)
for _name, _slot in BATTERY_SLOTS.items():
    setattr(PmsmEvPlant, _name, _energy_slot(_slot))
for _name, _slot in THERMAL_SLOTS.items():
    setattr(PmsmEvPlant, _name, _energy_slot(_slot))
PmsmEvPlant.R_s_now = _Energy(lambda plant: float(plant._pp[_k.P_R_S]))
PmsmEvPlant.psi_now = _Energy(lambda plant: float(plant._pp[_k.P_PSI]))
