"""The slots of the kernels' flat vectors, each declared once: name, length, meaning.

A ``Layout`` assigns the offsets from an ordered table of ``Slot(name, length, doc)`` rows
(contiguous, in table order, so no two slots overlap) and checks the table when this module is
imported: names unique and upper case with the vector's prefix, lengths whole numbers >= 1, the
total the declared size. Each slot's offset is then a module-level int named after it (``S_X``,
``C_Q``, ``P_R_S``, ...): numba reads such globals as compile-time constants, so the kernels
index the vectors as fast as with literal numbers.

**Named entries.** A slot longer than 1 whose entries mean different things names them where it is
declared (``Slot(..., parts=(...))``): each part a name (one entry) or a (name, length) pair, in the
slot's order, covering it. Each part's offset is exported as a module-level int too (``S_OMEGA_HAT`` is
``S_X + 2``, ``S_ID_N_D`` is ``S_ID_SUM + 4``), so a kernel reads ``s[S_OMEGA_HAT]``, not ``s[S_X + 2]``,
and numba compiles both to the same constant index: the mechanism is named offsets, module-level int
globals, not a record view or generated accessors. A slot whose entries are a vector or a matrix of
one meaning (``S_P``, ``S_AVG``) keeps its arithmetic (``S_P + n * i + j``); a part indexed by a loop
(``S_ID_N_D + j``: the count of the identification's phase j) reads as the first of its run.

**Reset by declaration.** Each slot of a state vector declares its value at a reset (``reset``, 0.0
unless said) and whether it is part of a saved state (``saved``; False: scratch, written before it is
read in every step). ``Layout.reset`` writes every slot's declared value; a slot whose start depends on
the parameters (the observer's x0 and P0, the adaptation's estimates) is then set by its owner's reset,
which its doc names.

Four vectors of the physics:

* ``PLANT_PARAMS_LAYOUT`` (``P_*``): the plant's parameters (``pmsm_ev.plant.Plant``);
* ``PLANT_ENERGY_LAYOUT`` (``E_*``): the plant's energy accumulators (``pmsm_ev.plant.Plant.energy``);
* ``UNIT_STATE_LAYOUT`` (``S_*``): the control unit's state, shared by its controllers and its
  observer (``pmsm_ev.control_unit.ControlUnit``); the slots marked ``saved=False`` are scratch
  space, written before they are read in every step, and are not part of a saved state;
* ``UNIT_PARAMS_LAYOUT`` (``C_*``): the control unit's parameters.

and the buffers of the FMUs' compiled step (``pmsm_ev.kernels.fmu``), which the lean binding reads and writes:

* ``PLANT_IO_LAYOUT`` (``PIO_*``): the plant FMU's inputs, outputs and the state ``Plant`` keeps outside its
  vectors;
* ``UNIT_IO_LAYOUT`` (``UIO_*``): a controller FMU's inputs, outputs and sample clock.
"""

from __future__ import annotations

from typing import NamedTuple


class LayoutError(ValueError):
    """A layout table that does not describe a vector (a duplicate or malformed name, a bad
    length, a size that is not the declared one)."""


class Slot(NamedTuple):
    name: str  #: the constant's name: the vector's prefix and an upper-case identifier
    length: int  #: how many consecutive floats
    doc: str  #: what it holds, with its unit
    saved: bool = True  #: part of a saved state (state vectors only; False: scratch)
    reset: float = 0.0  #: every entry's value at a reset (state vectors: ``Layout.reset``)
    parts: tuple = ()  #: the names of its entries, in order: a name (one entry) or (name, length)


class Layout:
    """Offsets of the slots of one flat float vector (see the module doc)."""

    def __init__(self, what: str, prefix: str, slots, size: int):
        self.what = what
        self.prefix = prefix
        self.slots: tuple[Slot, ...] = tuple(row if isinstance(row, Slot) else Slot(*row) for row in slots)
        self.offsets: dict[str, int] = {}
        #: the named entries of the slots (``Slot.parts``): name -> offset
        self.parts: dict[str, int] = {}
        offset = 0
        for slot in self.slots:
            name, length = slot.name, slot.length
            self._check_name(name)
            if isinstance(length, bool) or not isinstance(length, int) or length < 1:
                raise LayoutError(f"{what}: slot {name} has length {length!r}; it must be a whole number >= 1")
            self.offsets[name] = offset
            if slot.parts:
                at = offset
                for part in slot.parts:
                    part_name, part_length = (part, 1) if isinstance(part, str) else part
                    self._check_name(part_name)
                    self.parts[part_name] = at
                    at += part_length
                if at != offset + length:
                    raise LayoutError(f"{what}: the parts of slot {name} take {at - offset} floats, the slot {length}")
            offset += length
        if offset != size:
            raise LayoutError(f"{what}: the slots take {offset} floats, the vector is declared with {size}")
        self.size = size

    def _check_name(self, name) -> None:
        """A slot's or a part's name: an upper-case identifier with the prefix, not declared before."""
        if not (isinstance(name, str) and name.startswith(self.prefix) and name.isidentifier()
                and name == name.upper()):
            raise LayoutError(f"{self.what}: slot name {name!r} is not an upper-case identifier starting "
                              f"with {self.prefix!r}")
        if name in self.offsets or name in self.parts:
            raise LayoutError(f"{self.what}: slot {name} declared twice")

    def __len__(self) -> int:
        return self.size

    def span(self, name: str) -> range:
        """The indices of slot ``name``."""
        slot = self._slot(name)
        return range(self.offsets[name], self.offsets[name] + slot.length)

    def _slot(self, name: str) -> Slot:
        for slot in self.slots:
            if slot.name == name:
                return slot
        raise KeyError(f"{self.what} has no slot {name!r}")

    def export(self, namespace: dict) -> None:
        """Put each slot's offset and each named entry's into ``namespace`` under its name (a module's globals)."""
        for name, offset in (self.offsets | self.parts).items():
            if name in namespace:
                raise LayoutError(f"{self.what}: {name} is defined already in {namespace.get('__name__')}")
            namespace[name] = offset

    def reset(self, vector) -> None:
        """Every slot of ``vector`` at its declared reset value (``Slot.reset``)."""
        for slot in self.slots:
            for i in self.span(slot.name):
                vector[i] = slot.reset

    # -- saved states -------------------------------------------------------------------------
    def field(self, name: str) -> str:
        """The name of a slot in a saved state: without the prefix, lower case (``S_I_MAG`` -> ``i_mag``)."""
        return name[len(self.prefix):].lower()

    def save(self, vector) -> dict[str, list[float]]:
        """The saved slots of ``vector`` as {field: [floats]} (JSON-serialisable)."""
        return {self.field(s.name): [float(vector[i]) for i in self.span(s.name)] for s in self.slots if s.saved}

    def restore(self, vector, state) -> None:
        """Set the saved slots of ``vector`` from ``save``'s dict; the fields and their lengths must be
        this layout's (``LayoutError`` names the first that is not)."""
        if not isinstance(state, dict):
            raise LayoutError(f"{self.what}: a saved state is a dict of named fields (got {type(state).__name__})")
        expected = {self.field(s.name): s for s in self.slots if s.saved}
        for name in state:
            if name not in expected:
                raise LayoutError(f"{self.what}: the saved state has a field {name!r} that this version does not "
                                  f"know (expected {', '.join(expected)})")
        for name, slot in expected.items():
            if name not in state:
                raise LayoutError(f"{self.what}: the saved state has no field {name!r}")
            if len(state[name]) != slot.length:
                raise LayoutError(f"{self.what}: field {name!r} of the saved state has {len(state[name])} values, "
                                  f"expected {slot.length}")
        for name, slot in expected.items():
            for i, value in zip(self.span(slot.name), state[name]):
                vector[i] = float(value)


def restore_fields(what: str, state, lengths: dict[str, int | None]) -> dict:
    """Check a saved state of named fields against the expected ``lengths`` (None: a number, else a
    list of that many numbers, 0: a list of any length) and return it; ``LayoutError`` names the
    first field that differs."""
    if not isinstance(state, dict):
        raise LayoutError(f"{what}: a saved state is a dict of named fields (got {type(state).__name__})")
    if set(state) != set(lengths):
        missing, extra = sorted(set(lengths) - set(state)), sorted(set(state) - set(lengths))
        raise LayoutError(f"{what}: the saved state's fields differ: missing {missing}, unknown {extra}")
    for name, length in lengths.items():
        value = state[name]
        if length is None:
            if isinstance(value, (list, tuple, dict)):
                raise LayoutError(f"{what}: field {name!r} of the saved state must be a number")
        elif not isinstance(value, (list, tuple)) or (length and len(value) != length):
            raise LayoutError(f"{what}: field {name!r} of the saved state must be a list of {length or 'any number'} "
                              f"values")
    return state


#: the plant's parameter vector (``pmsm_ev.plant.Plant`` fills it)
PLANT_PARAMS_LAYOUT = Layout("plant parameter vector", "P_", (
    ("P_R_S", 1, "stator resistance [Ohm] (at the winding's temperature)"),
    ("P_L_D", 1, "d inductance [H]"),
    ("P_L_Q", 1, "q inductance [H]"),
    ("P_PSI", 1, "magnet flux [Wb] (at the magnet's temperature)"),
    ("P_N", 1, "pole pairs [-]"),
    ("P_B_M", 1, "viscous friction [N m s/rad]"),
    ("P_T_M0", 1, "static friction [N m]"),
    ("P_OMEGA_EPS", 1, "speed scale of the static friction's soft sign [rad/s]"),
    ("P_J_EQ", 1, "equivalent inertia (eq 9) [kg m^2]"),
    ("P_M_V", 1, "vehicle mass [kg]"),
    ("P_G", 1, "gravity [m/s^2]"),
    ("P_C_R", 1, "rolling resistance coefficient [-]"),
    ("P_RHO_A", 1, "air density [kg/m^3]"),
    ("P_C_D", 1, "drag coefficient [-]"),
    ("P_A_F", 1, "frontal area [m^2]"),
    ("P_R_W", 1, "wheel radius [m]"),
    ("P_ETA", 1, "gear efficiency [-]"),
    ("P_N_G", 1, "gear ratio [-]"),
    ("P_V_A", 1, "head wind [m/s]"),
    ("P_V_EPS", 1, "speed scale of the rolling resistance's soft sign [m/s]"),
    ("P_PAPER", 1, "1.0: the paper's load model (eqs 3, 4, 8 as printed)"),
    ("P_SUBSTEPS", 1, "RK4 sub-steps per step [-]"),
    ("P_DT_V", 1, "inverter dead time: per-phase voltage error v_dc t_d / T_s [V] (0 = off; "
                  "``PlantParams.dead_time``, ``switching_period``)"),
    ("P_DT_I0", 1, "current scale of the dead time's soft sign [A] (``PlantParams.dead_time_i0``)"),
    ("P_SAT", 1, "magnetic saturation: 1.0 = on (``saturated_flux``)"),
    ("P_SAT_AD", 1, "1/I_sat of the d axis [1/A]"),
    ("P_SAT_AQ", 1, "1/I_sat of the q axis [1/A]"),
    ("P_K_DQ", 1, "the dq convention's factor of eq 12's torque and of the power [-] (``MotorParams.k_dq``)"),
    ("P_SUBSTEP_ANGLE", 1, "the largest electrical angle of one RK4 sub-step [rad] (0 = off; "
                           "``PlantParams.substep_angle``)"),
    # the friction brake, the gear model and the inverter's losses (``pmsm_ev.kernels.plant_rates``)
    ("P_T_BRAKE", 1, "friction-brake torque at the wheels [N m], >= 0 (the plant's input ``T_brake``, set "
                     "before each step; 0 = released)"),
    ("P_GEAR_PF", 1, "1.0: the gear model 'power_flow' (eta in the direction the power flows); 0.0: 'paper' "
                     "(eq 9: the reflected mass and every wheel force divided by eta)"),
    ("P_J_M", 1, "rotor inertia [kg m^2] (the power_flow gear)"),
    ("P_M_R", 1, "vehicle mass reflected to the shaft without eta, m_v r_w^2 / n_g^2 [kg m^2]"),
    ("P_INV", 1, "1.0: the inverter's conduction and switching losses on (``PlantParams.inverter_losses``)"),
    ("P_INV_V", 1, "inverter: per-phase loss voltage, threshold + switching equivalent [V] "
                   "(``pmsm_ev.kernels.inverter_loss``)"),
    ("P_INV_R", 1, "inverter: per-phase on-state resistance [Ohm]"),
    ("P_INV_K", 1, "inverter: the factor from the phase losses to the model's power, k_dq / (3/2) [-]"),
    ("P_FE_H", 1, "iron losses, hysteresis: c_h [W / (rad/s Wb^2)] (0 = off; ``PlantParams.iron_c_h``)"),
    ("P_FE_E", 1, "iron losses, eddy currents: c_e [W / ((rad/s)^2 Wb^2)] (0 = off; ``PlantParams.iron_c_e``)"),
    # the algebraic magnetic model (``PlantParams.flux_model`` 'algebraic', ``pmsm_ev.kernels.flux_currents``)
    ("P_FLUX", 1, "1.0: the algebraic magnetic model (flux linkages with self- and cross-saturation; the RK4 "
                  "integrates psi_d, psi_q); 0.0: eqs 10-12 (or the per-axis saturation, P_SAT)"),
    ("P_FLUX_C", 12, "its coefficients in the order FX_AD0 .. FX_W0 (``pmsm_ev.kernels.plant``; "
                     "``pmsm_ev.params.flux_model_coefficients``)"),
    # the windage and the inverter's modulation-dependent conduction (``plant_rates``, ``inverter_loss``)
    ("P_K_W", 1, "windage: k_w of the drag k_w omega_m |omega_m| [N m s^2/rad^2] (0 = off; ``MotorParams.k_wind``)"),
    ("P_INV_DV", 1, "inverter: V_CE0 - V_F0, the IGBT's knee less the diode's [V] (``PlantParams.inv_v0``, "
                    "``inv_vf0``)"),
    ("P_INV_DR", 1, "inverter: r_CE - r_F, the IGBT's slope less the diode's [Ohm] (``inv_r_on``, ``inv_r_f``)"),
    ("P_INV_VDC", 1, "inverter: 1 / v_dc [1/V] (a phase's duty from its pole voltage; 0 = no DC link)"),
    # the battery (``PlantParams.battery`` 'ecm', ``pmsm_ev.kernels.battery_step``): the DC link's voltage from an
    # equivalent circuit; the inverter's slots above that depend on v_dc follow it each step (``battery_link``)
    ("P_BAT", 1, "1.0: the DC link is the battery's equivalent circuit; 0.0: an ideal source of v_dc (or none)"),
    ("P_BAT_Q", 1, "battery: capacity [C] (``BatteryParams.bat_capacity`` x 3600)"),
    ("P_BAT_SOC0", 1, "battery: state of charge at the start [-]"),
    ("P_BAT_R0", 1, "battery: series (ohmic) resistance R0 [Ohm]"),
    ("P_BAT_R1", 1, "battery: the RC pair's resistance R1 [Ohm] (0 = no RC pair)"),
    ("P_BAT_TAU", 1, "battery: the RC pair's time constant R1 C1 [s]"),
    ("P_BAT_C1", 1, "battery: the RC pair's capacitance C1 [F]"),
    ("P_BAT_I_CHG", 1, "battery: the charge current limit [A]"),
    ("P_BAT_I_DIS", 1, "battery: the discharge current limit [A]"),
    ("P_BAT_V_MAX", 1, "battery: the terminal voltage the charge current may raise it to [V]"),
    ("P_BAT_V_MIN", 1, "battery: the terminal voltage the discharge current may lower it to [V]"),
    ("P_BAT_SOC_TAPER", 1, "battery: the state of charge above which the charge current limit falls linearly to 0 "
                           "at 1 [-]"),
    ("P_BAT_N", 1, "battery: the points of the open-circuit voltage table [-] (2 .. BAT_OCV_MAX)"),
    ("P_BAT_OCV", 2 * 24, "battery: the table's states of charge [-] (BAT_OCV_MAX slots from P_BAT_OCV), then its "
                          "open-circuit voltages [V] (BAT_OCV_MAX slots from P_BAT_OCV + BAT_OCV_MAX)"),
    ("P_INV_V0", 1, "inverter: the mean knee (inv_v0 + inv_vf0) / 2 [V] (P_INV_V at the battery's voltage)"),
    ("P_INV_KSW", 1, "inverter: the switching losses' loss voltage per volt of the DC link [-] (P_INV_V at the "
                     "battery's voltage)"),
    ("P_DT_K", 1, "inverter dead time: t_d / T_s [-] (P_DT_V at the battery's voltage)"),
    # the motor's thermal network (``PlantParams.thermal_model`` 'lptn', or the one-node winding of ``thermal_R``;
    # ``pmsm_ev.kernels.thermal_network_step``): nodes stator yoke, stator tooth, winding, magnet (TH_Y .. TH_M)
    ("P_TH", 1, "1.0: the thermal network on (the winding's R_s and the magnet's psi follow its temperatures)"),
    ("P_TH_G", 8, "its thermal conductances [W/K] in the order TH_G_YC .. TH_G_WC (0: no such path)"),
    ("P_TH_INV_C", 4, "the inverse heat capacities of its nodes [1/(J/K)] in the order TH_Y .. TH_M (0: a node "
                      "that holds its temperature)"),
    ("P_TH_RES", 1, "the share of the residual losses (iron and friction) that heats the network [-] (1: all, "
                    "'lptn'; 0: the copper losses only, the one-node winding)"),
    ("P_TH_ROTOR", 1, "the residual losses' share that heats the magnet's node (the rotor's) [-]"),
    ("P_TH_YOKE", 1, "the stator's share of the residual losses that heats the yoke's node, the rest the tooth's [-]"),
    ("P_TH_AMB", 1, "the coolant's temperature [degC] (``PlantParams.T_ambient``)"),
    ("P_TH_LIM_W", 1, "the winding's insulation limit [degC] (``PlantParams.T_winding_max``)"),
    ("P_TH_LIM_M", 1, "the magnet's maximum temperature [degC] (``PlantParams.T_magnet_max``)"),
    ("P_R_S20", 1, "stator resistance at 20 degC [Ohm] (Table I's R_s)"),
    ("P_ALPHA_R", 1, "the copper's temperature coefficient [1/K]"),
    ("P_PSI20", 1, "magnet flux at 20 degC [Wb] (Table I's psi)"),
    ("P_ALPHA_PSI", 1, "the magnet's temperature coefficient of psi [1/K]"),
    # not a parameter: a memo the algebraic model's kernels keep (``plant_flux_linkages``), 0 in a new vector
    ("P_FLUX_MEMO", 5, "the last psi(i) solved: 1.0 when valid (0 = empty; clear it where P_FLUX_C changes), "
                       "i_d, i_q [A], psi_d, psi_q [Wb]"),
), size=56 + 64 + 23 + 5)

#: the plant's energy accumulators (``pmsm_ev.plant.Plant.energy``; ``plant_step`` adds each step's
#: RK4-integrated energies): joules since the start, in the dq convention's power scaling (``P_K_DQ``)
PLANT_ENERGY_LAYOUT = Layout("plant energy vector", "E_", (
    ("E_DC", 1, "DC-link energy: terminal power k_dq (v_d i_d + v_q i_q) at the winding's voltage, plus the "
                "inverter's losses [J] (negative while regenerating)"),
    ("E_DC_ABS", 1, "the DC link's energy throughput, the integral of |P_dc| [J]"),
    ("E_REGEN", 1, "energy returned to the DC link, the integral of max(-P_dc, 0) [J]"),
    ("E_COPPER", 1, "copper losses k_dq R_s (i_d^2 + i_q^2) [J]"),
    ("E_FRICTION", 1, "motor friction omega_m T_f (eq 8, and the windage k_w omega_m |omega_m|) [J]"),
    ("E_SHAFT", 1, "electromagnetic work at the shaft omega_m T_e [J]"),
    ("E_GEAR", 1, "gear losses [J] (the paper's gear: (1/eta - 1) times the wheel forces' power, signed)"),
    ("E_AERO", 1, "work against the aerodynamic drag v f_a (eq 4) [J]"),
    ("E_ROLL", 1, "work against the rolling resistance v f_f (eq 3) [J]"),
    ("E_GRADE", 1, "work against the gradient force v f_g (eq 2): the potential energy gained [J]"),
    ("E_BRAKE", 1, "friction-brake energy [J]"),
    ("E_INVERTER", 1, "inverter conduction and switching losses [J]"),
    ("E_P_DC", 1, "mean DC-link power over the last step [W]"),
    ("E_IRON", 1, "iron losses, the drag omega_m T_fe on the shaft [J]"),
    # the battery (``P_BAT``; ``battery_step``): its state and its energies, 0 with the ideal link
    ("E_BAT_SOC", 1, "battery: state of charge [-] (the start's less the charge drawn over the capacity)"),
    ("E_BAT_VRC", 1, "battery: the RC pair's voltage [V]"),
    ("E_BAT_V", 1, "battery: terminal voltage, the DC link's, at the end of the last step [V]"),
    ("E_BAT_I", 1, "battery: current over the last step, discharge positive [A]"),
    ("E_BAT_Q", 1, "battery: charge drawn since the start [C] (negative: charged)"),
    ("E_BAT_CHEM", 1, "battery: chemical energy, the open-circuit voltage times the current integrated [J]"),
    ("E_BAT_LOSS", 1, "battery: losses, R0 i^2 and the RC pair's R1 [J]"),
    ("E_BAT_W", 1, "battery: energy stored in the RC pair's capacitor, C1 v_rc^2 / 2 [J]"),
    ("E_BAT_P_CHG", 1, "battery: the charge power it accepts now (charge acceptance) [W]"),
    ("E_BAT_P_DIS", 1, "battery: the discharge power it gives now [W]"),
    # the thermal network (``P_TH``; ``thermal_network_step``): its temperatures (the start values with it off) and
    # its energies
    ("E_TH_T", 4, "thermal network: the temperatures of its nodes [degC] in the order TH_Y .. TH_M (stator yoke, "
                  "stator tooth, winding, magnet)"),
    ("E_TH_IN", 1, "thermal network: the heat the losses put in since the start [J]"),
    ("E_TH_OUT", 1, "thermal network: the heat given to the coolant since the start [J]"),
    ("E_TH_OVER", 1, "thermal network: over-temperature flags, TH_OVER_WINDING (1) + TH_OVER_MAGNET (2) of the nodes "
                     "at or above their limits now (0: none)"),
), size=24 + 7)

#: the control unit's state vector (controller + observer)
UNIT_STATE_LAYOUT = Layout("control unit state vector", "S_", (
    ("S_V_D", 1, "the last command, d [V]"),
    ("S_V_Q", 1, "the last command, q [V]"),
    ("S_U_PREV_0", 1, "the observer's voltage input of one period earlier (the one-period actuation delay), first "
                      "axis in the observer's own frame [V]: d (S_U_PREV_D) for the rotating-frame observers (ekf5, "
                      "ekf4), alpha (S_U_PREV_ALPHA) for the stationary-frame EKF5 (ekf5ab and the sensorless unit)"),
    ("S_U_PREV_1", 1, "... second axis: q (S_U_PREV_Q) or beta (S_U_PREV_BETA) [V]"),
    ("S_V_ALPHA", 1, "the voltage held, alpha [V]"),
    ("S_V_BETA", 1, "the voltage held, beta [V]"),
    ("S_I_D", 1, "the d current in the control frame [A]"),
    ("S_I_Q", 1, "the q current in the control frame [A]"),
    ("S_I_QREF", 1, "the q-current reference [A]"),
    ("S_W_INT", 1, "speed PI integral [A]"),
    ("S_INT_D", 1, "d current PI integral [V]"),
    ("S_INT_Q", 1, "q current PI integral [V]"),
    ("S_I_DL", 1, "decoupling filter of i_dref (eq 17) [A]"),
    ("S_I_QL", 1, "decoupling filter of i_qref (eq 18) [A]"),
    ("S_SAT", 1, "1.0 while the voltage vector is limited"),
    Slot("S_X", 5, "the observer's estimates i_d [A], i_q [A], omega_m [rad/s], theta_e [rad], T_L [N m] (EKF4: "
                   "T_L stays 0); the injection strategy feeds the EKF's last three from the tracking observer "
                   "while the blend's weight is 0 (``kernels.modes.feed_ekf``: the EKF carries the injection's "
                   "estimate, from which it takes over as the weight rises)",
         parts=("S_I_D_HAT", "S_I_Q_HAT", "S_OMEGA_HAT", "S_THETA_HAT", "S_TL_HAT")),
    ("S_THETA_PRIOR", 1, "the observer's predicted angle [rad]"),
    ("S_P", 25, "EKF covariance, n x n row by row (n = 4 or 5)"),
    ("S_PHT", 10, "scratch: P H^T, n x 2", False),
    ("S_K", 10, "scratch: Kalman gain, n x 2", False),
    ("S_A", 25, "scratch: J_f P, n x n (J_f itself when P = I)", False),
    ("S_STARTED", 1, "stationary-frame EKF5: 1.0 once past its first sample (x0 is the estimate there)"),
    # sensorless start-up (``sensorless_step``)
    ("S_MODE", 1, "the sensorless unit's mode (MODE_*)"),
    ("S_ALIGN_CLOCK", 1, "the alignment's clock: control periods since the alignment last began (0 at a reset, a "
                         "realignment and the injection unit's fall-back to the I-f strategy; read in MODE_ALIGN) [-]"),
    ("S_PHI", 1, "the current vector of alignment and I-f: angle in the stationary frame [rad]"),
    ("S_I_MAG", 1, "... its magnitude [A]"),
    ("S_I_TGT", 1, "... its target magnitude [A]"),
    ("S_OMEGA_IF", 1, "the I-f speed [rad/s]"),
    ("S_AGREE", 1, "how long omega_hat has agreed with the I-f speed [s]"),
    ("S_SLIP", 1, "I-f: omega_hat - omega_if, low-pass filtered (the damping's input and the slip detector's) [rad/s]"),
    ("S_V_OUT_ALPHA", 1, "with dead-time compensation: the vector sent to the inverter, alpha [V]"),
    ("S_V_OUT_BETA", 1, "... beta [V]"),
    Slot("S_PSI_RATIO", 1, "with psi adaptation: the EKF's magnet flux over the nominal psi [-]", reset=1.0),
    # adaptation while driving (``C_ADAPT``; ``pmsm_ev.kernels.adaptation``): the model-reference estimates of psi
    # and R_s, their least-squares sums and the last period's frame, currents and held vector
    ("S_AD_PSI", 1, "the estimated magnet flux psi_hat [Wb] (eq AD3)"),
    ("S_AD_RS", 1, "the estimated stator resistance R_s_hat [Ohm] (eq AD4)"),
    Slot("S_AD_SUM", 4, "the exponentially weighted sums of the two least-squares fits: omega_e^2, omega_e y_psi "
                        "[V^2, V^2/Wb ...], |i|^4, |i|^2 y_R (AD3, AD4)",
         parts=("S_AD_W2", "S_AD_WY", "S_AD_I4", "S_AD_I2Y")),
    Slot("S_AD_PREV", 3, "the last period's frame angle [rad] and currents i_d, i_q in it [A]",
         parts=("S_AD_THETA_PREV", "S_AD_ID_PREV", "S_AD_IQ_PREV")),
    Slot("S_AD_V", 2, "the vector held over the present period (alpha, beta) [V]: the command kept at the end of the "
                      "last period", parts=("S_AD_V_ALPHA", "S_AD_V_BETA")),
    Slot("S_AD_RATE", 2, "d and q current rates, low-pass filtered (AD_RATE_FILTER) [A/s]: the quasi-steady test",
         parts=("S_AD_RATE_D", "S_AD_RATE_Q")),
    Slot("S_AD_SEEN", 2, "1.0 in a period where psi (first) and R_s (second) were observable and their fits updated",
         parts=("S_AD_SEEN_PSI", "S_AD_SEEN_RS")),
    Slot("S_AD_PRIMED", 2, "1.0 once a period has left S_AD_PREV, S_AD_V (first); 1.0 once R_s_hat was seeded on the "
                           "identification's R_s_id (second)", parts=("S_AD_PRIMED_V", "S_AD_PRIMED_RS")),
    # the sensorless unit's synchronism (``sync_guard``, ``detect_trouble``)
    ("S_GUARD", 1, "the load-angle guard holding the I-f vector back (GUARD_SOFT, GUARD_HARD; 0 = not)"),
    ("S_LOS", 1, "I-f: how long the unit has been in trouble (the slip beyond its bound, or the limit reached) [s]"),
    ("S_EPISODE", 1, "the age of the present loss-of-synchronism episode [s] (0: none)"),
    ("S_INSYNC", 1, "how long it has been in synchronism since [s]"),
    ("S_FAULT", 1, "the fault (FAULT_*)"),
    ("S_THETA_CTRL", 1, "the control frame's angle of the last period [rad]"),
    ("S_OMEGA_CTRL", 1, "the control frame's speed of the last period [rad/s]"),
    # the car standing in I-f (``C_STILL``)
    ("S_ANCHOR", 1, "the rotor's angle when the stand began [rad]: the vector's and S_TRUST_OFF"),
    ("S_ANCHORED", 1, "the stand's state: STAND_HELD (1.0) while the car stands, else STAND_FREE (0.0)"),
    ("S_ANCHOR_TL", 1, "the load when the stand began [N m]: S_TRUST_TL"),
    ("S_STILL_OUT", 1, "how long |omega_hat| has been above C_STILL while standing [s] (the stand ends at "
                       "C_STILL_TIME)"),
    # reference generator
    ("S_I_DREF", 1, "the d-current reference of the reference generator [A] (``C_REF_MODE`` != 0)"),
    ("S_T_REF", 1, "the motor's torque reference after the limits [N m] (``C_REF_MODE`` != 0)"),
    ("S_T_BRAKE", 1, "the friction brake's demand at the wheels [N m, >= 0] (``C_REF_MODE`` != 0)"),
    ("S_REGION", 1, "the reference generator's region (``kernels.references`` REGION_*)"),
    ("S_T_AVAIL", 1, "the torque available at the present speed, either sign [N m]: the speed PI's clamp"),
    # the speed loop's feedforward (``C_FF``, ``speed_feedforward``)
    ("S_W_REF_PREV", 1, "the speed reference of the last period [rad/s]"),
    ("S_FF_PRIMED", 1, "1.0 once a period has given S_W_REF_PREV"),
    ("S_T_FF", 1, "the feedforward torque of this period [N m]: C_J_FF x the reference's slope plus the road load"),
    # the sensorless unit's handover deadline and stall (``C_IF_DEADLINE``, ``C_STALL_TIME``)
    ("S_IF_DUE", 1, "how long the unit has been in I-f with |omega_ref| above C_W_UP [s]"),
    ("S_REALIGN", 1, "the realignments after a stall since the last handover up [-]"),
    # the stand's anchor, relative to the I-f vector (``C_ANCHOR_SPEED``)
    ("S_TRUST_OFF", 1, "the EKF's angle less the I-f vector's, when it last saw the rotor turn at C_ANCHOR_SPEED "
                       "or faster in I-f (or was restarted on the vector) [rad]"),
    ("S_TRUST_TL", 1, "the EKF's load at that moment [N m]"),
    ("S_ANCHOR_REL", 1, "the stand's anchor less the I-f vector's angle when the stand began [rad]"),
    # the injection strategy (``C_LOW_SPEED``, ``kernels.injection``, ``kernels.modes``)
    ("S_MODE_TIME", 1, "time in the present mode [s]"),
    ("S_INJ_SIGN", 1, "the square wave's sign in the present half-wave (+1 or -1)"),
    ("S_INJ_COUNT", 1, "control periods run in the present half-wave"),
    ("S_INJ_AMP", 1, "the square wave's amplitude in the present half-wave [V]"),
    ("S_INJ_V1", 1, "the signed injected voltage of the last finished half-wave [V]"),
    ("S_INJ_V2", 1, "... of the one before [V]"),
    ("S_INJ_I1", 2, "the currents (alpha, beta) at the end of the last finished half-wave [A]"),
    ("S_INJ_I2", 2, "... at the end of the one before [A]"),
    ("S_INJ_AXIS", 1, "the axis the square wave was applied on in the last period [rad]"),
    ("S_INJ_SKIP", 1, "half-waves whose answer is not used (the axis jumped) [-]"),
    ("S_INJ_NEW", 1, "1.0 in a period that brought a new answer"),
    ("S_INJ_ERR", 1, "the last answer's angle error signal, sin 2e [-]"),
    ("S_INJ_ADM", 1, "the last answer's d-axis admittance, the inverse of the incremental inductance [1/H]"),
    ("S_AVG", 32, "the last 2 m currents, alpha (16) then beta (16) [A]: the fundamental is their mean"),
    ("S_AVG_POS", 1, "where the next current goes in S_AVG [-]"),
    Slot("S_TRK", 3, "the tracking observer: electrical angle [rad], mechanical speed [rad/s], load torque [N m]",
         parts=("S_TRK_THETA", "S_TRK_OMEGA", "S_TRK_TL")),
    ("S_BLEND", 1, "the EKF's weight in the control frame [-] (0: the tracking observer's, 1: the EKF's)"),
    Slot("S_ACQ", 4, "the angle's acquisition: sums of sin 2e on the first axis and on the axis 45 deg ahead, "
                     "how many answers each [-]", parts=("S_ACQ_SIN0", "S_ACQ_SIN45", "S_ACQ_N0", "S_ACQ_N45")),
    Slot("S_POL", 4, "the polarity test: sums of the d admittance at +i and at -i [1/H], how many of each [-]",
         parts=("S_POL_Y_POS", "S_POL_Y_NEG", "S_POL_N_POS", "S_POL_N_NEG")),
    ("S_POL_TRIES", 1, "polarity tests unresolved since enable [-]"),
    ("S_INJ_ERR_F", 1, "the tracking observer's angle error, low-pass filtered [rad]"),
    ("S_DISAGREE_F", 1, "the injection's angle error less the EKF's (both against the tracking observer), low-pass "
                        "filtered [rad]"),
    ("S_INJ_LOS_T", 1, "how long the injection's angle error (or its disagreement with the EKF) has been "
                       "beyond its bound [s]"),
    ("S_RESID_F", 1, "the EKF's current innovation magnitude, low-pass filtered [A]"),
    ("S_EKF_LOS_T", 1, "how long it has been beyond its bound [s]"),
    ("S_EVENT", 1, "the event of the last period (EV_*; 0 none)"),
    ("S_CROSS", 1, "the injection's axis less the estimated d axis in the last period [rad]: "
                   "cross-saturation's offset"),
    ("S_POL_AXIS", 1, "the polarity test's frame [rad]: the axis the acquisition found, moved only where the "
                      "tracking observer gets more than C_POL_BAND from it"),
    ("S_HOLD", 1, "the hill hold: the friction brake asked for from enable until the unit first gives torque "
                  "[N m at the wheels] (C_HOLD_BRAKE; 0 from then on)"),
    # the I-f strategy's alignment (``kernels.startup``)
    ("S_RUNAWAY_T", 1, "alignment: how long |omega_hat| has been above C_ALIGN_SLIP [s]"),
    ("S_ALIGN_SPEED", 1, "alignment: the rotor's speed the back-EMF shows on the vector's q axis less the sweep's, "
                         "low-pass filtered (the alignment damping's input) [rad/s]"),
    # the injection strategy's identification at enable and its axis and polarity detectors
    # (``kernels.modes``: ``identify``, ``detect_injection_lost``)
    ("S_INJ_YX", 1, "the error signal's gain, Y_x = (1/L_d - 1/L_q) / 2 [1/H]: C_INJ_Y until the identification "
                    "measures it (``demodulate``)"),
    Slot("S_ID_SUM", 8, "the identification: sums of the d admittance on the found d axis at the square wave's "
                        "amplitude and at twice it, on the q axis at both [1/H], how many answers each [-] (a blind "
                        "unit's pooled over its parked acquisitions)",
         parts=("S_ID_A_D", "S_ID_A_D2", "S_ID_A_Q", "S_ID_A_Q2", "S_ID_N_D", "S_ID_N_D2", "S_ID_N_Q", "S_ID_N_Q2")),
    Slot("S_ID_Y", 2, "the identified incremental admittances 1/L_d, 1/L_q at zero current [1/H] (0: not identified)",
         parts=("S_ID_Y_D", "S_ID_Y_Q")),
    Slot("S_ID_YE", 2, "... as the square wave at the amplitude S_INJ_VA sees them, the inverter's dead time included "
                       "[1/H]", parts=("S_ID_YE_D", "S_ID_YE_Q")),
    ("S_INJ_VA", 1, "the square wave's amplitude after the identification [V] (0: C_INJ_V)"),
    ("S_ID_DONE", 1, "1.0 once the first acquisition after enable has run its identification (a blind unit's parked "
                     "acquisitions run it again: ``refining``)"),
    Slot("S_RS_SUM", 6, "the R_s test: sums of the d command [V] and of the d current [A] at the lower level, the "
                        "same at the upper, how many samples each [-]",
         parts=("S_RS_V1", "S_RS_I1", "S_RS_V2", "S_RS_I2", "S_RS_N1", "S_RS_N2")),
    ("S_ID_RS", 1, "the identified stator resistance [Ohm] (0: not identified)"),
    ("S_PARKED", 1, "1.0 while a blind unit (S_ID_BLIND) holds the car at a stop on the friction brake and finds the "
                    "angle afresh for the restart"),
    ("S_ID_BLIND", 1, "1.0 where the identified saliency L_q / L_d is below C_SALIENCY_MIN: the injection cannot "
                      "see the axis well enough"),
    ("S_AXIS_F", 1, "cos 2e from the d admittance and the identified admittances, low-pass filtered [-]"),
    Slot("S_DISAGREE_V", 2, "cos and sin of the injection's angle less the EKF's, low-pass filtered (S_DISAGREE_F is "
                            "their angle: no wrap at +-pi) [-]", parts=("S_DISAGREE_COS", "S_DISAGREE_SIN")),
    Slot("S_ID_NOISE", 8, "the identification: sums of the answers' q second difference, its sign the half-wave's [A], "
                          "on each of its four phases, then of its square [A^2]",
         parts=(("S_ID_D_SUM", 4), ("S_ID_D_SQ", 4))),
    Slot("S_OFS_SUM", 3, "the offset window at enable (no voltage, no current): sums of the measured i_alpha, i_beta "
                         "[A], how many samples [-]", parts=("S_OFS_ALPHA", "S_OFS_BETA", "S_OFS_N")),
    Slot("S_ID_OFS", 2, "the current sensors' offset measured at enable, alpha and beta [A] (subtracted from the "
                        "measurements from then on)", parts=("S_ID_OFS_ALPHA", "S_ID_OFS_BETA")),
    ("S_ID_NOISE_F", 1, "the current measurement's noise floor from the identification's answers: a phase sensor's "
                        "sigma [A] (0: not identified)"),
    ("S_ID_ACC", 1, "the angle accuracy injection gives at a stop, rms [rad] (eq ID3; 0: not identified)"),
    # the injection strategy's back-EMF detector (``kernels.modes.emf_residual``, eqs LS1-LS2)
    ("S_EMF_F", 1, "the back-EMF the current PIs' integrators carry beyond the frame's speed's, as a speed (eq LS1), "
                   "low-pass filtered [rad/s]"),
    ("S_EMF_T", 1, "how long it has been beyond its bound (eq LS2) [s]"),
    ("S_EMF_SEEN", 1, "the rotor's speed the current loops see: all the back-EMF they carry as a speed (eq LS2), "
                      "low-pass filtered [rad/s]"),
    ("S_IF_FALLBACK", 1, "1.0 once a unit that cannot see its motor's axis (``kernels.modes.cannot_see``) runs the I-f "
                         "strategy (``sensorless_step``) for good"),
    Slot("S_V_FUND", 2, "the last period's command without the square wave, alpha and beta [V]: the EKF's input while "
                        "the unit injects (``kernels.modes.injection_unit_step``)",
         parts=("S_V_FUND_ALPHA", "S_V_FUND_BETA")),
    Slot("S_GAIN", 4, "the phase sensors' relative gain (``kernels.modes.balance_sensors``, eqs SG1-SG2): sums of the "
                      "measured phase a and phase b currents' squares on the EKF [A^2 periods], the electrical turns "
                      "they span [-], and g_a / g_b from them once they span ``C_GAIN_TURNS`` (0: not yet measured)",
         parts=("S_GAIN_SUM_A", "S_GAIN_SUM_B", "S_GAIN_TURNS", "S_GAIN_RATIO")),
), size=268)

#: the control unit's parameter vector
#: the points of the cross-saturation table ``C_CROSS``, at i_q = 0, ``CROSS_STEP``, .. (CROSS_POINTS - 1)
#: ``CROSS_STEP`` (``kernels.injection.cross_offset``; held beyond the last)
CROSS_POINTS = 9

UNIT_PARAMS_LAYOUT = Layout("control unit parameter vector", "C_", (
    ("C_DT", 1, "control period [s]"),
    ("C_KP_W", 1, "speed PI proportional gain [A s/rad]"),
    ("C_KI_W", 1, "speed PI integral gain [A/rad]"),
    ("C_I_Q_MAX", 1, "q current limit [A]"),
    ("C_KP_ID", 1, "d current PI proportional gain [V/A]"),
    ("C_KI_ID", 1, "d current PI integral gain [V/(A s)]"),
    ("C_KP_IQ", 1, "q current PI proportional gain [V/A]"),
    ("C_KI_IQ", 1, "q current PI integral gain [V/(A s)]"),
    ("C_T_D", 1, "decoupling filter time constant [s]"),
    ("C_U_MAX", 1, "voltage limit [V]"),
    # the controller's motor model
    ("C_N", 1, "pole pairs [-]"),
    ("C_L_D", 1, "d inductance [H]"),
    ("C_L_Q", 1, "q inductance [H]"),
    ("C_PSI", 1, "magnet flux [Wb]"),
    ("C_PAPER_SIGNS", 1, "1.0: eq 20's signs as printed"),
    ("C_I_D_REF", 1, "d current reference [A]"),
    ("C_ADVANCE", 1, "angle advance per rad/s of omega_hat [s]: periods x dt x N"),
    ("C_HALF_PERIOD_N", 1, "N dt / 2 (the ZOH compensation's half arc over omega)"),
    ("C_ZOH", 1, "1.0: ZOH compensation on"),
    ("C_DELAYED", 1, "1.0: the observer takes the command of one period earlier"),
    ("C_ESTIMATED", 1, "1.0: the control frame on the estimated angle"),
    ("C_OBSERVER", 1, "the observer (OBS_*)"),
    # EKF model constants (A2-A32) and R
    ("C_A_RD", 1, "1 - R_s dt / L_d (A8)"),
    ("C_A_RQ", 1, "1 - R_s dt / L_q (A14)"),
    ("C_C_WQ", 1, "N L_q dt / L_d (A9, A10)"),
    ("C_C_WD", 1, "N L_d dt / L_q (A13)"),
    ("C_C_WPSI", 1, "N psi dt / L_q (A15)"),
    ("C_C_VD", 1, "dt / L_d"),
    ("C_C_VQ", 1, "dt / L_q"),
    ("C_C_TPSI", 1, "N psi dt / J (A19)"),
    ("C_C_TDQ", 1, "N (L_d - L_q) dt / J (A18, A19)"),
    ("C_C_TL", 1, "-dt / J (A22)"),
    ("C_C_TH", 1, "N dt (A25)"),
    ("C_R0", 1, "EKF R, first diagonal entry [A^2]"),
    ("C_R1", 1, "EKF R, second diagonal entry [A^2]"),
    ("C_Q", 5, "EKF Q diagonal, n entries"),
    ("C_C_MID", 1, "stationary-frame EKF5: d(mid-period angle)/d(omega_m) = N dt / 2"),
    ("C_P0", 5, "EKF P0 diagonal, n entries"),
    # ``pmsm_ev.params.StartupParams``
    ("C_T_RAMP", 1, "alignment: current ramp time [s]"),
    ("C_T_HOLD", 1, "alignment: hold time at +90 deg [s]"),
    ("C_T_SWEEP", 1, "alignment: sweep time to 0 deg [s]"),
    ("C_T_SETTLE", 1, "alignment: settling time at 0 deg [s]"),
    ("C_I_ALIGN", 1, "alignment current [A]"),
    ("C_I_IF", 1, "least I-f current [A]"),
    ("C_IF_ACCEL", 1, "I-f acceleration limit [rad/s^2]"),
    ("C_I_RATE", 1, "I-f current rate [A/s]"),
    ("C_W_UP", 1, "handover up above this speed [rad/s]"),
    ("C_W_DOWN", 1, "handover down below this speed [rad/s]"),
    ("C_AGREE_TOL", 1, "relative agreement of omega_hat and omega_if [-]"),
    ("C_AGREE_TIME", 1, "... for this long [s]"),
    ("C_IF_MARGIN", 1, "I-f current margin over the load's current [-]"),
    ("C_IF_DAMP", 1, "I-f damping: 2 zeta sqrt(J / psi) [rad s sqrt(A)], divided by sqrt(i) in use"),
    ("C_P0_ALIGNED", 5, "EKF P0 diagonal at the restart after the alignment"),
    ("C_SLIP_FILTER", 1, "dt / time constant of the low-pass filter of the damping's input [-]"),
    ("C_DTC_V", 1, "dead-time compensation: per-phase voltage amplitude [V] (0 = off; "
                   "``ControllerParams.dead_time_comp``)"),
    ("C_DTC_I0", 1, "... its soft sign's current scale [A] (``ControllerParams.dead_time_comp_i0``)"),
    ("C_PSI_ADAPT", 1, "psi adaptation of the stationary-frame EKF5: gain [1/s] (0 = off; ``EkfParams.psi_adapt``)"),
    ("C_PSI_ADAPT_W", 1, "... the least |omega_hat| it adapts at [rad/s]"),
    # adaptation while driving (``ControllerParams.adaptation``; ``pmsm_ev.kernels.adaptation``)
    ("C_ADAPT", 1, "ADAPT_OFF, ADAPT_OBSERVE (the estimates computed, not used), ADAPT_USE (the controller's model "
                   "takes them)"),
    ("C_AD_GAIN", 1, "dt / ControllerParams.adapt_time: the least-squares sums' forgetting per period [-]"),
    ("C_AD_PSI_W", 1, "the least |omega_e| at which psi is observable [rad/s, electrical]"),
    ("C_AD_RS_W", 1, "the largest |omega_e| at which R_s is observable [rad/s, electrical]"),
    ("C_AD_RS_I", 1, "the least |i| at which R_s is observable [A]"),
    ("C_AD_RATE", 1, "the largest filtered |di/dt| of a quasi-steady period [A/s]"),
    ("C_AD_PSI0", 1, "the model's psi: where psi_hat starts [Wb]"),
    ("C_AD_RS0", 1, "the model's R_s: where R_s_hat starts (until the identification's R_s_id) [Ohm]"),
    Slot("C_AD_NOM", 2, "the EKF model's psi-proportional constants at C_AD_PSI0: C_C_WPSI, C_C_TPSI",
         parts=("C_AD_NOM_WPSI", "C_AD_NOM_TPSI")),
    # the sensorless unit's I-f sizing and synchronism (``pmsm_ev.params.StartupParams``)
    ("C_J_IF", 1, "the EKF model's inertia [kg m^2]"),
    ("C_E_MAX", 1, "the design load angle [rad]"),
    ("C_SIN_E", 1, "its sine [-]"),
    ("C_I_RATE_LOAD", 1, "the current rate when the load exceeds the vector [A/s]"),
    ("C_GUARD", 1, "1.0: the load-angle guard on"),
    ("C_SLIP_TOL", 1, "the slip bound [rad/s]"),
    ("C_SLIP_TIME", 1, "... for this long: a loss of synchronism [s]"),
    ("C_RECOVER_TIME", 1, "the time in synchronism that ends an episode [s]"),
    ("C_FAULT_TIME", 1, "the episode's age that latches the fault [s]"),
    ("C_E_GUARD", 1, "the guard's angle [rad]"),
    ("C_ALIGN_DAMP", 1, "1.0: the alignment damped on the back-EMF (``StartupParams.align_damping``)"),
    ("C_ALIGN_SLIP", 1, "|omega_hat| that ends the alignment: the rotor runs away under its vector [rad/s]"),
    ("C_ALIGN_SLIP_TIME", 1, "... for this long [s]"),
    ("C_STILL", 1, "below this |omega_hat| and |omega_if| in I-f the car stands: its angle is held [rad/s]"),
    # high-speed current control and discretisation
    ("C_CC_HS", 1, "1.0: the high-speed current control (``ControllerParams.current_control``)"),
    ("C_CC_PRED", 1, "... the share of the current error the decoupling predicts the current to have made up at "
                     "the middle of the applied period: 1 - exp(-omega_c dt angle_advance) [-]"),
    ("C_EKF_BILINEAR", 1, "1.0: the observers' current model stepped by Tustin's rule (``EkfParams.discretisation``)"),
    # reference generator (``pmsm_ev.params.ControllerParams.reference``, ``kernels.references``)
    ("C_REF_MODE", 1, "the references: REF_PAPER (i_d_ref, i_q from the speed PI), REF_MTPA, REF_FW"),
    ("C_I_MAX", 1, "the current-magnitude limit [A]"),
    ("C_T_MAX", 1, "the torque limit [N m] (resolved: MTPA at C_I_MAX when not given)"),
    ("C_U_FW", 1, "the voltage for field weakening [V]: fw_margin x the voltage limit (0: no voltage limit)"),
    ("C_K_T", 1, "the torque constant k_dq N psi [N m/A]: the speed PI's output x C_K_T is the torque demand"),
    ("C_K_DQN", 1, "k_dq N: eq 12's torque factor [-]"),
    ("C_P_REGEN", 1, "the regenerative power limit [W] (0: none)"),
    ("C_BRAKE_GAIN", 1, "n_g eta: a shaft torque's friction-brake torque at the wheels [-]"),
    # the speed loop's feedforward (``pmsm_ev.params.ControllerParams.speed_feedforward``)
    ("C_FF", 1, "1.0: the speed loop's feedforward on (the reference generator's modes only)"),
    ("C_J_FF", 1, "the inertia of the acceleration feedforward [kg m^2]: the speed PI's J_m + J_load"),
    ("C_FF_T0", 1, "the road-load feedforward's constant term at the shaft [N m] (0: none)"),
    ("C_FF_T1", 1, "... its term in |omega_ref| [N m s/rad]"),
    ("C_FF_T2", 1, "... its term in omega_ref^2 [N m s^2/rad^2]"),
    # the sensorless unit's handover deadline and stall (``pmsm_ev.params.StartupParams``)
    ("C_IF_DEADLINE", 1, "in I-f with |omega_ref| above C_W_UP this long, the handover up is forced [s]"),
    ("C_STALL_TIME", 1, "... this long, the drive has stalled: a realignment [s]"),
    ("C_REALIGN_MAX", 1, "realignments after a stall before the fault latches [-]"),
    ("C_ANCHOR_SPEED", 1, "in I-f at this |omega_hat| or faster the EKF's angle (relative to the vector) and load "
                          "are what a stand is anchored on [rad/s]"),
    # the injection strategy (``pmsm_ev.params.InjectionParams``)
    ("C_LOW_SPEED", 1, "the strategy at and near zero speed: 0 I-f, 1 injection (LOW_SPEED_*)"),
    ("C_INJ_V", 1, "the square wave's amplitude [V]"),
    ("C_INJ_M", 1, "its half-period in control periods, m [-]"),
    ("C_INJ_Y", 1, "the controller's model's (1/L_d - 1/L_q) / 2 [1/H]: the error signal's gain"),
    Slot("C_TRK_L", 3, "the tracking observer's gains l1 [1/s], l2 [1/s^2 per electrical rad], l3 [N m/(rad s)]",
         parts=("C_TRK_L1", "C_TRK_L2", "C_TRK_L3")),
    ("C_TRK_J", 1, "its inertia [kg m^2]"),
    ("C_BLEND_LO", 1, "the EKF's weight rises from 0 at this |omega| [rad/s] ..."),
    ("C_BLEND_HI", 1, "... to 1 at this one, where the injection is off [rad/s]"),
    ("C_BLEND_HYST", 1, "back into the injection below C_BLEND_HI less this [rad/s]"),
    ("C_ACQ_TIME", 1, "the acquisition's time on each axis [s]"),
    ("C_ACQ_SETTLE", 1, "the tracking observer's settling after it [s]"),
    ("C_POL_I", 1, "the polarity test's d current [A]"),
    ("C_POL_RAMP", 1, "its ramp [s]"),
    ("C_POL_HOLD", 1, "its hold at each sign [s]"),
    ("C_POL_CONTRAST", 1, "the least relative difference of the answers that decides [-]"),
    ("C_INJ_LOS_ANGLE", 1, "the injection's loss-of-synchronism angle [rad]"),
    ("C_INJ_LOS_TIME", 1, "... time [s]"),
    ("C_EKF_LOS_I", 1, "the EKF's loss-of-synchronism innovation [A]"),
    ("C_EKF_LOS_TIME", 1, "... time [s]"),
    ("C_EKF_LOS_EMF", 1, "... plus this times |omega_hat|: the current the back-EMF drives in a period, dt N psi / L_q "
                         "[A s/rad]"),
    ("C_LOS_FILTER", 1, "dt / the detectors' filter time constant (inj_los_time / "
                        "``control_unit.LOS_FILTER_CONSTANTS``) [-]"),
    ("C_CROSS", CROSS_POINTS, "the injection's axis less the rotor's d axis at i_q = 0, 50, .. 400 A [rad]: "
                              "cross-saturation's offset in the controller's model of the saturation (0: not "
                              "compensated)"),
    ("C_INJ_I_MAX", 1, "the q current limit while the injection carries the angle [A]"),
    ("C_POL_BAND", 1, "the polarity test's frame: how far the tracking observer may move from it before it follows "
                      "[rad]"),
    ("C_HOLD_BRAKE", 1, "the hill hold's friction brake [N m at the wheels]: InjectionParams.hold_brake times the "
                        "drive's torque limit at the wheels, C_T_MAX C_BRAKE_GAIN"),
    # the I-f strategy's guard, trust, relock and stand (``pmsm_ev.params.StartupParams``)
    ("C_SOFT_GUARD", 1, "beyond this lead of the I-f vector over the rotor's angle it turns no faster than the rotor "
                        "[rad]"),
    ("C_GUARD_BAND", 1, "the guard lets go once the lead is back within C_SOFT_GUARD less this [rad]"),
    ("C_TRUST_MOVE", 1, "in I-f the EKF is believed once the rotor has moved this far on the vector since [rad]"),
    ("C_RELOCK_TIME", 1, "a relocked vector's torque brings the speed to the reference in this time [s]"),
    ("C_STILL_TIME", 1, "a stand ends once |omega_hat| has been above C_STILL this long [s]"),
    # the DC link measured (the controller's inputs v_dc, P_charge_max, P_discharge_max; ``unit_dc_link``)
    ("C_FW_MARGIN", 1, "the field weakening's share of the voltage limit [-] (``ControllerParams.fw_margin``; 0 "
                       "without field weakening): C_U_FW = C_FW_MARGIN x C_U_MAX at the measured DC link"),
    ("C_BAT_LINK", 1, "1.0: the DC link is measured (the input v_dc > 0): the voltage limit follows it and the torque "
                      "is held within the battery's powers C_P_CHG, C_P_DIS"),
    ("C_P_CHG", 1, "the battery's charge acceptance [W] (input P_charge_max): a braking torque's power at the shaft "
                   "at most this"),
    ("C_P_DIS", 1, "the battery's discharge power [W] (input P_discharge_max): a motoring torque's power at the shaft "
                   "at most this"),
    # the injection strategy's identification and detectors (``pmsm_ev.params.InjectionParams``)
    ("C_ID_TIME", 1, "the identification's time on each axis, d then q [s] (0: none, the model's admittances)"),
    ("C_INJ_V_MAX", 1, "the square wave's largest amplitude, that the identified motor's answer may ask for [V]"),
    ("C_RS_I", 1, "the R_s test's upper d current [A] (the lower: half of it)"),
    ("C_RS_TIME", 1, "the R_s test's time at each level [s] (0: no test)"),
    ("C_SALIENCY_MIN", 1, "the least identified saliency L_q / L_d the injection is trusted at [-]"),
    ("C_SALIENCY_TRUST", 1, "the least saliency a blind unit's pooled answers must show to trust the injection [-]"),
    ("C_AXIS_COS", 1, "the tracking observer has lost the axis where cos 2e from the d admittance stays below this "
                      "[-]"),
    ("C_OFS_TIME", 1, "the offset window at enable: no voltage, the sensors' mean is their offset [s] (0: none)"),
    ("C_ANGLE_MAX", 1, "the largest angle accuracy (eq ID3) at which the injection is trusted [rad]"),
    ("C_EMF_SPEED", 1, "the back-EMF detector: the unexplained back-EMF's speed beyond which the frame has lost the "
                       "rotor, at a standing frame [rad/s] (eq LS2)"),
    ("C_EMF_REL", 1, "... plus this share of the rotor's speed the current loops see [-]"),
    # the controller's model from the identification (``ControllerParams.model_source``; ``kernels.adaptation``, AD7)
    ("C_MODEL_SRC", 1, "MODEL_GIVEN (the motor's parameters as given) or MODEL_IDENTIFIED (L_d, L_q, R_s as the "
                       "identification measures them)"),
    Slot("C_MODEL0", 7, "the given model: L_d [H], L_q [H], R_s [Ohm] and the current PIs' gains at them: K_p,d [V/A], "
                        "K_i,d [V/(A s)], K_p,q, K_i,q",
         parts=("C_MODEL0_L_D", "C_MODEL0_L_Q", "C_MODEL0_R_S", "C_MODEL0_KP_ID", "C_MODEL0_KI_ID", "C_MODEL0_KP_IQ",
                "C_MODEL0_KI_IQ")),
    ("C_SEE_MAX", 1, "the largest angle accuracy (eq ID3) at which a blind unit finds the axis at its stops [rad] "
                     "(``cannot_see``)"),
    ("C_GAIN_TURNS", 1, "the electrical turns on the EKF over which the phase sensors' relative gain is measured "
                        "before it is used (eq SG2) [-] (0: not measured)"),
    ("C_SALIENCY_HOLD", 1, "the least identified saliency at which a seeing unit holds the car on the injection at "
                          "its stops before it has measured its phase sensors' relative gain [-]"),
    # cross-saturation on the identified motor (``kernels.adaptation.cross_apply``, AD8)
    ("C_MODEL0_CROSS", CROSS_POINTS, "the given model's C_CROSS [rad], to go back to"),
    ("C_MODEL0_INJ_I_MAX", 1, "the given C_INJ_I_MAX [A], to go back to"),
    ("C_CROSS_G", 3 * CROSS_POINTS, "the given model's incremental admittance matrix (g_dd, g_dq, g_qq) [1/H] at i_d = "
                                    "0, i_q = 0, 50, .. 400 A, three a point (0: no compensation)"),
    ("C_INJ_TILT_MAX", 1, "the given model's cross-saturation offset at C_INJ_I_MAX [rad]: the identified motor's "
                          "injection current limit is where its offset reaches it"),
    ("C_GAIN_SE", 1, "the standard error at which the phase sensors' relative gain measured at standstill is taken "
                     "(eq SG0) [-] (0: not measured at standstill)"),
), size=180 + CROSS_POINTS + 1 + 3 * CROSS_POINTS + 2)

#: the battery's open-circuit voltage table: at most this many points (``P_BAT_OCV``)
BAT_OCV_MAX = 24
#: the thermal network's nodes (``P_TH_INV_C``, ``E_TH_T``): stator yoke, stator tooth, winding, magnet (rotor)
TH_Y, TH_T, TH_W, TH_M = 0, 1, 2, 3
#: its conductances (``P_TH_G``): yoke-coolant, yoke-winding, yoke-tooth, tooth-winding, tooth-magnet (the air gap),
#: winding-magnet (the end windings' air), magnet-ambient (the shaft and the housing's air: to the coolant's
#: temperature), winding-coolant (the one-node winding's ``thermal_R``)
TH_G_YC, TH_G_YW, TH_G_YT, TH_G_TW, TH_G_TM, TH_G_WM, TH_G_MA, TH_G_WC = range(8)
#: its over-temperature flags (``E_TH_OVER``): the winding at or above its insulation's limit, the magnet above its own
TH_OVER_WINDING, TH_OVER_MAGNET = 1.0, 2.0

PLANT_PARAMS_LAYOUT.export(globals())
PLANT_ENERGY_LAYOUT.export(globals())
UNIT_STATE_LAYOUT.export(globals())
UNIT_PARAMS_LAYOUT.export(globals())
#: the observer's voltage input of one period earlier (``S_U_PREV_0``, ``S_U_PREV_1``) by the observer's frame: dq for
#: the rotating-frame observers, alpha-beta for the stationary-frame EKF5 (a unit has one observer, so one of the two)
S_U_PREV_D, S_U_PREV_Q = S_U_PREV_0, S_U_PREV_1  # noqa: F821 - exported above
S_U_PREV_ALPHA, S_U_PREV_BETA = S_U_PREV_0, S_U_PREV_1  # noqa: F821
PLANT_PARAMS = PLANT_PARAMS_LAYOUT.size  #: length of the plant's parameter vector
PLANT_ENERGY = PLANT_ENERGY_LAYOUT.size  #: length of the plant's energy vector
UNIT_STATE = UNIT_STATE_LAYOUT.size  #: length of the control unit's state vector
UNIT_PARAMS = UNIT_PARAMS_LAYOUT.size  #: length of the control unit's parameter vector

# the FMUs' buffers of the compiled step (``pmsm_ev.kernels.fmu``): what the lean binding reads and writes
PLANT_IO_LAYOUT = Layout("plant FMU buffer", "PIO_", (
    # the Real inputs (PmsmEvPlant's)
    ("PIO_V_ALPHA", 1, "input v_alpha [V]"),
    ("PIO_V_BETA", 1, "input v_beta [V]"),
    ("PIO_DELTA", 1, "input delta [rad]"),
    ("PIO_T_BRAKE", 1, "input T_brake [N m at the wheels]"),
    # the outputs: the plant's state and outputs after the last step (``Plant``'s attributes of the same names)
    ("PIO_I_ALPHA", 1, "output i_alpha (as measured) [A]"),
    ("PIO_I_BETA", 1, "output i_beta (as measured) [A]"),
    ("PIO_I_D", 1, "output i_d [A]"),
    ("PIO_I_Q", 1, "output i_q [A]"),
    ("PIO_OMEGA_M", 1, "output omega_m [rad/s]"),
    ("PIO_THETA_E", 1, "output theta_e [rad]"),
    ("PIO_T_E", 1, "output T_e [N m]"),
    ("PIO_T_L_MECH", 1, "output T_L_mech [N m]"),
    ("PIO_V_VEHICLE", 1, "output v_vehicle [m/s]"),
    ("PIO_X_VEHICLE", 1, "output x_vehicle [m]"),
    # the plant's other state (``Plant``'s attributes)
    ("PIO_PLANT_DELTA", 1, "Plant.delta: the elevation of the last step [rad]"),
    ("PIO_PLANT_T_BRAKE", 1, "Plant.T_brake: the brake torque of the last step, >= 0 [N m]"),
    ("PIO_CLOCK", 1, "Plant.clock [s]"),
    ("PIO_SAMPLES", 1, "Plant.samples: the measurements taken (a whole number)"),
    ("PIO_V_ALPHA_APPLIED", 1, "Plant.v_alpha_applied [V]"),
    ("PIO_V_BETA_APPLIED", 1, "Plant.v_beta_applied [V]"),
    ("PIO_I_ALPHA_TRUE", 1, "Plant.i_alpha_true [A]"),
    ("PIO_I_BETA_TRUE", 1, "Plant.i_beta_true [A]"),
    # the plant's constants
    ("PIO_U_LIM", 1, "the voltage limit v_dc / sqrt(3) [V] (0: none)"),
    ("PIO_SENSORS", 1, "1.0: the current sensors are modelled (plant_step_measured)"),
    ("PIO_SEED", 2, "the sensors' noise stream: its 64-bit seed as two 32-bit halves, high first"),
    ("PIO_SENSOR_ARGS", 7, "gain_a, offset_a, gain_b, offset_b, noise, lsb, adc_range (Plant._sensor_args)"),
    # scratch
    ("PIO_SAVE", PLANT_ENERGY, "the energy vector before the step (restored when a kernel raises) [J]"),
), size=33 + PLANT_ENERGY)

UNIT_IO_LAYOUT = Layout("controller FMU buffer", "UIO_", (
    # the Real inputs (FocSlave's)
    ("UIO_I_ALPHA", 1, "input i_alpha [A]"),
    ("UIO_I_BETA", 1, "input i_beta [A]"),
    ("UIO_OMEGA_REF", 1, "input omega_ref [rad/s]"),
    ("UIO_THETA_MEAS", 1, "input theta_meas [rad]"),
    ("UIO_OMEGA_MEAS", 1, "input omega_meas [rad/s]"),
    # the outputs the step writes (FocSlave's attributes of the same names)
    ("UIO_V_ALPHA", 1, "output v_alpha [V]"),
    ("UIO_V_BETA", 1, "output v_beta [V]"),
    ("UIO_V_D", 1, "output v_d [V]"),
    ("UIO_V_Q", 1, "output v_q [V]"),
    ("UIO_I_D", 1, "output i_d [A]"),
    ("UIO_I_Q", 1, "output i_q [A]"),
    ("UIO_I_QREF", 1, "output i_qref [A]"),
    ("UIO_I_D_HAT", 1, "output i_d_hat [A]"),
    ("UIO_I_Q_HAT", 1, "output i_q_hat [A]"),
    ("UIO_OMEGA_HAT", 1, "output omega_hat [rad/s]"),
    ("UIO_THETA_HAT", 1, "output theta_hat [rad]"),
    ("UIO_T_L_HAT", 1, "output T_L_hat [N m]"),
    ("UIO_MODE", 1, "output mode"),
    ("UIO_FAULT", 1, "output fault"),
    ("UIO_THETA_CTRL", 1, "output theta_ctrl [rad]"),
    ("UIO_OMEGA_CTRL", 1, "output omega_ctrl [rad/s]"),
    ("UIO_T_BRAKE", 1, "output T_brake: ControlUnit.T_brake of the state [N m]"),
    # the sample clock (FocSlave._dt, _t0, _k_next) and the unit's constants
    ("UIO_DT", 1, "the sample period [s] (0: not fixed yet, the first step's size)"),
    ("UIO_T0", 1, "the start time [s]"),
    ("UIO_CLOCK", 1, "1.0: the clock runs (_k_next set), 0.0: the first step starts it"),
    ("UIO_K_NEXT", 1, "the index of the next sample instant (a whole number)"),
    ("UIO_UNIT_DT", 1, "the unit's own dt [s] (a first step of another size rebuilds the unit: declined)"),
    ("UIO_TOLERANCE", 1, "SAMPLE_TOLERANCE of the slave [-]"),
    ("UIO_KIND", 1, "the step's kernel: 0 control_step, 1 sensorless_step, 2 injection_unit_step"),
    ("UIO_MEASURED", 1, "1.0: the control frame is the measured angle (theta_ctrl = theta_meas)"),
    ("UIO_REFERENCE", 1, "the reference generator's mode (ControlUnit.reference; T_brake is 0 with 0)"),
    # the DC link's inputs (FocSlave's; 0 = unconnected: the parameters' constant link)
    ("UIO_V_DC_MEAS", 1, "input v_dc_meas: the DC link's measured voltage [V] (0: not measured)"),
    ("UIO_P_CHARGE_MAX", 1, "input P_charge_max: the battery's charge acceptance [W]"),
    ("UIO_P_DISCHARGE_MAX", 1, "input P_discharge_max: the battery's discharge power [W]"),
    # the reference generator's outputs of the state (``unit_reference_outputs``), written after each step as
    # T_brake is: the FMU's outputs i_dref, T_ref and ref_region, read from here with no Python
    ("UIO_I_DREF", 1, "output i_dref: ControlUnit.i_dref of the state [A]"),
    ("UIO_T_REF", 1, "output T_ref: ControlUnit.T_ref of the state [N m]"),
    ("UIO_REF_REGION", 1, "output ref_region: ControlUnit.ref_region of the state"),
    # the identification's and the adaptation's outputs of the state (``unit_status_outputs``, UNIT_STATUS_OUTPUTS),
    # written after each step likewise: read from here with no Python
    ("UIO_STATUS", 15, "outputs psi_est ... gain_ratio_id (UNIT_STATUS_OUTPUTS, in that order) of the state"),
    # scratch
    ("UIO_SAVE", UNIT_STATE, "the state vector before the step (restored when a kernel raises)"),
), size=52 + UNIT_STATE)
#: the controller FMUs' outputs of the identification at enable and the adaptation while driving, in the order of
#: their slots from ``UIO_STATUS`` (``pmsm_ev.kernels.unit_status_outputs``)
UNIT_STATUS_OUTPUTS = ("psi_est", "R_s_est", "psi_observable", "R_s_observable", "L_d_id", "L_q_id", "saliency_id",
                       "R_s_id", "noise_id", "offset_a_id", "offset_b_id", "angle_accuracy", "blind", "axis_cos",
                       "gain_ratio_id")
PLANT_IO_LAYOUT.export(globals())
UNIT_IO_LAYOUT.export(globals())
PLANT_IO = PLANT_IO_LAYOUT.size  #: length of the plant FMU's buffer
UNIT_IO = UNIT_IO_LAYOUT.size  #: length of a controller FMU's buffer

#: modes of the sensorless unit (``S_MODE``): the I-f strategy's alignment and I-f, FOC on the EKF (both
#: strategies), and the injection strategy's angle acquisition, polarity test and FOC on the injection: named integers,
#: which the state holds as floats (``kernels.machine`` declares the events and the entry actions)
MODE_ALIGN, MODE_IF, MODE_EKF, MODE_ACQUIRE, MODE_POLARITY, MODE_INJECTION = range(6)
#: the strategies at and near zero speed (``C_LOW_SPEED``, ``InjectionParams.low_speed``)
LOW_SPEED_IF, LOW_SPEED_INJECTION = 0.0, 1.0
LOW_SPEED_CODES = {"if": LOW_SPEED_IF, "injection": LOW_SPEED_INJECTION}
#: its fault output (``S_FAULT``): none; a loss of synchronism detected, recovery under way; the
#: recovery failed: the safe state (stop and hold at the current limit) latched
FAULT_NONE, FAULT_RECOVERING, FAULT_LATCHED = 0.0, 1.0, 2.0

#: observers (``C_OBSERVER``)
OBS_EKF5, OBS_EKF4, OBS_EKF5AB, OBS_SENSORED = 0, 1, 2, 3
OBSERVER_CODES = {"ekf5": OBS_EKF5, "ekf4": OBS_EKF4, "ekf5ab": OBS_EKF5AB, "sensored": OBS_SENSORED}

#: adaptation while driving (``C_ADAPT``, ``ControllerParams.adaptation``)
ADAPT_OFF, ADAPT_OBSERVE, ADAPT_USE = 0.0, 1.0, 2.0
#: the controller's model of the motor (``C_MODEL_SRC``, ``ControllerParams.model_source``)
MODEL_GIVEN, MODEL_IDENTIFIED = 0.0, 1.0
ADAPT_CODES = {"off": ADAPT_OFF, "observe": ADAPT_OBSERVE, "use": ADAPT_USE}
MODEL_CODES = {"given": MODEL_GIVEN, "identified": MODEL_IDENTIFIED}

#: the reference generator's modes (``C_REF_MODE``, ``ControllerParams.reference``)
REF_PAPER, REF_MTPA, REF_FW = 0.0, 1.0, 2.0
REFERENCE_CODES = {"paper": REF_PAPER, "mtpa": REF_MTPA, "fw": REF_FW}
