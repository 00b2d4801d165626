"""All parameters of the drive, in one place, with units and sources.

Sources are marked in each docstring line:

* ``[T1]``/``[T2]``: the paper's Table I (PMSM) and Table II (mechanical part).
* ``[chosen]``: the paper is silent (or its appendix prints a garbled "2"); the value
  is chosen here, with the reasoning next to it. README.md ("Choices where the paper is
  silent") sums the choices up for readers who do not read code; each FMU's
  modelDescription.xml gives every parameter's unit and description (``pmsm_ev_fmus.metadata``).

Everything is SI: V, A, Ohm, H, Wb (= V s/rad), N m, kg m^2, rad, rad/s, s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace

from .kernels import (
    FX_ADQ,
    FX_IF,
    FX_PSI0,
    FX_W0,
    REFERENCE_CODES,
    STATIONARY_SUBSTEP_ANGLE,
    flux_currents,
    flux_energy,
    flux_jacobian,
    flux_linkages,
)
from .kernels import dq_torque as kernel_dq_torque
from .kernels import mtpa_limit_current as kernel_mtpa_limit_current
from .kernels import winding_resistance as kernel_winding_resistance

LOAD_MODELS = ("physical", "paper")
DECOUPLING_MODES = ("physical", "paper")
ANGLE_SOURCES = ("measured", "estimated")
OBSERVERS = ("ekf5", "ekf4", "ekf5ab", "sensored", "sensorless")
#: the current references of the controllers (``ControllerParams.reference``)
REFERENCES = tuple(REFERENCE_CODES)
#: how the gear's efficiency acts (``VehicleParams.gear_model``)
GEAR_MODELS = ("paper", "power_flow")
#: how the dq quantities scale to the phase quantities (``MotorParams.dq_convention``)
DQ_CONVENTIONS = ("paper", "amplitude_invariant")
#: the current control (``ControllerParams.current_control``) and the observers' discretisation
#: (``EkfParams.discretisation``); docs/speed-range.md
CURRENT_CONTROLS = ("paper", "high_speed")
#: the speed loop's feedforward (``ControllerParams.speed_feedforward``; docs/cycles.md)
SPEED_FEEDFORWARDS = ("none", "inertia", "inertia+road")
#: adaptation while driving (``ControllerParams.adaptation``)
ADAPTATIONS = ("off", "observe", "use")
#: the controller's model of the motor (``ControllerParams.model_source``)
MODEL_SOURCES = ("given", "identified")
DISCRETISATIONS = ("euler", "bilinear")
#: the frames the plant's RK4 integrates in (``PlantParams.integrator``)
INTEGRATORS = ("rk4_rotor", "rk6_stationary")
#: the plant's magnetic model (``PlantParams.flux_model``)
FLUX_MODELS = ("linear", "algebraic")
#: the plant's thermal models (``PlantParams.thermal_model``): none (or the one-node winding of ``thermal_R``), the
#: four-node lumped-parameter thermal network
THERMAL_MODELS = ("off", "lptn")


class ParameterError(ValueError):
    """A parameter value that is not physical or not allowed."""


def _require(cond: bool, message: str) -> None:
    if not cond:
        raise ParameterError(message)


@dataclass(frozen=True)
class MotorParams:
    """PMSM parameters, Table I of the paper, plus the friction terms of eq 8."""

    N: int = 4  #: pole pairs [-] [T1]
    psi: float = 0.08975  #: permanent-magnet flux linkage [V s/rad] [T1]
    L_d: float = 0.202e-3  #: d-axis inductance [H] [T1]
    L_q: float = 0.29e-3  #: q-axis inductance [H] [T1]
    R_s: float = 8.669e-3  #: stator resistance [Ohm] [T1]
    J_m: float = 0.01  #: rotor inertia [kg m^2] [T1]
    #: viscous friction [N m s/rad] [chosen]: bearing and windage loss of a ~50 kW EV
    #: motor is a few tenths of a percent of rated power; 1e-3 N m s/rad gives 0.2 N m
    #: (40 W) at 200 rad/s, about 5 % of the level-road load torque.
    B_m: float = 1.0e-3
    #: constant (Coulomb) friction torque of eq 8 [N m] [chosen]: 0.1 N m, the order
    #: of the seal and bearing drag of a motor this size.
    T_m0: float = 0.1
    #: speed scale of the smooth sign of T_m0 in the "physical" load model [rad/s]
    #: [chosen]: 0.1 rad/s (2.3 mm/s at the wheel), smooth enough for RK4 at 10 kHz.
    omega_eps: float = 0.1
    #: windage [N m s^2/rad^2]: a drag k_wind omega |omega| beside eq 8, a power k_wind |omega|^3; 0 = off
    #: (the paper's motor, eq 8 alone). The drive-cycle and speed-range scenarios take the sourced friction
    #: and windage of a traction motor of this power instead of the paper's B_m, T_m0 (docs/speed-range.md,
    #: "The losses"): ``SOURCED_T_M0`` (bearings, the constant-coefficient friction moment) and
    #: ``SOURCED_K_WIND`` (the rotor's air friction, ``rotor_windage_power``), with B_m = 0.
    k_wind: float = 0.0
    #: the dq convention, stated once (docs/speed-range.md). The project's Clarke and Park transforms,
    #: current sensors and voltage limit (u_max = v_dc / sqrt 3) are amplitude-invariant: a dq current
    #: of 1 A is a phase current of 1 A peak. With those, the power into the winding is
    #: 3/2 (v_d i_d + v_q i_q) and the torque 3/2 N (psi i_q + (L_d - L_q) i_d i_q); eq 12 as printed
    #: has no 3/2. "paper" (default, the paper's scenarios): eq 12 as printed, and the power that
    #: balances eqs 10-12 is then v_d i_d + v_q i_q (the model's own scaling, as if power-invariant);
    #: "amplitude_invariant": torque and power both 3/2 of that (the physical correction). Either way
    #: the energy balance closes; ``k_dq`` is the factor.
    dq_convention: str = "paper"

    @property
    def k_dq(self) -> float:
        """The factor of eq 12's torque and of v_d i_d + v_q i_q in the power [-]: 1 ("paper"),
        3/2 ("amplitude_invariant"); see ``dq_convention``."""
        return 1.5 if self.dq_convention == "amplitude_invariant" else 1.0

    def validate(self) -> None:
        _require(self.dq_convention in DQ_CONVENTIONS,
                 f"dq_convention must be one of {DQ_CONVENTIONS} (got {self.dq_convention!r})")
        _require(self.N >= 1 and float(self.N).is_integer(), f"N must be a whole number >= 1 (got {self.N})")
        _require(self.psi > 0, f"psi must be > 0 V s/rad (got {self.psi})")
        _require(self.L_d > 0, f"L_d must be > 0 H (got {self.L_d})")
        _require(self.L_q > 0, f"L_q must be > 0 H (got {self.L_q})")
        _require(self.R_s > 0, f"R_s must be > 0 Ohm (got {self.R_s})")
        _require(self.J_m > 0, f"J_m must be > 0 kg m^2 (got {self.J_m})")
        _require(self.B_m >= 0, f"B_m must be >= 0 N m s/rad (got {self.B_m})")
        _require(self.T_m0 >= 0, f"T_m0 must be >= 0 N m (got {self.T_m0})")
        _require(self.omega_eps > 0, f"omega_eps must be > 0 rad/s (got {self.omega_eps})")
        _require(math.isfinite(self.k_wind) and self.k_wind >= 0,
                 f"k_wind must be finite and >= 0 N m s^2/rad^2, 0 = off (got {self.k_wind})")


@dataclass(frozen=True)
class VehicleParams:
    """Vehicle and gear parameters, Table II of the paper (eqs 1-9)."""

    c_r: float = 0.014  #: rolling-resistance coefficient [-] [T2]
    g: float = 9.81  #: gravity [m/s^2] [T2]
    rho_a: float = 1.2041  #: air density [kg/m^3] [T2]
    c_d: float = 0.31  #: drag coefficient [-] [T2]
    A_f: float = 2.11  #: frontal area [m^2] [T2]
    r_w: float = 0.2933  #: wheel radius [m] [T2]
    eta: float = 0.96  #: gear efficiency [-] [T2]
    n_g: float = 12.5  #: gear ratio, motor speed / wheel speed [-] [T2]
    m_v: float = 900.0  #: vehicle mass [kg] [T2]
    v_a: float = 2.0  #: head-wind speed [m/s] [T2] (eq 4 adds it to v_v)
    #: "physical" (default): rolling resistance opposes motion, c_r m g cos(delta)
    #: tanh(v/v_eps), and drag acts along the relative air speed, (v+v_a)|v+v_a|.
    #: "paper": eqs 3-4 literally, rolling resistance always pushes back, even at
    #: standstill, and drag is (v+v_a)^2. Both are equal for v > 0 (all plateaus).
    load_model: str = "physical"
    #: speed scale of the smooth sign of rolling resistance [m/s] [chosen]: 1 cm/s,
    #: far below any driving speed, yet smooth enough for RK4 at 10 kHz.
    v_eps: float = 0.01
    #: how the gear's efficiency eta acts (docs/speed-range.md). "paper" (default): eq 9 as printed,
    #: which the paper obtains by substituting eqs 1-7 into eq 8 (its reference [1], Kamalakkannan's
    #: vehicle model): the reflected mass and every wheel force divided by eta whatever the direction
    #: of the power, so the model also "loses" 1 - eta when the power flows back from the wheels
    #: (braking, downhill): it returns more than the vehicle had (the car's kinetic energy is
    #: 1/2 J_eq omega^2, 1/eta of 1/2 m_v v^2, and a wheel force that pushes the car is amplified by
    #: 1/eta at the shaft). "power_flow": the physical correction, eta in the direction the power
    #: flows through the gear (motoring: the wheels get eta of the shaft's power; regeneration: the
    #: shaft gets eta of the wheels'), ``pmsm_ev.kernels.power_flow_gear``.
    gear_model: str = "paper"

    def validate(self) -> None:
        _require(self.c_r >= 0, f"c_r must be >= 0 (got {self.c_r})")
        _require(self.g > 0, f"g must be > 0 m/s^2 (got {self.g})")
        _require(self.rho_a >= 0, f"rho_a must be >= 0 kg/m^3 (got {self.rho_a})")
        _require(self.c_d >= 0, f"c_d must be >= 0 (got {self.c_d})")
        _require(self.A_f >= 0, f"A_f must be >= 0 m^2 (got {self.A_f})")
        _require(self.r_w > 0, f"r_w must be > 0 m (got {self.r_w})")
        _require(0 < self.eta <= 1, f"eta must be in (0, 1] (got {self.eta})")
        _require(self.n_g > 0, f"n_g must be > 0 (got {self.n_g})")
        _require(self.m_v > 0, f"m_v must be > 0 kg (got {self.m_v})")
        _require(self.load_model in LOAD_MODELS, f"load_model must be one of {LOAD_MODELS} (got {self.load_model!r})")
        _require(self.v_eps > 0, f"v_eps must be > 0 m/s (got {self.v_eps})")
        _require(self.gear_model in GEAR_MODELS, f"gear_model must be one of {GEAR_MODELS} (got {self.gear_model!r})")

    @property
    def reflected_inertia(self) -> float:
        """Vehicle mass reflected to the motor shaft, r_w^2 m_v / (eta n_g^2) [kg m^2] (eq 9)."""
        return self.r_w**2 * self.m_v / (self.eta * self.n_g**2)


def equivalent_inertia(motor: MotorParams, vehicle: VehicleParams) -> float:
    """J_eq = J_m + r_w^2 m_v / (eta n_g^2) [kg m^2], the left side of eq 9 (0.526 by default)."""
    return motor.J_m + vehicle.reflected_inertia


def road_load_coefficients(vehicle: VehicleParams) -> tuple[float, float, float]:
    """The road load on a level road at the motor shaft as coast-down coefficients (T0 [N m], T1 [N m s/rad],
    T2 [N m s^2/rad^2]): T = T0 + T1 omega + T2 omega^2 for omega >= 0 is eqs 3-4's rolling resistance
    c_r m_v g and drag 1/2 rho_a c_d A_f (v + v_a)^2 at v = omega r_w / n_g, through eq 9's r_w / (eta n_g)
    (3.06 N m, 9.03e-4, 5.30e-6 with Table II: 17.19 N m at 1550 rad/s, 131 km/h). The road-load
    coefficients f0, f1, f2 of a coast-down test (UN GTR No. 15, Annex 4) carried to the shaft."""
    k = vehicle.r_w / (vehicle.eta * vehicle.n_g)  # a wheel force's torque at the shaft, eq 9
    w = vehicle.r_w / vehicle.n_g  # v per omega [m/rad]
    drag = 0.5 * vehicle.rho_a * vehicle.c_d * vehicle.A_f
    return (k * (vehicle.c_r * vehicle.m_v * vehicle.g + drag * vehicle.v_a**2),
            k * 2.0 * drag * vehicle.v_a * w, k * drag * w * w)


_ROAD_LOAD = road_load_coefficients(VehicleParams())


# -- the sourced losses of the drive-cycle and speed-range scenarios (docs/speed-range.md, "The losses") ----
#: the motor the geometry is taken from [source]: the 2004 Toyota Prius traction motor, an interior-PM motor
#: of 50 kW ("the motor can deliver a peak-power output of 50 kW over the speed range of 1200-1540 rpm": R. H.
#: Staunton et al., "Evaluation of 2004 Toyota Prius Hybrid Electric Drive System", ORNL/TM-2006/423, 2006,
#: abstract), 8 poles (N = 4, as Table I) and 48 slots, the size of this drive's ~55 kW. Its dimensions as
#: the open-source machine model of it gives them (pyleecan, Eomys/pyleecan, pyleecan/Data/Machine/
#: Toyota_Prius.json, "TOYOTA Prius 2004 interior magnet (V shape) with distributed winding"): stator
#: Rext 0.13462 m, Rint 0.08095 m, L1 0.08382 m, Kf1 0.95 (the stacking factor), 48 slots of type SlotW11
#: (H0 1 mm, W0 1.93 mm, H1 0, W1 5 mm, W2 8 mm, H2 33.3 mm, R1 4 mm); rotor Rext 0.0802 m, its bore (the
#: shaft, Drsh) 0.11064 m. [m]
PRIUS2004 = {"D_so": 2 * 0.13462, "D_si": 2 * 0.08095, "l": 0.08382, "k_stack": 0.95, "D_r": 2 * 0.0802,
             "D_ri": 0.11064, "slots": 48,
             "slot": {"H0": 1e-3, "W0": 1.93e-3, "W1": 5e-3, "W2": 8e-3, "H2": 33.3e-3, "R1": 4e-3}}
#: air at 20 degC and 101.325 kPa [kg/m^3, Pa s]: the ideal gas law, 101325 / (287.05 x 293.15) = 1.204, and
#: Sutherland's law, 1.716e-5 (293.15/273.15)^1.5 (273.15 + 110.4) / (293.15 + 110.4) = 1.81e-5 (warm air in
#: a motor at 80 degC is 17 % lighter and its windage ~15 % lower)
AIR_RHO, AIR_MU = 1.204, 1.81e-5


def _saari_cylinder_cm(re: float, gap_ratio: float) -> float:
    """The torque coefficient C_M of a cylinder turning in a coaxial one (Saari's fits, laminar to
    turbulent, of the Couette flow in the air gap): gap_ratio = 2 delta / D_r, re = rho Omega r delta / mu.
    The two upper regimes (500 < Re < 1e4: 1.03, above: 0.065) are those FAST-OAD_CS23-HE's PMSM model uses
    (perf_windage_friction_coeff.py: 0.515 (e_g / r)^0.3 Re^-0.5 and 0.0325 (e_g / r)^0.3 Re^-0.2 with the
    power c_f pi rho r^4 Omega^3 l, perf_air_gap_windage_losses.py: the same power); the two laminar ones
    below Re = 500 [not checked against a source here] only matter below ~125 rad/s, where the windage is
    below 0.2 W."""
    k = gap_ratio ** 0.3
    if re < 64.0:
        return 10.0 * k / re
    if re < 500.0:
        return 2.0 * k / re ** 0.6
    if re < 1.0e4:
        return 1.03 * k / re ** 0.5
    return 0.065 * k / re ** 0.2


def rotor_windage_power(omega: float, D_r: float, l_r: float, delta: float, D_ri: float = 0.0,
                        rho: float = AIR_RHO, mu: float = AIR_MU) -> float:
    """The air friction of a smooth rotor [W] at omega [rad/s]: its surface, (1/32) C_M pi rho Omega^3 D_r^4 l_r,
    and its two end faces, (1/64) C_M rho Omega^3 (D_r^5 - D_ri^5) = 1/2 C_M rho Omega^3 (r^5 - r_i^5), with
    Saari's moment coefficients C_M for the cylinder (``_saari_cylinder_cm`` of Re_delta = rho Omega (D_r/2)
    delta / mu) and, for the faces, 3.87 / Re_r^0.5 below Re_r = 3e5 and 0.146 / Re_r^0.2 above, Re_r = rho
    Omega (D_r/2)^2 / mu (the coefficients and the face power 0.5 c_f rho Omega^3 R^5 of eMach's windage
    analyser, Severson-Group/eMach, mach_eval/analyzers/general/windage_loss.py, after Riemer, Lessmann,
    Hameyer, ECCE 2010; FAST-OAD_CS23-HE's perf_rotor_windage_loss.py has the same coefficients but a factor pi
    more in the power, which would make the faces' windage pi times larger: eMach's is taken). D_r, l_r, delta,
    D_ri in m (D_ri: the faces' inner diameter, the shaft's)."""
    w = abs(omega)
    if w == 0.0:
        return 0.0
    re_gap = rho * w * 0.5 * D_r * delta / mu
    cm = _saari_cylinder_cm(re_gap, 2.0 * delta / D_r)
    p_cyl = cm * math.pi * rho * w**3 * D_r**4 * l_r / 32.0
    re_r = rho * w * (0.5 * D_r) ** 2 / mu
    cm_face = 3.87 / re_r**0.5 if re_r < 3.0e5 else 0.146 / re_r**0.2
    p_faces = cm_face * rho * w**3 * (D_r**5 - D_ri**5) / 64.0
    return p_cyl + p_faces


def bearing_friction_torque(mu: float, load: float, bore: float) -> float:
    """The friction moment of a rolling bearing [N m] with a constant coefficient of friction, M = 1/2 mu P d
    (JTEKT/Koyo catalogue, "Friction coefficient of bearings": M = mu P d / 2; SKF, "Rolling bearings",
    "Friction", "Estimating the frictional moment", with its table of mu for open bearings): mu the bearing
    type's coefficient, P the bearing's load [N], d the bore [m]."""
    return 0.5 * mu * load * bore


#: the top speed at which the windage coefficient is fitted [rad/s]: 131 km/h at the wheels (acceleration.toml)
WINDAGE_SPEED = 1550.8
#: the rotor's air gap [m]: half the stator bore less the rotor's diameter, (161.9 - 160.4) / 2 = 0.75 mm
PRIUS2004_GAP = 0.5 * (PRIUS2004["D_si"] - PRIUS2004["D_r"])
#: the windage of the reference motor at ``WINDAGE_SPEED`` [W]: ``rotor_windage_power`` with the 2004 Prius
#: rotor (160.4 mm x 83.82 mm, air gap 0.75 mm, faces from its 110.64 mm bore out): 78.7 W on its surface,
#: 62.9 W on its faces, 141.6 W
SOURCED_WINDAGE_POWER = rotor_windage_power(WINDAGE_SPEED, PRIUS2004["D_r"], PRIUS2004["l"], PRIUS2004_GAP,
                                            PRIUS2004["D_ri"])
#: the windage as k_wind omega |omega| [N m s^2/rad^2] (``MotorParams.k_wind``): the power at top speed over
#: its cube, 3.80e-8. Saari's C_M falls as Re^-0.5 there (Re_delta = 6.2e3), so the exact power goes as
#: omega^2.5 and the cubic law under-states it at lower speed (at 500 rad/s 6.4 W against 4.7 W): both are
#: below 0.1 % of the drive's power
SOURCED_K_WIND = SOURCED_WINDAGE_POWER / WINDAGE_SPEED**3
#: the bearings' Coulomb friction [N m] (``MotorParams.T_m0`` with B_m = 0 and load model "physical"): two
#: deep-groove ball bearings, mu = 0.0015 (SKF, "Rolling bearings", "Friction", table 1, "Constant
#: coefficient of friction mu for open bearings": "Deep groove ball bearings 0,0015"; JTEKT/Koyo give
#: 0.0010 to 0.0015), bore d = 35 mm [chosen: a 6207, a common deep-groove size for the shaft of a motor of
#: this power; the Prius's bearings are not in the sources above], P = 250 N each [chosen: a wave spring's
#: axial preload of ~200 N, as motors' deep-groove bearing pairs carry to keep the balls rolling, plus half
#: the rotor's weight, its laminations 6.5 kg by the geometry above, ~9 kg with magnets and shaft]:
#: 2 x 6.6e-3 = 0.0131 N m, 20 W at top speed
SOURCED_T_M0 = 2.0 * bearing_friction_torque(0.0015, 250.0, 0.035)


#: the lamination: 0.35 mm non-oriented fully processed electrical steel of grade M330-35A (EN 10106,
#: IEC 60404-8-4; the name gives 3.30 W/kg, the grade's largest specific total loss at 1.5 T, 50 Hz, and
#: the 0.35 mm thickness [the designation's figure: the standard's table itself not consulted here]); its
#: density 7650 kg/m^3 and resistivity 0.48 uOhm m as stem_material's record of this grade has them
#: (docs.rs stem_material 0.3.4, stem_test_database/src/Material/M330-35A.yaml: "mass_density: 7650.0
#: kg / m^3", "electrical_resistivity: 0.48e-6 Ohm * m", after EMT's "Allgemeine Informationen zu
#: Elektroblechen")
M330_35A = {"P15_50": 3.30, "d": 0.35e-3, "gamma": 7650.0, "rho_e": 0.48e-6}


def lamination_loss_coefficients(lam: dict = M330_35A) -> tuple[float, float]:
    """(k_h [W/(kg Hz T^2)], k_e [W/(kg Hz^2 T^2)]) of the specific loss p = k_h f B^2 + k_e f^2 B^2 of a
    lamination: k_e the classical eddy-current loss of a sheet of thickness d in a sinusoidal field,
    pi^2 d^2 / (6 rho_e gamma) (Steinmetz's separation, textbook), k_h the rest of the grade's loss at
    1.5 T, 50 Hz (hysteresis and the excess loss there): (P15_50 - k_e 50^2 1.5^2) / (50 x 1.5^2)."""
    k_e = math.pi**2 * lam["d"] ** 2 / (6.0 * lam["rho_e"] * lam["gamma"])
    k_h = (lam["P15_50"] - k_e * 50.0**2 * 1.5**2) / (50.0 * 1.5**2)
    return k_h, k_e


def iron_loss_coefficients(mass: float, B_ref: float, psi_ref: float, k_build: float = 1.5,
                           lam: dict = M330_35A) -> tuple[float, float]:
    """(c_h, c_e) of ``PlantParams.iron_c_h``, ``iron_c_e`` for a stator of ``mass`` [kg] of the lamination
    ``lam`` whose flux density is B_ref [T] at the flux linkage psi_ref [Wb] (B = B_ref psi_s / psi_ref),
    with the build factor k_build (punching, rotating fields and harmonics over the Epstein figure):
    P_fe = k_build mass (k_h f + k_e f^2) B^2, f = omega_e / (2 pi), so
    c_h = k_build mass k_h B_ref^2 / (2 pi psi_ref^2), c_e = k_build mass k_e B_ref^2 / (4 pi^2 psi_ref^2)."""
    k_h, k_e = lamination_loss_coefficients(lam)
    b2 = k_build * mass * (B_ref / psi_ref) ** 2
    return k_h * b2 / (2.0 * math.pi), k_e * b2 / (4.0 * math.pi**2)


def slot_w11_area(slot: dict) -> float:
    """The cross-section of a slot of pyleecan's type SlotW11 [m^2]: its opening H0 W0 (H1 = 0: no wedge
    trapezoid) and its winding area 1/2 (W1 + W2) (H2 - R1) + pi R1^2 / 2 + R1 (W2 - 2 R1) (pyleecan,
    pyleecan/Methods/Slot/SlotW11/comp_surface_opening.py and comp_surface_active.py; the opening's arc on
    the bore, below 1e-8 m^2 here, left out)."""
    s_open = slot["H0"] * slot["W0"]
    s_wind = (0.5 * (slot["W1"] + slot["W2"]) * (slot["H2"] - slot["R1"]) + 0.5 * math.pi * slot["R1"] ** 2
              + slot["R1"] * (slot["W2"] - 2.0 * slot["R1"]))
    return s_open + s_wind


#: the stator iron of the reference motor [kg]: the 2004 Prius stator's annulus (269.24 / 161.9 mm) less its
#: 48 slots of 217.5 mm^2 (``slot_w11_area``), over its 83.82 mm stack at the stacking factor 0.95, in
#: M330-35A's 7650 kg/m^3: 15.8 kg
SOURCED_IRON_MASS = ((0.25 * math.pi * (PRIUS2004["D_so"] ** 2 - PRIUS2004["D_si"] ** 2)
                      - PRIUS2004["slots"] * slot_w11_area(PRIUS2004["slot"]))
                     * PRIUS2004["l"] * PRIUS2004["k_stack"] * M330_35A["gamma"])
#: (c_h, c_e) of the drive-cycle and speed-range scenarios: ``iron_loss_coefficients`` of
#: ``SOURCED_IRON_MASS`` with B_ref = 1.5 T at Table I's psi = 0.08975 Wb [chosen: a PM motor's no-load flux
#: density lies near 1.5 T in the stator iron, above it in the teeth, below it in the yoke; one figure for
#: both] and k_build = 1.5 [chosen: punching, pressing, rotating fields and the PWM's harmonics raise a
#: stator's losses over the grade's Epstein figure; a factor of 1.5]: see their values in
#: docs/speed-range.md (28.0 and 9.19e-3). At no load, 6000 rpm: 1.03 kW; at top speed in field weakening
#: (psi_s ~ 0.034 Wb): ~0.6 kW
SOURCED_IRON = iron_loss_coefficients(SOURCED_IRON_MASS, 1.5, 0.08975)

#: reference temperature of Table I's R_s and psi [degC] [chosen]: data-sheet values are
#: usually given at 20-25 degC; 20 degC, the reference of copper's alpha = 0.00393 1/K
TEMPERATURE_REF = 20.0


def winding_resistance(R_s20: float, T: float, alpha_R: float) -> float:
    """R_s(T) = R_s20 (1 + alpha_R (T - 20 degC)) [Ohm]: copper's linear law
    (``pmsm_ev.kernels.winding_resistance``, which the thermal model uses at every step)."""
    return kernel_winding_resistance(R_s20, T, alpha_R, TEMPERATURE_REF)


def magnet_flux(psi20: float, T: float, alpha_psi: float) -> float:
    """psi(T) = psi20 (1 + alpha_psi (T - 20 degC)) [V s/rad]: the remanence's linear law."""
    return psi20 * (1.0 + alpha_psi * (T - TEMPERATURE_REF))


# -- the battery (off by default: the DC link is an ideal source of PlantParams.v_dc) -------------------------------
#: the ideal link or the battery's equivalent circuit (``BatteryParams.battery``)
BATTERY_MODELS = ("ideal", "ecm")
#: the most points of the open-circuit voltage table (``pmsm_ev.kernels.BAT_OCV_MAX``)
BATTERY_OCV_POINTS = 24


def parse_table(text: str, name: str) -> tuple[float, ...]:
    """The numbers of a comma-separated table (``BatteryParams.bat_ocv_soc``, ``bat_ocv_v``); ``ParameterError``
    names ``name`` when an entry is not a finite number."""
    values = []
    for item in str(text).split(","):
        try:
            value = float(item)
        except ValueError:
            raise ParameterError(f"{name}: {item.strip()!r} is not a number (a comma-separated table)") from None
        _require(math.isfinite(value), f"{name}: {item.strip()!r} is not finite")
        values.append(value)
    return tuple(values)


@dataclass(frozen=True)
class BatteryParams:
    """The traction battery that feeds the DC link (docs/speed-range.md, "The battery"), off by default: the DC link
    is then an ideal source of ``PlantParams.v_dc``, as in the paper's scenarios.

    "ecm": a Thevenin equivalent circuit, v = OCV(soc) - R0 i - v_rc, C1 dv_rc/dt = i - v_rc / R1, the state of
    charge falling with the charge drawn, soc = soc0 - integral(i) / capacity (coulombic efficiency 1), inside the
    plant FMU (``pmsm_ev.kernels.battery_step``). The pack is a 2013 Nissan Leaf's: 48 modules of 2s2p cells,
    96s2p, 192 cells ("The 24 kWh Leaf battery pack has 48 modules. Each module has 4 cells. Each module's cells
    are in two pairs. Each pair is in parallel. The two pairs are in series.", "The fully charged voltage is
    403.2 volts with a nominal voltage of 360 volts": mobility.lk, "Leaf 24 kWh Battery", 2021). Its cell's
    figures are fitted here to ORNL's hybrid-pulse (HPPC) test of the 2013 Leaf cell at 25 degC
    (batterysim/equiv-circ-model, examples/data/cell-low-current-hppc-25c-2.csv, MIT licence: a full charge to
    4.2 V, then per 10 % of charge an hour's rest, a 30 A discharge pulse of 30 s, a 22 A charge pulse of 10 s
    and 3 Ah at 10 A, to 3.0 V): the rest voltages are the open-circuit voltages, the 30 A pulses fitted by
    least squares with v = OCV - R0 i - R1 i (1 - exp(-t / tau)) at 1 s samples (R0 then holds what happens
    within the first second); a cell discharged 30.50 Ah to 3.0 V. The pack: 96 x the cell's voltages, 48 x its
    resistances, 2 x its capacity, C1 = tau / R1."""

    #: the DC link: "ideal" (default; ``PlantParams.v_dc``, constant) or "ecm" (this equivalent circuit)
    battery: str = "ideal"
    #: state of charge at the start [-], in [0, 1] [chosen: 0.9, a car charged to 90 %, the WLTP's
    #: "fully charged" less the margin most EVs keep]
    bat_soc0: float = 0.9
    #: capacity [Ah]: 2 x 30.50 Ah, the cell's charge from 4.2 V to 3.0 V in ORNL's HPPC test at 10 A (C/3), 25 degC
    #: (the cell's rating is 33.1 Ah: batterysim/equiv-circ-model, examples/cell/params.py); 61.0 Ah x ~375 V
    #: = 22.9 kWh, of the Leaf's 24 kWh
    bat_capacity: float = 61.0
    #: the open-circuit voltage table's states of charge [-], comma-separated, rising from 0 to 1: the HPPC test's
    #: rest points by coulomb counting from the full charge (1) and 0 at its end of discharge
    bat_ocv_soc: str = "0, 0.0610, 0.1653, 0.2697, 0.3740, 0.4783, 0.5826, 0.6869, 0.7912, 0.8956, 1"
    #: ... its open-circuit voltages [V], rising: 96 x the cell's rest voltage at the end of each hour's rest (3.531,
    #: 3.723, 3.802, 3.869, 3.909, 3.949, 3.984, 4.048, 4.086 V from 6 % to 90 %, 4.182 V at 100 %); at 0, 96 x
    #: 3.00 V [chosen: the test's end of discharge under 10 A, a lower bound of the open-circuit voltage there]
    bat_ocv_v: str = ("288.0, 338.976, 357.408, 364.992, 371.424, 375.264, 379.104, 382.464, 388.608, 392.256, "
                      "401.472")
    #: series resistance R0 [Ohm]: 48 x 1.60 mOhm, the median of the cell's fits from 10 % to 90 % (1.58 .. 1.64
    #: mOhm; 1.85 at 100 %, 1.70 at 6 %)
    bat_R0: float = 0.0768
    #: the RC pair's resistance R1 [Ohm]: 48 x 1.34 mOhm, the median of the fits from 10 % to 90 % (1.08 .. 1.74)
    bat_R1: float = 0.0643
    #: the RC pair's capacitance C1 [F]: tau / R1 with tau = 25 s, the median of the fits (19.5 .. 29.5 s)
    bat_C1: float = 389.0
    #: discharge current limit [A] [chosen: 250 A, ~4 C of the 61 Ah pack, a power cell's 10 s rating; 90 kW at
    #: 360 V, above the ~55 kW this drive draws at its peak]
    bat_i_discharge_max: float = 250.0
    #: charge current limit [A] [chosen: 125 A, ~2 C, the order of a power cell's pulse charge rating; ~49 kW at
    #: 390 V, the drive's former constant regenerative limit of 50 kW]
    bat_i_charge_max: float = 125.0
    #: the terminal voltage a charge current may raise the pack to [V]: 96 x 4.2 V = 403.2 V, the fully charged
    #: voltage (mobility.lk, above)
    bat_v_max: float = 403.2
    #: the terminal voltage a discharge current may lower it to [V]: 96 x 3.0 V, the HPPC test's end of discharge
    bat_v_min: float = 288.0
    #: above this state of charge the charge current limit falls linearly to 0 at 1 [-] [chosen: 0.95, a battery
    #: management system's taper near full; regeneration then refused, the friction brake takes it]
    bat_soc_taper: float = 0.95

    @property
    def enabled(self) -> bool:
        return self.battery == "ecm"

    def ocv_table(self) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """(states of charge, open-circuit voltages) of the table, as numbers."""
        return parse_table(self.bat_ocv_soc, "bat_ocv_soc"), parse_table(self.bat_ocv_v, "bat_ocv_v")

    def validate(self) -> None:
        _require(self.battery in BATTERY_MODELS,
                 f"battery must be one of {BATTERY_MODELS} (got {self.battery!r})")
        _require(math.isfinite(self.bat_capacity) and self.bat_capacity > 0,
                 f"bat_capacity must be > 0 Ah (got {self.bat_capacity})")
        _require(math.isfinite(self.bat_soc0) and 0.0 <= self.bat_soc0 <= 1.0,
                 f"bat_soc0 must be in [0, 1] (got {self.bat_soc0})")
        for name in ("bat_R0", "bat_R1"):
            value = getattr(self, name)
            _require(math.isfinite(value) and value >= 0, f"{name} must be finite and >= 0 Ohm (got {value})")
        _require(math.isfinite(self.bat_C1) and self.bat_C1 > 0, f"bat_C1 must be > 0 F (got {self.bat_C1})")
        for name in ("bat_i_discharge_max", "bat_i_charge_max"):
            value = getattr(self, name)
            _require(math.isfinite(value) and value >= 0, f"{name} must be finite and >= 0 A (got {value})")
        _require(math.isfinite(self.bat_soc_taper) and 0.0 <= self.bat_soc_taper < 1.0,
                 f"bat_soc_taper must be in [0, 1) (got {self.bat_soc_taper})")
        socs, volts = self.ocv_table()
        _require(len(socs) == len(volts),
                 f"bat_ocv_soc and bat_ocv_v must have as many points (got {len(socs)} and {len(volts)})")
        _require(2 <= len(socs) <= BATTERY_OCV_POINTS,
                 f"the open-circuit voltage table must have 2 to {BATTERY_OCV_POINTS} points (got {len(socs)})")
        _require(socs[0] == 0.0 and socs[-1] == 1.0,
                 f"bat_ocv_soc must run from 0 to 1 (got {socs[0]:g} .. {socs[-1]:g})")
        _require(all(b > a for a, b in zip(socs, socs[1:])), "bat_ocv_soc is not monotonic: it must rise")
        _require(volts[0] > 0, f"bat_ocv_v must be > 0 V (got {volts[0]:g} at a state of charge of 0)")
        _require(all(b > a for a, b in zip(volts, volts[1:])),
                 "bat_ocv_v (the open-circuit voltage table) is not monotonic: it must rise with the state of charge")
        for name in ("bat_v_max", "bat_v_min"):
            value = getattr(self, name)
            _require(math.isfinite(value) and value > 0, f"{name} must be > 0 V (got {value})")
        _require(self.bat_v_min < self.bat_v_max,
                 f"bat_v_min ({self.bat_v_min:g} V) must be below bat_v_max ({self.bat_v_max:g} V)")


@dataclass(frozen=True)
class PlantParams:
    """Numerical and initial-state settings of the plant (vehicle + PMSM)."""

    #: RK4 sub-steps per communication step [-] [chosen]: at 200 rad/s the electrical
    #: angle turns 0.08 rad per 1e-4 s step; one RK4 step has a local error ~1e-8 of
    #: that, so 1 is accurate; raise it for larger communication steps.
    rk4_substeps: int = 1
    #: the largest electrical angle one RK4 sub-step may turn [rad] [chosen]: a step takes
    #: max(rk4_substeps, ceil(N |omega_m| dt / substep_angle)) sub-steps, so the plant stays accurate
    #: at top speed (1554 rad/s turns 0.62 rad per 1e-4 s period: 7 sub-steps; RK4's local error on
    #: the rotation is ~(0.1)^5 / 120 = 8e-8 of a sub-step's). 0.1 rad keeps one sub-step up to
    #: 250 rad/s at 10 kHz (the paper's scenarios run as before); 0 = off (always rk4_substeps).
    substep_angle: float = 0.1
    #: how the plant integrates its winding over a step (docs/performance.md, "The plant's integrator").
    #: "rk4_rotor" (default; the paper's scenarios): RK4 in the rotor's dq frame, the currents (or, with the
    #: algebraic flux model, the flux linkages) as the state, sub-steps bounded by ``substep_angle``: the held
    #: stationary-frame voltage turns in that frame, so the sub-steps, and the cost, grow with the speed.
    #: "rk6_stationary" (the drive-cycle scenarios): Butcher's RK6 on the flux linkages (psi_alpha, psi_beta) in
    #: the stationary frame, where the held voltage is constant, the currents explicit functions of them at the
    #: integrated angle: order 6, seven stages, one sub-step (``rk4_substeps`` at least) up to
    #: ``stationary_substep_angle`` of electrical angle a sub-step (148 km/h at 1e-4 s); ``substep_angle`` unused
    integrator: str = "rk4_rotor"
    #: the largest electrical angle one sub-step of the stationary-frame RK6 may turn [rad] [chosen]
    #: (``integrator`` 'rk6_stationary'; default ``pmsm_ev.kernels.STATIONARY_SUBSTEP_ANGLE``, its reasons there)
    stationary_substep_angle: float = STATIONARY_SUBSTEP_ANGLE
    i_d0: float = 0.0  #: initial d current [A]
    i_q0: float = 0.0  #: initial q current [A]
    omega_m0: float = 0.0  #: initial mechanical speed [rad/s] (start-up from standstill)
    theta_e0: float = 0.0  #: initial electrical angle [rad] (the observer has its own guess)

    # -- current sensors (all off by default: the paper's measurements are exact) ------
    #: white noise on each measured phase current, standard deviation [A]; 0 = off
    sensor_noise: float = 0.0
    #: seed of the sensor noise [-]: the same seed gives the same noise sequence
    sensor_seed: int = 1
    sensor_offset_a: float = 0.0  #: offset of the phase-a current sensor [A]
    sensor_offset_b: float = 0.0  #: offset of the phase-b current sensor [A]
    sensor_gain_a: float = 1.0  #: gain of the phase-a current sensor [-] (1 = exact)
    sensor_gain_b: float = 1.0  #: gain of the phase-b current sensor [-] (1 = exact)
    #: ADC resolution [bits]; 0 = no quantisation
    adc_bits: int = 0
    #: ADC full scale [A]: the converter spans -adc_range..+adc_range (LSB = 2 range / 2^bits)
    adc_range: float = 1000.0

    # -- inverter (ideal by default) ---------------------------------------------------
    #: DC-link voltage [V]; the voltage vector is limited to the linear range v_dc/sqrt(3).
    #: 0 = ideal inverter, no limit.
    v_dc: float = 0.0
    #: switching (PWM) period T_s of the inverter [s]: the dead time takes v_dc t_d / T_s from each
    #: phase and the inverter delay counts it, whatever the plant's communication step. 1e-4 s: the
    #: drive's control period (10 kHz, the paper's step), the inverter updating its PWM once a period.
    switching_period: float = 1e-4
    #: actuation delay [switching periods], 0 or 1: with 1 the voltage received at t is applied
    #: from t + switching_period on (the computation delay of a real drive: one PWM period), rounded
    #: to whole communication steps of the plant.
    inverter_delay: int = 0
    #: dead time of each inverter leg [s]; 0 = off. Each phase's pole voltage loses
    #: v_dc t_d / T_s tanh(i_x / dead_time_i0) (T_s = ``switching_period``;
    #: ``pmsm_ev.kernels.dead_time_error``), so it needs v_dc > 0. Typical size: 1-3 us for
    #: IGBT inverters of this power class (2 us at 10 kHz and 360 V is 7.2 V per phase, 2 % of
    #: v_dc: the back-EMF at 20 rad/s).
    dead_time: float = 0.0
    #: current scale of the dead time's soft sign [A] [chosen]: the error builds up as the phase
    #: current charges the switches' output capacitance within the dead time, i0 ~ C_oss v_dc / t_d
    #: = 10 nF x 360 V / 2 us = 1.8 A for a module of this size: 2 A.
    dead_time_i0: float = 2.0
    #: the inverter's conduction and switching losses (``pmsm_ev.kernels.inverter_loss``,
    #: ``inverter_modulation_loss``), drawn from the DC link only (the winding's voltage is unchanged); off
    #: by default (the paper's inverter is ideal). A phase current flows through the IGBT of its leg for the
    #: duty d (i > 0; 1 - d for i < 0) and through the opposite diode for the rest: each phase loses
    #: d (V_CE0 |i| + r_CE i^2) + (1 - d) (V_F0 |i| + r_F i^2) + f_sw inv_e_sw v_dc / (inv_v_ref inv_i_ref) |i|,
    #: f_sw = 1 / switching_period; needs v_dc > 0. The figures are for one module, Infineon's HybridPACK 1
    #: FS400R07A1E3 (final data sheet V3.4, 2018-08-09, page 1: "HybridPACK 1 module with Trench/Fieldstop
    #: IGBT3 and Emitter Controlled 3 diode and NTC", "VCES = 650V", "IC nom = 400A", "Optimized for
    #: automotive applications with DC link voltages up to 420V", T_vj op = 150 degC), at T_vj = 150 degC,
    #: where the losses are largest. Its characteristic-value tables were not at hand: V_CEsat = 1.45 V typical is
    #: the module's headline figure as its distributors quote it (slw-ele.com, FS400R07A1E3: "an extremely
    #: low VCE(sat) of 1.45V (typ)"; its conditions not stated there, taken as I_C nom = 400 A, 25 degC);
    #: every other figure below is [chosen] and should give way to the data sheet's tables;
    #: docs/speed-range.md
    inverter_losses: bool = False
    #: the IGBT's knee V_CE0 [V] (the straight-line model V_CE = V_CE0 + r_CE i of the output characteristic
    #: at V_GE = 15 V, T_vj = 150 degC: its intercept) [chosen]: 0.70 V, the knee of a silicon IGBT's
    #: collector junction at 150 degC
    inv_v0: float = 0.70
    #: the IGBT's slope r_CE [Ohm]: (V_CEsat - V_CE0) / I_C = (1.65 V - 0.70 V) / 400 A = 2.375 mOhm, with
    #: V_CEsat = 1.65 V at 400 A, 150 degC [chosen: the 1.45 V at 25 degC above raised by the 13 % a 650 V
    #: Infineon trench-field-stop module's typical V_CEsat rises from 25 to 150 degC at its rated current,
    #: FS200R07N3E4R (IGBT4), technical information rev. 2.0, 2013-11-05: 1.55 V at 25 degC, 1.75 V at 150 degC;
    #: 1.64 V, rounded up]
    inv_r_on: float = 2.375e-3
    #: the diode's knee V_F0 [V] (V_F = V_F0 + r_F i, the forward characteristic at T_vj = 150 degC: its
    #: intercept) [chosen]: 0.80 V, a silicon pin diode's knee, a little above the IGBT's
    inv_vf0: float = 0.80
    #: the diode's slope r_F [Ohm]: (V_F - V_F0) / I_F = (1.45 V - 0.80 V) / 400 A = 1.625 mOhm, with
    #: V_F = 1.45 V at 400 A, 150 degC [chosen: an emitter-controlled diode's forward voltage at the module's
    #: rated current, of the order of its IGBT's V_CEsat and falling a little with temperature]
    inv_r_f: float = 1.625e-3
    #: switching energy per switching period of one leg, E_on + E_off (IGBT) + E_rec (diode) [J] at
    #: inv_v_ref and inv_i_ref [chosen]: 28.5 mJ at 300 V, 400 A, 150 degC, the order of a 650 V / 400 A
    #: trench-field-stop module's typical switching energies at its rated current (tens of mJ; the data
    #: sheet's switching table should replace it); scaled linearly with the current and the DC voltage
    #: (D. Graovac, M. Puerschel, "IGBT Power Losses Calculation Using the Data-Sheet Parameters", Infineon
    #: application note, 2009)
    inv_e_sw: float = 0.0285
    inv_v_ref: float = 300.0  #: DC voltage at which inv_e_sw is given [V] [chosen: its reference point]
    inv_i_ref: float = 400.0  #: current at which inv_e_sw is given [A] (the module's rated current, I_C nom)

    # -- iron losses (off by default: the paper's motor has none) ------------------------------
    #: hysteresis coefficient c_h of the iron losses P_fe = (c_h |omega_e| + c_e omega_e^2) psi_s^2,
    #: psi_s^2 = psi_d^2 + psi_q^2 (Steinmetz's loss separation, ``pmsm_ev.kernels.iron_torque``), taken
    #: from the shaft as a drag [W / (rad/s Wb^2)]; 0 = off. The drive-cycle and speed-range scenarios take
    #: ``SOURCED_IRON`` (``iron_loss_coefficients``: a 0.35 mm M330-35A lamination's grade figure and
    #: classical eddy currents on the stator iron of the 2004 Prius motor; docs/speed-range.md)
    iron_c_h: float = 0.0
    #: eddy-current coefficient c_e [W / ((rad/s)^2 Wb^2)]; 0 = off; see ``iron_c_h``
    iron_c_e: float = 0.0

    # -- magnetic saturation (off by default: Table I's constant inductances) ------------
    #: saturation current of the q axis [A]; 0 = off (linear). Flux psi_q = L_q i_q / (1 +
    #: |i_q| / sat_i_q) (Froehlich-Kennelly curve, ``pmsm_ev.kernels.saturated_flux``): the
    #: apparent inductance falls to 1/(1 + i/I_sat). Typical size: the q inductance of EV
    #: interior-PM motors falls by 30-50 % from no load to rated current; 900 A gives -31 % (apparent),
    #: -51 % (incremental) at the 400 A limit, -21 % at the 234 A of the 22 deg plateau.
    sat_i_q: float = 0.0
    #: saturation current of the d axis [A]; 0 = off. Same form around the magnet's flux, psi_d =
    #: psi + L_d i_d / (1 + |i_d| / sat_i_d); the magnet already biases the d path, so its
    #: self-saturation with i_d is the smaller (typical: 2-3x sat_i_q). No cross-saturation.
    sat_i_d: float = 0.0

    # -- the algebraic magnetic model (off by default: flux_model "linear") ----------------------
    #: the plant's magnetic model. "linear" (default): eqs 10-12 with Table I's constant inductances, or
    #: with ``sat_i_q``/``sat_i_d`` the per-axis saturation above. "algebraic": flux linkages psi_d(i_d, i_q),
    #: psi_q(i_d, i_q) with self- and cross-saturation and the magnet's asymmetry (positive i_d adds to the
    #: magnet's flux and saturates the d path, negative i_d relieves it), the algebraic magnetic model of
    #: Hinkkanen et al. (IEEE Trans. Ind. Appl. 53(3), 2017) with the magnet as an equivalent current
    #: i_f on the d axis (Awan et al., IEEE Trans. Ind. Appl. 54(6), 2018), current as an explicit
    #: function of flux (``pmsm_ev.kernels.flux_currents``), reciprocal (it derives from an energy), so
    #: the energy balance closes. Table I's L_d, L_q are its incremental inductances at zero current
    #: (the unloaded motor is the data sheet's), the magnet's psi (with ``T_magnet``) its flux there;
    #: the fields below give the saturation's shape (``flux_model_coefficients``; docs/sensorless.md,
    #: "The plant's flux model")
    flux_model: str = "linear"
    #: the q current at which ``flux_q_ratio`` is given [A] [chosen]: 400 A, the drive's current limit
    #: (``ControllerParams.i_q_max``, ``i_max``): the far end of what injection must work with
    flux_q_current: float = 400.0
    #: the incremental q inductance at (i_d, i_q) = (0, flux_q_current) over L_q [-] [chosen]: 0.5. The q
    #: inductance of EV interior-PM motors falls by 30-50 % from no load to rated current (apparent
    #: inductance; the incremental one, the slope, falls further); 0.5 is the incremental fall of the
    #: per-axis model's typical size (``sat_i_q`` = 900 A: -51 % incremental at 400 A), so both models
    #: describe the same motor on the q axis; 1 = no q saturation
    flux_q_ratio: float = 0.5
    #: the d current at which ``flux_d_asymmetry`` is given [A] [chosen]: 200 A, half the current limit,
    #: the order of the pulses of a polarity detection
    flux_d_current: float = 200.0
    #: the magnet's asymmetry: (L_dd(-flux_d_current, 0) - L_dd(+flux_d_current, 0)) / L_d [-] [chosen]: 0.10.
    #: Positive i_d adds to the magnet's flux and saturates the d path (lower incremental L_d), negative i_d
    #: relieves it (higher); the high-frequency polarity detection of IPMSMs relies on that difference,
    #: reported as a few percent up to ~15 % between plus and minus rated d current: 10 % is its middle.
    #: 0 = none (the d axis linear)
    flux_d_asymmetry: float = 0.10
    #: cross-saturation: the fall of psi_d at (i_d, i_q) = (0, flux_q_current) below the magnet's psi [-]
    #: [chosen]: 0.05. The q current saturates the d path it shares (the teeth and the bridges), so the
    #: magnet's flux linkage falls with load; flux maps of IPMSMs show a few to ~10 % at rated current.
    #: 0 = no cross-saturation
    flux_cross: float = 0.05
    #: the exponents S (d self-saturation), T (q), U, V (cross) of the model [-]: 4, 6, 1, 1, those Lelli,
    #: Hinkkanen and Giulii Capponi fit to the measured flux maps of a 5.5 kW PM-assisted synchronous
    #: reluctance motor with its magnets on the d axis, as here ("A saturation model based on a simplified
    #: equivalent magnetic circuit for permanent magnet machines", TechRxiv 2024, doi
    #: 10.36227/techrxiv.171332345.53790692; its bridge term left out): the q axis, the iron path, keeps
    #: its inductance up to a knee and then falls steeply (T = 6), the d axis, through the magnet, bends
    #: gently (S = 4). (Hinkkanen et al.'s synchronous reluctance motor, no magnet, has 5, 1, 1, 0.)
    #: S > 0, T > 0, U, V >= 0
    flux_S: float = 4.0
    flux_T: float = 6.0  #: see ``flux_S``
    flux_U: float = 1.0  #: see ``flux_S``
    flux_V: float = 1.0  #: see ``flux_S``

    # -- temperature (constant over a run, unless thermal_R > 0 heats the winding or thermal_model 'lptn' both) --
    #: winding temperature [degC] (at the start, with the thermal model); Table I's R_s is taken at
    #: ``TEMPERATURE_REF`` (20 degC). R_s(T) = R_s (1 + alpha_R (T - 20)). Typical: 20 (cold) .. 120
    #: degC (hot, +39 % R_s).
    T_winding: float = TEMPERATURE_REF
    #: magnet temperature [degC]; Table I's psi at 20 degC. psi(T) = psi (1 + alpha_psi (T - 20)).
    #: Typical: 20 .. 100 degC (-10 % psi for NdFeB).
    T_magnet: float = TEMPERATURE_REF
    #: thermal resistance winding -> coolant [K/W]; 0 = off (T_winding stays at its start value).
    #: On: C_th dT/dt = P_cu - (T - T_ambient) / R_th, P_cu = k_dq R_s(T) (i_d^2 + i_q^2) in the dq
    #: convention's power scaling (``MotorParams.k_dq``: 1 for "paper", as eq 12 without 3/2), R_s
    #: following T each step.
    #: Typical: 0.02-0.1 K/W for a liquid-cooled EV motor's winding (100 K at 1-5 kW of copper loss).
    thermal_R: float = 0.0
    #: heat capacity of the winding [J/K] [chosen]: ~5 kg of copper and insulation, 2000 J/K;
    #: with thermal_R = 0.05 K/W a time constant of 100 s
    thermal_C: float = 2000.0
    #: coolant (ambient) temperature of the thermal model [degC]
    T_ambient: float = TEMPERATURE_REF
    #: temperature coefficient of the copper's resistance [1/K]: 0.00393 (annealed copper at
    #: 20 degC, IEC 60028)
    alpha_R: float = 0.00393
    #: temperature coefficient of the magnet's remanence, hence of psi [1/K]: -0.0012 (sintered
    #: NdFeB, -0.09 .. -0.12 %/K in makers' data sheets; the upper end for high-coercivity grades)
    alpha_psi: float = -0.0012

    # -- the motor's thermal network (off by default: the temperatures above are constants) ------------------------
    #: "off" (default: T_winding, T_magnet constant, or the one-node winding of ``thermal_R``) or "lptn": the
    #: four-node lumped-parameter thermal network of Wallscheid and Boecker, "Global identification of a low-order
    #: lumped-parameter thermal network for permanent magnet synchronous motors", IEEE Trans. Energy Convers. 31(1),
    #: 2016, pp. 354-365, identified on a 60 kW automotive interior-PM motor with a water jacket: nodes stator yoke,
    #: stator tooth, winding (start ``T_winding``, the yoke and tooth too: a soaked motor) and magnet (start
    #: ``T_magnet``); the copper losses heat the winding, the residual ones (iron and friction) the stator and the
    #: rotor (``lptn_rotor_share``); R_s follows the winding, psi the magnet (``pmsm_ev.kernels.thermal_network_step``;
    #: docs/speed-range.md, "A motor that warms"). Figures below: the paper's identified network (its table of
    #: parameters; as reimplemented in public code, not re-derived here)
    thermal_model: str = "off"
    lptn_C_yoke: float = 5590.0  #: heat capacity of the stator yoke's node [J/K] (Wallscheid and Boecker 2016)
    lptn_C_tooth: float = 2910.0  #: ... of the stator tooth's node [J/K] (idem)
    lptn_C_winding: float = 2620.0  #: ... of the winding's node [J/K] (idem)
    lptn_C_magnet: float = 10800.0  #: ... of the magnet's node: the rotor [J/K] (idem)
    lptn_R_yoke_coolant: float = 0.017  #: thermal resistance yoke -> coolant, the water jacket [K/W] (idem)
    lptn_R_yoke_winding: float = 0.289  #: ... yoke -> winding [K/W] (idem)
    lptn_R_yoke_tooth: float = 0.013  #: ... yoke -> tooth [K/W] (idem)
    lptn_R_tooth_winding: float = 0.019  #: ... tooth -> winding, through the slot liner [K/W] (idem)
    lptn_R_tooth_magnet: float = 0.599  #: ... tooth -> magnet, across the air gap [K/W] (idem)
    lptn_R_winding_magnet: float = 1.149  #: ... winding -> magnet, the end windings' air [K/W] (idem)
    #: ... magnet -> ambient, the shaft and the housing's air [K/W] (idem); its far end taken at the coolant's
    #: temperature ``T_ambient`` [chosen: one boundary temperature; with 2.451 K/W it carries a few % of the heat]
    lptn_R_magnet_ambient: float = 2.451
    #: the residual losses' (iron and friction) share that heats the rotor's node [-]: 1 - k_1 of the paper's loss
    #: split k_1 = 0.719 - 0.059 i + 0.069 n - 0.619 i n (i, n the current and speed over their maxima) at light load
    #: (i, n -> 0), the drive cycles' usual point [chosen: the constant share, not the paper's function of i and n]
    lptn_rotor_share: float = 0.281
    #: the stator's share of the residual losses that heats the yoke, the rest the tooth [-]: the paper's
    #: k_2 = 0.742 - 0.213 i - 0.023 n - 0.474 i n at light load [chosen, as ``lptn_rotor_share``]
    lptn_yoke_share: float = 0.742
    #: the winding's temperature limit [degC]: thermal class 180 (H) of IEC 60085, the enamelled wire and slot
    #: insulation of EV traction motors [chosen: class H; the network's winding node is a mean, the hot spot runs
    #: hotter, so this is the mean's limit only as a first check]
    T_winding_max: float = 180.0
    #: the magnet's maximum temperature [degC]: a sintered NdFeB grade's maximum working temperature, 150 degC for
    #: the "SH" coercivity class in makers' grade tables (N 80, M 100, H 120, SH 150, UH 180, EH 200) [chosen: SH,
    #: a common traction grade; beyond it the magnet risks irreversible demagnetisation at peak stator current]
    T_magnet_max: float = 150.0

    def validate(self) -> None:
        _require(self.rk4_substeps >= 1 and float(self.rk4_substeps).is_integer(),
                 f"rk4_substeps must be a whole number >= 1 (got {self.rk4_substeps})")
        _require(math.isfinite(self.substep_angle) and self.substep_angle >= 0,
                 f"substep_angle must be >= 0 rad, 0 = off (got {self.substep_angle})")
        _require(self.integrator in INTEGRATORS,
                 f"integrator must be one of {INTEGRATORS} (got {self.integrator!r})")
        _require(math.isfinite(self.stationary_substep_angle) and self.stationary_substep_angle > 0,
                 f"stationary_substep_angle must be > 0 rad (got {self.stationary_substep_angle})")
        for name in ("i_d0", "i_q0", "omega_m0", "theta_e0", "sensor_offset_a", "sensor_offset_b"):
            _require(math.isfinite(getattr(self, name)), f"{name} must be finite")
        _require(math.isfinite(self.sensor_noise) and self.sensor_noise >= 0,
                 f"sensor_noise must be >= 0 A (got {self.sensor_noise})")
        _require(float(self.sensor_seed).is_integer() and self.sensor_seed >= 0,
                 f"sensor_seed must be a whole number >= 0 (got {self.sensor_seed})")
        for name in ("sensor_gain_a", "sensor_gain_b"):
            _require(math.isfinite(getattr(self, name)) and getattr(self, name) > 0,
                     f"{name} must be > 0 (got {getattr(self, name)})")
        _require(float(self.adc_bits).is_integer() and 0 <= self.adc_bits <= 32,
                 f"adc_bits must be a whole number in 0..32 (got {self.adc_bits})")
        _require(math.isfinite(self.adc_range) and self.adc_range > 0,
                 f"adc_range must be > 0 A (got {self.adc_range})")
        _require(math.isfinite(self.v_dc) and self.v_dc >= 0, f"v_dc must be >= 0 V (got {self.v_dc})")
        _require(math.isfinite(self.switching_period) and self.switching_period > 0,
                 f"switching_period must be > 0 s (got {self.switching_period})")
        _require(self.inverter_delay in (0, 1),
                 f"inverter_delay must be 0 or 1 switching periods (got {self.inverter_delay})")
        _require(math.isfinite(self.dead_time) and self.dead_time >= 0,
                 f"dead_time must be >= 0 s (got {self.dead_time})")
        _require(self.dead_time == 0 or self.v_dc > 0,
                 f"dead_time = {self.dead_time} s needs the DC-link voltage: set v_dc > 0 V")
        _require(math.isfinite(self.dead_time_i0) and self.dead_time_i0 > 0,
                 f"dead_time_i0 must be > 0 A (got {self.dead_time_i0})")
        for name in ("inv_v0", "inv_r_on", "inv_vf0", "inv_r_f", "inv_e_sw"):
            value = getattr(self, name)
            _require(math.isfinite(value) and value >= 0, f"{name} must be finite and >= 0 (got {value})")
        for name in ("inv_v_ref", "inv_i_ref"):
            value = getattr(self, name)
            _require(math.isfinite(value) and value > 0, f"{name} must be > 0 (got {value})")
        for name in ("iron_c_h", "iron_c_e"):
            value = getattr(self, name)
            _require(math.isfinite(value) and value >= 0, f"{name} must be finite and >= 0, 0 = off (got {value})")
        _require(not self.inverter_losses or self.v_dc > 0,
                 "inverter_losses needs the DC-link voltage (the switching losses scale with it): set v_dc > 0 V")
        for name in ("sat_i_q", "sat_i_d"):
            value = getattr(self, name)
            _require(math.isfinite(value) and value >= 0, f"{name} must be >= 0 A, 0 = off (got {value})")
        _require(self.flux_model in FLUX_MODELS,
                 f"flux_model must be one of {FLUX_MODELS} (got {self.flux_model!r})")
        _require(self.flux_model == "linear" or (self.sat_i_q == 0 and self.sat_i_d == 0),
                 f"flux_model {self.flux_model!r} has its own saturation: set sat_i_q = sat_i_d = 0 (they are the "
                 f"linear model's)")
        for name in ("flux_q_current", "flux_d_current"):
            value = getattr(self, name)
            _require(math.isfinite(value) and value > 0, f"{name} must be > 0 A (got {value})")
        _require(math.isfinite(self.flux_q_ratio) and 0 < self.flux_q_ratio <= 1,
                 f"flux_q_ratio must be in (0, 1]: saturation lowers the incremental L_q (got {self.flux_q_ratio})")
        for name in ("flux_d_asymmetry", "flux_cross"):
            value = getattr(self, name)
            _require(math.isfinite(value) and 0 <= value < 1, f"{name} must be in [0, 1) (got {value})")
        for name in ("flux_S", "flux_T"):
            value = getattr(self, name)
            _require(math.isfinite(value) and value > 0, f"{name} must be > 0 (got {value})")
        for name in ("flux_U", "flux_V"):
            value = getattr(self, name)
            _require(math.isfinite(value) and value >= 0, f"{name} must be >= 0 (got {value})")
        _require(math.isfinite(self.thermal_R) and self.thermal_R >= 0,
                 f"thermal_R must be >= 0 K/W, 0 = off (got {self.thermal_R})")
        _require(math.isfinite(self.thermal_C) and self.thermal_C > 0,
                 f"thermal_C must be > 0 J/K (got {self.thermal_C})")
        for name in ("T_winding", "T_magnet", "alpha_R", "alpha_psi", "T_ambient"):
            _require(math.isfinite(getattr(self, name)), f"{name} must be finite (got {getattr(self, name)})")
        for name in ("T_winding", "T_magnet", "T_ambient"):
            _require(getattr(self, name) > -273.15, f"{name} must be above -273.15 degC (got {getattr(self, name)})")
        _require(1.0 + self.alpha_R * (self.T_winding - TEMPERATURE_REF) > 0,
                 f"R_s at T_winding = {self.T_winding} degC with alpha_R = {self.alpha_R} 1/K is not > 0")
        _require(1.0 + self.alpha_psi * (self.T_magnet - TEMPERATURE_REF) > 0,
                 f"psi at T_magnet = {self.T_magnet} degC with alpha_psi = {self.alpha_psi} 1/K is not > 0")
        _require(self.thermal_model in THERMAL_MODELS,
                 f"thermal_model must be one of {THERMAL_MODELS} (got {self.thermal_model!r})")
        _require(self.thermal_model == "off" or self.thermal_R == 0,
                 f"thermal_model {self.thermal_model!r} has its own winding-to-coolant path: set thermal_R = 0 (the "
                 f"one-node model's)")
        for name in LPTN_FIELDS:
            value = getattr(self, name)
            unit = "J/K" if name.startswith("lptn_C_") else "K/W"
            _require(math.isfinite(value) and value > 0, f"{name} must be > 0 {unit} (got {value})")
        for name in ("lptn_rotor_share", "lptn_yoke_share"):
            value = getattr(self, name)
            _require(math.isfinite(value) and 0.0 <= value <= 1.0, f"{name} must be in [0, 1] (got {value})")
        for name in ("T_winding_max", "T_magnet_max"):
            value = getattr(self, name)
            _require(math.isfinite(value) and value > self.T_ambient,
                     f"{name} = {value} degC must be above the coolant's T_ambient = {self.T_ambient} degC")
        if self.thermal:
            _require(thermal_time_constant_bound(self) >= THERMAL_TAU_MIN,
                     f"the thermal network's fastest node has C / sum(1/R) = {thermal_time_constant_bound(self):.3g} "
                     f"s, below {THERMAL_TAU_MIN} s: its Euler step per plant step would not be stable (raise the "
                     f"heat capacities or the thermal resistances)")

    @property
    def thermal(self) -> bool:
        """The motor's temperatures follow its losses: the network ``thermal_model`` 'lptn' or the one-node winding
        (``thermal_R`` > 0)."""
        return self.thermal_model != "off" or self.thermal_R > 0


#: the thermal network's resistances and capacitances (``PlantParams.thermal_model`` 'lptn'), each > 0
LPTN_FIELDS = ("lptn_C_yoke", "lptn_C_tooth", "lptn_C_winding", "lptn_C_magnet", "lptn_R_yoke_coolant",
               "lptn_R_yoke_winding", "lptn_R_yoke_tooth", "lptn_R_tooth_winding", "lptn_R_tooth_magnet",
               "lptn_R_winding_magnet", "lptn_R_magnet_ambient")

#: the least C_i / sum_j G_ij of the thermal network's nodes [s]: the plant's explicit Euler step of the network
#: (``pmsm_ev.kernels.thermal_network_step``) is stable for a step below it (Gershgorin: the fastest mode's rate is at
#: most 2 sum_j G_ij / C_i); 10 ms is over 4 times the plant's longest step with its defaults (2.3 ms,
#: ``PmsmEvPlant.max_step``). Wallscheid and Boecker's network: 22 s (the tooth)
THERMAL_TAU_MIN = 0.01


def thermal_network(p: PlantParams) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """(the conductances [W/K] in the order of ``pmsm_ev.kernels.TH_G_YC`` .. ``TH_G_WC``, the heat capacities [J/K]
    of the nodes TH_Y .. TH_M, 0 for a node that holds its temperature) of the plant's thermal model: the four-node
    network (``thermal_model`` 'lptn'), the one-node winding (``thermal_R`` > 0: winding -> coolant, ``thermal_C``)
    or none (all 0)."""
    if p.thermal_model == "lptn":
        r = (p.lptn_R_yoke_coolant, p.lptn_R_yoke_winding, p.lptn_R_yoke_tooth, p.lptn_R_tooth_winding,
             p.lptn_R_tooth_magnet, p.lptn_R_winding_magnet, p.lptn_R_magnet_ambient)
        return tuple(1.0 / x for x in r) + (0.0,), (p.lptn_C_yoke, p.lptn_C_tooth, p.lptn_C_winding,
                                                      p.lptn_C_magnet)
    if p.thermal_R > 0:
        return (0.0,) * 7 + (1.0 / p.thermal_R,), (0.0, 0.0, p.thermal_C, 0.0)
    return (0.0,) * 8, (0.0,) * 4


#: the nodes each conductance of ``thermal_network`` joins (-1: the coolant)
THERMAL_EDGES = ((0, -1), (0, 2), (0, 1), (1, 2), (1, 3), (2, 3), (3, -1), (2, -1))


def thermal_time_constant_bound(p: PlantParams) -> float:
    """min over the network's nodes with a heat capacity of C_i / sum_j G_ij [s] (``THERMAL_TAU_MIN``); inf without
    the thermal model."""
    g, c = thermal_network(p)
    bound = math.inf
    for node, cap in enumerate(c):
        if cap > 0:
            total = sum(gk for gk, edge in zip(g, THERMAL_EDGES) if node in edge)
            if total > 0:
                bound = min(bound, cap / total)
    return bound


def _bisect(f, lo: float, hi: float) -> float:
    """The zero of f between lo and hi, where f has opposite signs, to the float's resolution."""
    f_lo = f(lo)
    for _ in range(300):
        mid = 0.5 * (lo + hi)
        if mid in (lo, hi):
            break
        f_mid = f(mid)
        if (f_mid < 0.0) == (f_lo < 0.0):
            lo, f_lo = mid, f_mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def _axis_flux(i: float, a0: float, a: float, e: float, i_f: float) -> float:
    """psi [Wb] of one axis without cross-saturation: (a0 + a |psi|^e) psi - i_f = i (increasing in psi)."""
    def g(x):
        return (a0 + a * abs(x) ** e) * x - i_f - i
    lo, hi = -1.0, 1.0
    while g(lo) > 0.0:
        lo *= 2.0
    while g(hi) < 0.0:
        hi *= 2.0
    return _bisect(g, lo, hi)


def flux_model_coefficients(motor: MotorParams, plant: PlantParams, psi: float | None = None) -> tuple:
    """The coefficients of the algebraic magnetic model (``PlantParams.flux_model`` 'algebraic';
    ``pmsm_ev.kernels.flux_currents``) in the order of ``pmsm_ev.kernels.FX_AD0`` .. ``FX_W0``: (a_d0, a_dd,
    S, a_q0, a_qq, T, a_dq, U, V, i_f, psi0, w0), from the motor's L_d, L_q (the incremental inductances at
    zero current) and psi (at 20 degC), the exponents ``flux_S`` .. ``flux_V`` and the shape:

    * d axis: 1/L_d = a_d0 + (S+1) a_dd psi^S (the slope at zero current), a_dd such that
      L_dd(-I_d, 0) - L_dd(+I_d, 0) = ``flux_d_asymmetry`` L_d at I_d = ``flux_d_current`` (bisection);
    * cross and q axis: psi_d at (0, I_q) is (1 - ``flux_cross``) psi, I_q = ``flux_q_current``, which
      fixes a_dq for a given psi_q there; a_qq makes i_q = I_q there and 1/L_q = a_q0 (+ a_dq psi^(U+2)
      / (U+2) when V = 0) the q slope at zero current; psi_q such that L_qq(0, I_q) = ``flux_q_ratio`` L_q
      (a scan for the bracket, then bisection);
    * the magnet: i_f = (a_d0 + a_dd psi_T^S) psi_T at the magnet's flux psi_T = ``psi`` (default: psi at
      ``T_magnet``, ``magnet_flux``): the flux at zero current is psi_T; the iron's curve is the 20 degC
      one (a hot magnet has less MMF, not other iron). psi0 = psi_T; w0 the field energy there.

    Checks the model is physical over currents up to twice the larger of ``flux_q_current``,
    ``flux_d_current`` in either axis and sign: psi(i) found (Newton) and the incremental inductance
    matrix positive definite. ``ParameterError`` (one line, naming the field) where a target cannot be
    met or the model is not physical."""
    p = plant
    L_d, L_q, psi20 = motor.L_d, motor.L_q, motor.psi
    S, T, U, V = float(p.flux_S), float(p.flux_T), float(p.flux_U), float(p.flux_V)
    I_d, I_q = float(p.flux_d_current), float(p.flux_q_current)
    psi_T = magnet_flux(psi20, p.T_magnet, p.alpha_psi) if psi is None else float(psi)

    # the d axis (psi_q = 0 wherever i_q = 0)
    def d_axis(a_dd):
        a_d0 = 1.0 / L_d - (S + 1.0) * a_dd * psi20 ** S
        return a_d0, (a_d0 + a_dd * psi20 ** S) * psi20

    def asymmetry(a_dd):
        a_d0, i_f = d_axis(a_dd)
        l_plus = 1.0 / (a_d0 + (S + 1.0) * a_dd * abs(_axis_flux(I_d, a_d0, a_dd, S, i_f)) ** S)
        l_minus = 1.0 / (a_d0 + (S + 1.0) * a_dd * abs(_axis_flux(-I_d, a_d0, a_dd, S, i_f)) ** S)
        return (l_minus - l_plus) / L_d

    a_dd = 0.0
    if p.flux_d_asymmetry > 0.0:
        a_top = (1.0 - 1e-9) / (L_d * (S + 1.0) * psi20 ** S)  # a_d0 > 0: the relieved d path's slope is finite
        top = asymmetry(a_top)
        _require(top > p.flux_d_asymmetry,
                 f"flux_d_asymmetry = {p.flux_d_asymmetry:g} is beyond the {top:.3g} the model reaches at "
                 f"flux_d_current = {I_d:g} A with flux_S = {S:g}")
        a_dd = _bisect(lambda a: asymmetry(a) - p.flux_d_asymmetry, 0.0, a_top)
    a_d0, i_f20 = d_axis(a_dd)

    # cross-saturation and the q axis
    ratio, cross = float(p.flux_q_ratio), float(p.flux_cross)
    unreachable = (f"flux_q_ratio = {ratio:g} at flux_q_current = {I_q:g} A is not reachable by the model with "
                   f"flux_cross = {cross:g} (flux_T = {T:g}, flux_U = {U:g}, flux_V = {V:g})")
    if cross == 0.0:
        a_dq, a_q0 = 0.0, 1.0 / L_q

        def q_ratio(a_qq):
            x = abs(_axis_flux(I_q, a_q0, a_qq, T, 0.0))
            return 1.0 / (a_q0 + (T + 1.0) * a_qq * x ** T) / L_q

        a_qq = 0.0
        if ratio < 1.0:
            hi = a_q0
            while q_ratio(hi) > ratio:
                hi *= 4.0
                _require(hi < 1e300, unreachable)
            a_qq = _bisect(lambda a: q_ratio(a) - ratio, 0.0, hi)
    else:
        psi_ds = (1.0 - cross) * psi20
        k_cross = i_f20 / psi_ds - a_d0 - a_dd * psi_ds ** S  # > 0: psi_d(0, 0) = psi20 > psi_ds

        def q_coefficients(psi_qs):
            a_dq = k_cross * (V + 2.0) / (psi_ds ** U * psi_qs ** (V + 2.0))
            a_q0 = 1.0 / L_q - (a_dq / (U + 2.0) * psi20 ** (U + 2.0) if V == 0.0 else 0.0)
            a_qq = (I_q / psi_qs - a_q0 - a_dq / (U + 2.0) * psi_ds ** (U + 2.0) * psi_qs ** V) / psi_qs ** T
            return a_dq, a_q0, a_qq

        def q_error(psi_qs):
            a_dq, a_q0, a_qq = q_coefficients(psi_qs)
            if a_q0 <= 0.0 or a_qq < 0.0:
                return None
            c = (a_d0, a_dd, S, a_q0, a_qq, T, a_dq, U, V, i_f20, psi20, 0.0)
            g_dd, g_dq, g_qq = flux_jacobian(psi_ds, psi_qs, c, 0)
            det = g_dd * g_qq - g_dq * g_dq
            if g_dd <= 0.0 or det <= 0.0:
                return None
            return g_dd / det / L_q - ratio

        grid = [2.0 * L_q * I_q * 0.98 ** j for j in range(400)]  # from twice the linear flux down
        found = None
        for hi, lo in zip(grid, grid[1:]):
            e_hi, e_lo = q_error(hi), q_error(lo)
            if e_hi is not None and e_lo is not None and (e_hi < 0.0) != (e_lo < 0.0):
                found = (lo, hi)
                break
        _require(found is not None, unreachable)
        a_dq, a_q0, a_qq = q_coefficients(_bisect(q_error, *found))

    # the magnet at its temperature, and the energy's zero
    i_f = (a_d0 + a_dd * psi_T ** S) * psi_T
    c = [a_d0, a_dd, S, a_q0, a_qq, T, a_dq, U, V, i_f, psi_T, 0.0]
    c[FX_W0] = flux_energy(psi_T, 0.0, c, 0)
    # physical over the currents the drive can reach
    reach = 2.0 * max(I_q, I_d)
    n = 16
    for j in range(-n, n + 1):
        for m in range(-n, n + 1):
            i_d, i_q = reach * j / n, reach * m / n
            psi_d, psi_q = flux_linkages(i_d, i_q, c, 0)
            f_d, f_q = flux_currents(psi_d, psi_q, c, 0)
            g_dd, g_dq, g_qq = flux_jacobian(psi_d, psi_q, c, 0)
            _require(abs(f_d - i_d) + abs(f_q - i_q) < 1e-6 * (1.0 + reach) and g_dd > 0.0
                     and g_dd * g_qq - g_dq * g_dq > 0.0,
                     f"flux_cross = {cross:g} with flux_q_ratio = {ratio:g} gives a flux model that is not physical at "
                     f"(i_d, i_q) = ({i_d:g}, {i_q:g}) A (its incremental inductance matrix is not positive definite)")
    assert c[FX_IF] == i_f and c[FX_PSI0] == psi_T and c[FX_ADQ] == a_dq
    return tuple(float(x) for x in c)


# --- Controller design ------------------------------------------------------------
#: control period [s] [chosen]: 10 kHz, a common PWM/sampling rate of EV inverters.
DT_DEFAULT = 1.0e-4


#: the default voltage limit of the current PIs [V] (``ControllerParams.u_max``)
_U_MAX_DEFAULT = 360.0 / math.sqrt(3.0)


@dataclass(frozen=True)
class ControllerParams:
    """FOC design and limits (eqs 14-20).

    The paper gives the structure of its PIs (eqs 14-16) and filters (17-18) but no gains.
    Here the gains follow from bandwidths and the controller's own motor model when the
    control unit is built (``pmsm_ev.controller.controller_gains``, which has the formulas):
    current PIs K_p = L omega_c, K_i = R_s omega_c; speed PI K_p = 2 zeta omega_n J / k_t,
    K_i = omega_n^2 J / k_t on J = J_m + ``J_load``, k_t = N psi; T_d = 1 / omega_c. So a
    controller given another L_q (``ctrl.L_q``) retunes its q-current PI with it. A gain
    field other than 0 overrides its derived value.
    """

    #: current-loop bandwidth [rad/s] [chosen]: ~320 Hz, 1/30 of the 10 kHz sampling rate,
    #: so the sampled loop behaves like the continuous design (phase lag < 4 deg). With the
    #: PI zero on the R/L pole each current loop is first order, 1 / (1 + s / omega_c):
    #: a step rises 10-90 % in 2.2 / omega_c (1.1 ms); sampled at dt its pole is 1 - omega_c dt,
    #: a rise of ln 9 dt / -ln(1 - omega_c dt) (0.98 ms at 10 kHz, measured in tests/test_gains.py).
    omega_c: float = 2000.0
    #: speed-loop natural frequency [rad/s] and damping [-] [chosen]. The paper reports speed
    #: dips of 15 rad/s (scenario 1) and up to 33 rad/s (22 deg steps); a PI loop on J_eq
    #: with omega_n = 2 rad/s, zeta = 1 gives dips of that order (6.6 rad/s for a 5 deg
    #: step, 28 rad/s for 22 deg). A stiff loop (omega_n ~ 100 rad/s) is fine with a speed
    #: sensor but unstable with the EKF5, whose model carries J_m = J_eq/52 (eqs 30-31).
    omega_n: float = 2.0
    zeta: float = 1.0
    #: the vehicle's inertia at the motor shaft that the speed-loop design assumes [kg m^2]
    #: [T2]: r_w^2 m_v / (eta n_g^2) of eq 9 (0.516 kg m^2); the speed PI is tuned on
    #: J_m + J_load = J_eq (0.526 kg m^2). The controller has no vehicle parameters of its own.
    J_load: float = VehicleParams().reflected_inertia
    #: gain overrides, 0 = derived from the bandwidths (``pmsm_ev.controller.controller_gains``)
    kp_w: float = 0.0  #: speed PI proportional gain [A s/rad] (eq 14); 0 = 2 zeta omega_n J / k_t
    ki_w: float = 0.0  #: speed PI integral gain [A/rad] (eq 14); 0 = omega_n^2 J / k_t
    kp_id: float = 0.0  #: d-current PI proportional gain [V/A] (eq 15); 0 = L_d omega_c
    ki_id: float = 0.0  #: d-current PI integral gain [V/(A s)] (eq 15); 0 = R_s omega_c
    kp_iq: float = 0.0  #: q-current PI proportional gain [V/A] (eq 16); 0 = L_q omega_c
    ki_iq: float = 0.0  #: q-current PI integral gain [V/(A s)] (eq 16); 0 = R_s omega_c
    #: decoupling low-pass time constant [s] (eqs 17-18); 0 = 1 / omega_c, the closed current
    #: loop's time constant, so i_dl, i_ql follow the references the way the real currents do
    T_d: float = 0.0
    i_d_ref: float = 0.0  #: d-current reference [A]: 0, the usual choice below base speed
    #: q-current limit [A] [chosen]: 400 A gives 144 N m, 1.5x the 94 N m of the 25 deg plateau.
    i_q_max: float = 400.0
    #: voltage-vector limit [V] [chosen]: linear-modulation limit V_dc/sqrt(3) of a 360 V
    #: DC link (208 V), twice the ~100 V the 25 deg plateau needs at 200 rad/s.
    u_max: float = _U_MAX_DEFAULT
    #: "physical" (default): v_q = u_q + N w (L_d i_dl + psi), the sign that cancels
    #: eq 11's back-EMF and cross-coupling. "paper": eq 20 as printed (minus signs).
    decoupling: str = "physical"
    #: voltage angle advance [control periods] [chosen]: the inverter holds v_alpha,
    #: v_beta over a period while the rotor turns omega_e dt; advancing the inverse
    #: Park by half a period makes the period's mean dq voltage equal the command.
    #: With a one-period actuation delay (plant ``inverter_delay = 1``) use 1.5: the
    #: vector is applied one period later, and centred half a period after that.
    angle_advance: float = 0.5
    #: actuation delay the controller accounts for [periods], 0 or 1: with 1 the observer
    #: is given the voltage commanded one period earlier (the one the inverter is applying).
    delay_compensation: int = 0
    #: lengthen the held voltage vector by a/sin(a), a = omega_e dt / 2 [chosen: off].
    #: Seen from the rotor, a vector held over a period sweeps an arc of omega_e dt and
    #: its mean is shorter by sin(a)/a (0.03 % at 200 rad/s). Measured: this is not the
    #: only O(dt^2) effect: the current ripple sampled at the period edges biases the
    #: EKF the other way, and with the compensation on the EKF5's speed bias doubles
    #: (0.05 -> 0.10 rad/s at 10 kHz). Off by default; both vanish as dt^2.
    zoh_compensation: bool = False
    #: dead-time compensation: per-phase voltage added in the sign of the measured phase current
    #: [V]; 0 = off. To cancel the plant's ``dead_time``: v_dc t_d / T_s (7.2 V for 2 us at 10 kHz
    #: and 360 V). The observers keep the uncompensated command as their voltage input.
    dead_time_comp: float = 0.0
    #: current scale of the compensation's soft sign [A] [chosen]: the plant's ``dead_time_i0``
    dead_time_comp_i0: float = 2.0
    #: the current control (docs/speed-range.md). "paper" (default): eqs 15-20 as above, the decoupling
    #: on the filtered references i_dl, i_ql (eqs 17-18), the whole vector scaled to u_max and the
    #: integrators held while it is. "high_speed" [chosen, for omega_e dt up to 0.62 rad at top speed]:
    #: (1) the decoupling and back-EMF terms of eqs 19-20 on the current predicted at the middle of the
    #: period the voltage is applied over, i + (1 - exp(-omega_c dt angle_advance)) (i_ref - i) (the
    #: closed loop's first-order response, Harnefors and Nee 1998; the prediction of the discrete-time
    #: design of Kim, Degner, Guerrero, Briz and Lorenz, IEEE TIA 46(4), 2010); (2) under the voltage
    #: limit the back-EMF and decoupling part keeps its priority and only the PI part is shortened (the
    #: dq angle of the operating point's own voltage stays), the integrators updated with the
    #: realisable reference (Harnefors: the error the limited voltage realises, e_r = (u_lim - I) / K_p,
    #: a back-calculation of gain K_i / K_p) instead of held; (3) the held vector lengthened by
    #: sin(a)/a, a = omega_e dt / 2 (shortened: the held stationary vector must equal the mean of the
    #: rotating one the currents need, which is sin(a)/a of it; ``zoh_compensation``'s a/sin(a) is the
    #: rotor-frame view and is not used), at the angle advance ``angle_advance`` (0.5; 1.5 with the
    #: plant's inverter_delay = 1: the middle of the applied period). Needs decoupling "physical".
    current_control: str = "paper"

    # -- the whole speed range (docs/speed-range.md; all off by default: the paper's drive) ------------
    #: the current references [chosen: "paper"]. "paper": i_d = ``i_d_ref``, i_q from the speed PI limited
    #: to +-``i_q_max`` (the paper's drive, eqs 14-20). "mtpa": the speed PI (eq 14, the same gains) commands
    #: the torque k_t x its output (k_t = k_dq N psi), turned into (i_d, i_q) on MTPA for this salient motor
    #: within ``i_max`` and ``T_max``, no voltage limit. "fw": MTPA, field weakening and MTPV under the
    #: voltage limit v_dc / sqrt(3) with the margin ``fw_margin`` (needs ``v_dc``)
    #: (``pmsm_ev.kernels.references``).
    reference: str = "paper"
    #: current-magnitude limit of the modes "mtpa" and "fw" [A] [chosen]: 400 A, ``i_q_max``'s figure: an
    #: inverter rated 400 A peak per phase (the dq currents are amplitude-invariant: |i_dq| is the phase
    #: current's peak), 153.1 N m on MTPA with Table I's motor (144 N m at i_d = 0)
    i_max: float = 400.0
    #: torque limit of the modes "mtpa" and "fw" [N m]; 0 = what ``i_max`` gives on MTPA. Above that it is
    #: refused (the current limit gives no more)
    T_max: float = 0.0
    #: the share of the voltage limit that field weakening plans with [-] [chosen]: 0.9 leaves 10 % (21 V of
    #: 208 V) to the current PIs: the R_s drop (400 A x 8.7 mOhm = 3.5 V, 1.7 %, not in the flux circle),
    #: the transients of the current loops (a 10 A step error is 5.8 V through K_p = L_q omega_c) and what
    #: the rotation during a period takes at the top speed's 990 Hz electrical (omega_e dt = 0.62 rad: the
    #: held vector's mean is 1 - sin(a)/a = 1.6 % shorter, a = omega_e dt / 2, without ZOH compensation)
    fw_margin: float = 0.9
    #: DC-link voltage [V]; 0 = not given: the current PIs keep ``u_max``. > 0: the voltage limit of the
    #: current PIs and of field weakening is v_dc / sqrt(3) (linear modulation; the plant's ``v_dc``), and
    #: ``u_max`` must then stay at its default (one of the two)
    v_dc: float = 0.0
    #: regenerative power limit [W], >= 0; 0 = no limit (the paper's drive). A braking torque demand (opposing
    #: the motion) goes to the motor up to P_regen_max / |omega| and the envelope; the rest is the friction
    #: brake's (``T_brake``). A battery's charge limit, e.g. 30 kW
    P_regen_max: float = 0.0
    #: gear ratio the friction-brake demand is converted through, motor speed / wheel speed [-] [T2]:
    #: ``VehicleParams.n_g``
    n_g: float = VehicleParams().n_g
    #: gear efficiency of that conversion [-] [T2]: ``VehicleParams.eta``; T_brake = the shaft torque
    #: left x n_g x eta (a wheel torque T_b acts on the shaft as T_b / (eta n_g), eq 29)
    eta: float = VehicleParams().eta
    #: the speed loop's feedforward (docs/cycles.md) [chosen: "none", the paper's drive, a PI alone], the
    #: reference generator's modes only. The soft speed PI (omega_n 2 rad/s, for the observers) lags a drive
    #: cycle's accelerations by seconds; a two-degree-of-freedom speed controller adds the torque the
    #: reference itself needs, so the PI only corrects what the model misses (``kernels.speed_feedforward``).
    #: "inertia": J omega_ref', the reference's acceleration on the speed PI's own inertia J_m + ``J_load``
    #: (J_eq, 0.526 kg m^2), its slope taken over the last period; "inertia+road": plus the level road's
    #: load at the reference speed, sign(omega_ref) (``ff_T0`` + ``ff_T1`` |omega_ref| + ``ff_T2``
    #: omega_ref^2). The sum is clamped at the torque available, the PI at what is left of it.
    speed_feedforward: str = "none"
    #: the road-load feedforward's coast-down coefficients at the shaft (``road_load_coefficients``), Table
    #: II's level road by default: constant [N m], in |omega| [N m s/rad], in omega^2 [N m s^2/rad^2]
    ff_T0: float = _ROAD_LOAD[0]
    ff_T1: float = _ROAD_LOAD[1]
    ff_T2: float = _ROAD_LOAD[2]

    # -- adaptation while driving (docs/sensorless.md, "Adaptation while driving"; ``pmsm_ev.kernels.adaptation``) ----
    #: the magnet flux and the stator resistance tracked as the motor warms, by a model-reference estimator on the
    #: unit's own voltage and measured currents (eqs AD1-AD6) [chosen: "off", today's drive]. "observe": the
    #: estimates computed and put out (psi_est, R_s_est), the controller unchanged, bit for bit; "use": the
    #: controller's model takes them (psi in the feed-forward, the reference generator and the EKF's A3-A4, R_s in
    #: the EKF's A8, A14)
    adaptation: str = "off"
    #: the controller's model of the motor's inductances and resistance [chosen: "given", today's drive]: "given",
    #: the controller's MotorParams (the data sheet); "identified", L_d, L_q and R_s as the injection unit's
    #: identification measures them at enable (eqs ID1, ID2; again at a blind unit's stops) in the EKF's model, the
    #: current PIs' gains (K_p = L omega_c, K_i = R_s omega_c at the given model's bandwidth), the decoupling and
    #: feed-forward, the reference generator and the I-f sizing (eq AD7, ``pmsm_ev.kernels.model_apply``); a unit that
    #: does not identify (no injection) keeps the given model
    model_source: str = "given"
    #: the estimators' memory [s] [chosen]: the least-squares sums forget with this time constant over the periods
    #: where their parameter is observable. Far below the motor's thermal time constants (the winding's fastest
    #: 15.9 s, the magnet's 65 min: docs/speed-range.md, "A motor that warms"), so the estimate lags the warming by
    #: a small share; far above the period (2 s at speed is 20 000 periods: the 4 V rms that the sensors' 1 A puts
    #: on L_q di/dt a period averages to 0.03 V, 0.1 % of the back-EMF at adapt_psi_speed)
    adapt_time: float = 2.0
    #: psi is observable at this |omega_m| or faster [rad/s] [chosen]: back-EMF N omega psi = 54 V at 150 rad/s
    #: (12.7 km/h), so that a resistance 5 % off at 300 A (0.13 V) or an inverter's residual voltage of 0.5 V moves
    #: psi_hat by 0.3 % or 1 %; below, the back-EMF is of the order of those errors
    adapt_psi_speed: float = 150.0
    #: R_s is observable at this |omega_m| or slower [rad/s] [chosen]: at 15 rad/s (1.3 km/h) a psi_hat 0.5 % off
    #: moves R_s_hat by N omega Delta psi / |i| = 3 % of R_s at adapt_rs_current; faster, the back-EMF's error
    #: swamps R_s |i|^2
    adapt_rs_speed: float = 15.0
    #: ... and at this current magnitude or more [A] [chosen]: R_s |i| = 0.87 V at 100 A, large against the current
    #: PI's own noise (K_p sigma = 0.6 V a period, averaged out) and the 0.1 V a 1 % dead-time residual leaves
    adapt_rs_current: float = 100.0
    #: the currents are quasi-steady, and both fits update, while |di/dt| (filtered over 50 ms) is at most this
    #: [A/s] [chosen]: the L di/dt terms are in the fits, but with the model's inductances: 10 % of L_q x 2000 A/s is
    #: 0.06 V, 0.1 % of the back-EMF at adapt_psi_speed
    adapt_current_rate: float = 2000.0

    @property
    def u_limit(self) -> float:
        """The voltage limit of the current PIs and of field weakening [V]: v_dc / sqrt(3) if ``v_dc`` is
        given, else ``u_max``."""
        return self.v_dc / math.sqrt(3.0) if self.v_dc > 0 else self.u_max

    def torque_at_current_limit(self, motor: "MotorParams") -> float:
        """The torque ``i_max`` gives on MTPA [N m] (k_dq x eq 12 of the controller's ``motor``)."""
        i_d, i_q = kernel_mtpa_limit_current(float(self.i_max), motor.psi, motor.L_d, motor.L_q)
        return kernel_dq_torque(motor.k_dq * motor.N, i_d, i_q, motor.psi, motor.L_d, motor.L_q)

    def validate_limits(self, motor: "MotorParams") -> None:
        """The checks that need the controller's motor model: ``T_max`` within what ``i_max`` gives."""
        t_i = self.torque_at_current_limit(motor)
        _require(self.T_max <= t_i * (1.0 + 1e-12),
                 f"T_max = {self.T_max:g} N m is above the {t_i:.1f} N m that i_max = {self.i_max:g} A gives on "
                 f"MTPA: lower T_max or raise i_max")

    def validate(self) -> None:
        for name in ("omega_c", "omega_n", "zeta", "J_load", "kp_w", "ki_w", "kp_id", "ki_id", "kp_iq", "ki_iq",
                     "T_d", "i_q_max", "u_max"):
            value = getattr(self, name)
            _require(math.isfinite(value), f"{name} must be finite (got {value})")
        _require(self.omega_c > 0, f"omega_c must be > 0 rad/s (got {self.omega_c})")
        _require(self.omega_n > 0, f"omega_n must be > 0 rad/s (got {self.omega_n})")
        _require(self.zeta > 0, f"zeta must be > 0 (got {self.zeta})")
        _require(self.J_load >= 0, f"J_load must be >= 0 kg m^2 (got {self.J_load})")
        for name in ("kp_w", "ki_w", "kp_id", "ki_id", "kp_iq", "ki_iq"):
            _require(getattr(self, name) >= 0, f"{name} must be >= 0, 0 = derived (got {getattr(self, name)})")
        _require(self.T_d >= 0, f"T_d must be >= 0 s, 0 = 1/omega_c (got {self.T_d})")
        _require(self.angle_advance >= 0, f"angle_advance must be >= 0 (got {self.angle_advance})")
        _require(self.delay_compensation in (0, 1),
                 f"delay_compensation must be 0 or 1 (got {self.delay_compensation})")
        _require(self.i_q_max > 0, f"i_q_max must be > 0 A (got {self.i_q_max})")
        _require(self.u_max > 0, f"u_max must be > 0 V (got {self.u_max})")
        _require(math.isfinite(self.dead_time_comp) and self.dead_time_comp >= 0,
                 f"dead_time_comp must be >= 0 V (got {self.dead_time_comp})")
        _require(math.isfinite(self.dead_time_comp_i0) and self.dead_time_comp_i0 > 0,
                 f"dead_time_comp_i0 must be > 0 A (got {self.dead_time_comp_i0})")
        _require(self.decoupling in DECOUPLING_MODES,
                 f"decoupling must be one of {DECOUPLING_MODES} (got {self.decoupling!r})")
        _require(self.current_control in CURRENT_CONTROLS,
                 f"current_control must be one of {CURRENT_CONTROLS} (got {self.current_control!r})")
        _require(self.current_control == "paper" or self.decoupling == "physical",
                 "current_control 'high_speed' needs decoupling 'physical' (eq 20 as printed does not cancel eq 11)")
        _require(self.reference in REFERENCES, f"reference must be one of {REFERENCES} (got {self.reference!r})")
        for name in ("i_max", "T_max", "fw_margin", "v_dc", "P_regen_max", "n_g", "eta"):
            value = getattr(self, name)
            _require(math.isfinite(value), f"{name} must be finite (got {value})")
        _require(self.i_max > 0, f"i_max must be > 0 A (got {self.i_max})")
        _require(self.T_max >= 0, f"T_max must be >= 0 N m, 0 = what i_max gives on MTPA (got {self.T_max})")
        _require(0 < self.fw_margin <= 1, f"fw_margin must be in (0, 1] (got {self.fw_margin})")
        _require(self.v_dc >= 0, f"v_dc must be >= 0 V, 0 = not given (got {self.v_dc})")
        _require(self.P_regen_max >= 0, f"P_regen_max must be >= 0 W, a power the motor may take back, 0 = no "
                                        f"limit (got {self.P_regen_max})")
        _require(self.n_g > 0, f"n_g must be > 0 (got {self.n_g})")
        _require(0 < self.eta <= 1, f"eta must be in (0, 1] (got {self.eta})")
        _require(self.speed_feedforward in SPEED_FEEDFORWARDS,
                 f"speed_feedforward must be one of {SPEED_FEEDFORWARDS} (got {self.speed_feedforward!r})")
        _require(self.speed_feedforward == "none" or self.reference != "paper",
                 f"speed_feedforward {self.speed_feedforward!r} needs reference 'mtpa' or 'fw' (the paper's "
                 f"reference has no torque demand to add it to)")
        for name in ("ff_T0", "ff_T1", "ff_T2"):
            value = getattr(self, name)
            _require(math.isfinite(value) and value >= 0, f"{name} must be >= 0 (got {value})")
        _require(self.reference != "fw" or self.v_dc > 0,
                 "reference 'fw' (field weakening) needs the DC-link voltage: set v_dc > 0 V")
        _require(self.v_dc == 0 or self.u_max == _U_MAX_DEFAULT,
                 f"u_max = {self.u_max:g} V and v_dc = {self.v_dc:g} V are both given: set one of the two "
                 f"(v_dc > 0 sets the voltage limit v_dc/sqrt(3))")
        self.validate_adaptation()

    def validate_adaptation(self) -> None:
        """The adaptation's settings (``adaptation``, ``adapt_*``)."""
        _require(self.adaptation in ADAPTATIONS,
                 f"adaptation must be one of {ADAPTATIONS} (got {self.adaptation!r})")
        _require(self.model_source in MODEL_SOURCES,
                 f"model_source must be one of {MODEL_SOURCES} (got {self.model_source!r})")
        for name in ("adapt_time", "adapt_psi_speed", "adapt_rs_current", "adapt_current_rate"):
            value = getattr(self, name)
            _require(math.isfinite(value) and value > 0, f"{name} must be finite and > 0 (got {value})")
        _require(math.isfinite(self.adapt_rs_speed) and 0 <= self.adapt_rs_speed < self.adapt_psi_speed,
                 f"adapt_rs_speed must be >= 0 rad/s and below adapt_psi_speed = {self.adapt_psi_speed:g} rad/s "
                 f"(got {self.adapt_rs_speed})")


@dataclass(frozen=True)
class EkfParams:
    """EKF covariances (eqs 24-27). The appendix prints every entry of Q, R as "2".

    The diagonals are chosen from the physics [chosen]:

    * R: current measurement variance [A^2]. Simulated currents are exact, so R
      expresses trust in the measurement: (0.5 A)^2, a good 12-bit sensor at 1000 A.
    * Q_i: current process noise [A^2 per step], model error of A2-A3 (Euler step,
      unmodelled inverter effects): 0.1 V over a period moves i by V dt / L = 0.05 A.
    * Q_w: speed process noise [(rad/s)^2 per step]: small, speed follows from torque.
    * Q_theta: angle process noise [rad^2 per step]: tiny, angle follows from speed.
    * Q_TL: load-torque random walk [(N m)^2 per step]; sets how fast T_L_hat follows
      the road. A 5 deg step moves T_L by ~19 N m; (0.05 N m)^2 per step tracks that
      in a few ms of innovation.
    * P0: initial uncertainty: 1 A^2, (10 rad/s)^2, (pi)^2 rad^2, (10 N m)^2.

    EKF4 (no T_L state) takes the first four entries and, having no load model, needs a
    larger speed random walk: ``q_omega_ekf4``.
    """

    q_i: float = 2.5e-3
    q_omega: float = 1.0e-4
    q_theta: float = 1.0e-8
    q_TL: float = 2.5e-3
    r_i: float = 0.25
    p0_i: float = 1.0
    p0_omega: float = 100.0
    p0_theta: float = math.pi**2
    p0_TL: float = 100.0
    #: speed random walk of EKF4 [(rad/s)^2 per step]: with dw/dt = 0 the filter can
    #: follow a load-induced acceleration only through this noise.
    q_omega_ekf4: float = 1.0e-2
    #: initial speed estimate [rad/s]: 0, the drive starts from standstill; set it for a
    #: flying start (plant started at speed).
    x0_omega: float = 0.0
    #: initial electrical-angle estimate [rad]: the observer's own guess of theta(0).
    x0_theta: float = 0.0
    #: inertia of the EKF's mechanical model (A4, A18-A22) [kg m^2]; 0 = the motor's J_m,
    #: the paper's choice (eq 22), which makes T_L_hat absorb the reflected vehicle inertia
    #: (eqs 30-31). [chosen] The sensorless unit defaults to the drive's whole inertia
    #: J_eq (eq 9, 0.526 kg m^2, ``SENSORLESS_EKF``): with J_m, 52x too small, a rotor that
    #: swings at start-up makes the model see 52x the acceleration per N m of torque error,
    #: and the estimate loses the angle.
    J_model: float = 0.0
    #: magnet-flux adaptation of the stationary-frame EKF5 (observers "ekf5ab", "sensorless")
    #: [1/s]; 0 = off (the nominal psi). The EKF's psi is moved until omega_hat agrees with the
    #: rate of its own angle estimate (``pmsm_ev.kernels.adapt_psi``): a hot magnet (-10 % psi)
    #: otherwise biases omega_hat, and the speed, by several %. [chosen] 1/s when on: the
    #: mismatch is corrected in a few seconds, far slower than the EKF's own dynamics.
    psi_adapt: float = 0.0
    #: the adaptation runs while |omega_hat| exceeds this [rad/s] [chosen]: 30 rad/s, the
    #: sensorless unit's handover speed (back-EMF 10.8 V): below it psi is poorly observable
    psi_adapt_speed: float = 30.0
    #: the discretisation of the current model A2-A3 (every EKF: ekf5, ekf4, ekf5ab, the sensorless
    #: unit; docs/speed-range.md). "euler" (default): the appendix's forward Euler; at omega_e dt = 0.62
    #: rad (top speed) the eigenvalues 1 + lambda dt of its rotation have |.| = 1.18 > 1. "bilinear"
    #: [chosen]: Tustin's rule (trapezoidal) on A2-A3, (I - A dt/2) i' = (I + A dt/2) i + b dt, whose
    #: rotation keeps |.| = 1 (phase 2 atan(omega_e dt / 2) for omega_e dt), with the voltage of the
    #: Euler step (the dq command; for the stationary-frame EKF5 the held vector in its frame at
    #: mid-period); the Jacobian is this step's derivative (tests/test_observers.py checks it by finite
    #: differences). A4-A6 stay as printed. Measured one-step prediction error of the currents at 1500
    #: rad/s (tests/test_high_speed.py): 0.47 A / 0.52 A (d / q) against Euler's 0.91 A / 0.58 A.
    discretisation: str = "euler"

    def validate(self) -> None:
        _require(self.discretisation in DISCRETISATIONS,
                 f"discretisation must be one of {DISCRETISATIONS} (got {self.discretisation!r})")
        for f in fields(self):
            if f.name == "discretisation":
                continue
            value = getattr(self, f.name)
            if f.name.startswith("x0_"):
                _require(math.isfinite(value), f"{f.name} must be finite (got {value})")
                continue
            _require(math.isfinite(value) and value >= 0, f"{f.name} must be finite and >= 0 (got {value})")
        _require(self.r_i > 0, f"r_i must be > 0 A^2 (got {self.r_i})")

    def inertia(self, motor: "MotorParams") -> float:
        """The inertia of the EKF's mechanical model [kg m^2]: ``J_model``, or J_m if 0."""
        return self.J_model if self.J_model > 0 else motor.J_m


@dataclass(frozen=True)
class StartupParams:
    """The sensorless unit's low-speed range (observer "sensorless", FocSensorless.fmu):
    alignment at standstill, I-f (current-frequency) drive, and the handover to and from
    the stationary-frame EKF5 (``pmsm_ev.kernels.sensorless_step``, a state machine: ``kernels.startup``; reasoning in
    ``docs/sensorless.md``).

    Alignment [chosen]: a current vector of ``i_align`` is ramped up on the +90 deg axis
    (``t_ramp``), held (``t_hold``), swept slowly to 0 deg (``t_sweep``) and held again
    (``t_settle``): the magnet then sits on 0 deg, whatever theta(0) was. Two steps
    because a single vector on 0 deg gives no torque at theta(0) = +-pi (the unstable
    equilibrium); slow because the drivetrain (J_eq = 0.526 kg m^2) on the magnet's
    "spring" (N^2 psi i_align = 86 N m/rad at 60 A) swings at 2 Hz with little damping: a
    ramped current and a swept vector move it quasi-statically. Position moved by the
    alignment: at most pi/N = 45 deg at the shaft, 1.8 cm at the wheel.

    I-f [chosen]: the vector (magnitude i_if) turns at the I-f speed, which follows the
    speed reference with at most ``if_accel`` [rad/s^2]; the rotor lags it by the load
    angle, sin(lag) = torque / (N psi i), a self-stabilising open-loop drive as long as
    the torque needed stays below N psi i_if (21.5 N m at 60 A; the level-road start needs
    ~14 N m). The EKF5 runs on throughout; it was restarted at the aligned angle.

    Handover up [chosen]: once |omega_if| > ``omega_up`` and |omega_hat - omega_if| <
    ``agree_tol`` |omega_if| for ``agree_time``, the speed PI takes over on the EKF's
    angle and speed, its integral and the current PIs' integrators seated on the present
    currents and voltage (no jump). Handover down: below |omega_hat| < ``omega_down``
    (hysteresis: 20 < 30 rad/s) the vector stays where the current is and its magnitude
    ramps to ``if_margin`` times the present current (at least ``i_if``), so it holds the
    load (a car stopping on a slope) with a lag of acos(1/margin) to spare.
    """

    i_align: float = 60.0  #: alignment current [A] [chosen]: the I-f current
    t_ramp: float = 0.5  #: alignment current ramp 0 -> i_align on +90 deg [s] [chosen]
    t_hold: float = 0.5  #: hold on +90 deg [s] [chosen]: the swing decays (rolling friction)
    t_sweep: float = 1.0  #: sweep of the vector +90 -> 0 deg [s] [chosen]: ~2 swing periods
    t_settle: float = 0.3  #: hold on 0 deg before the I-f start [s] [chosen]
    #: I-f current [A] [chosen]: 60 A gives N psi i = 21.5 N m, 1.5x the ~14 N m of the
    #: level-road start (10.5 N m to accelerate J_eq at 20 rad/s^2 plus the rolling load)
    i_if: float = 60.0
    #: largest I-f acceleration [rad/s^2] [chosen]: 80 rad/s^2 (1.9 m/s^2 at the car, a brisk
    #: driver; 4x the routes' 20 rad/s^2 ramp). A jump of the reference becomes a ramp; below
    #: this, the torque the vector gives sets the acceleration (``if_load_angle``)
    if_accel: float = 80.0
    #: rate of change of the I-f current magnitude [A/s] [chosen]: 300 A/s, 0.03 A per period.
    #: After a handover down the vector sits on the q axis, where the magnet's spring is
    #: softest; a faster rise kicks the rotor into a swing (measured at the stop on 22 deg:
    #: T_e transient 24 N m peak-to-peak at 1000 A/s, 8 N m at 300 A/s); 0.23 s to 1.3 x 234 A
    i_rate: float = 300.0
    omega_up: float = 30.0  #: handover up above this I-f speed [rad/s] [chosen]: back-EMF 10.8 V
    omega_down: float = 20.0  #: back to I-f below this |omega_hat| [rad/s] [chosen]
    agree_tol: float = 0.1  #: relative agreement of omega_hat with the I-f speed [-] [chosen]
    agree_time: float = 0.3  #: how long it must hold before the handover up [s] [chosen]
    #: I-f current after the handover down, times the present current [-] [chosen]: a lag
    #: of acos(1/1.3) = 40 deg in reserve for load changes while the car stands
    if_margin: float = 1.3
    #: damping ratio of the rotor's swing on the I-f vector [-] [chosen]: the magnet on the
    #: vector is a spring (N^2 psi i per rad at the shaft) on J_eq with almost no damping;
    #: the vector is pulled back by k (omega_hat - omega_if), k = 2 zeta sqrt(J / (psi i)),
    #: which damps it (docs/sensorless.md); 0.7: a well-damped second-order response.
    #: 0 = the plain I-f (the swing then rings, +-35 N m at a stop on 22 deg)
    if_damping: float = 0.7
    #: time constant of the low-pass filter on omega_hat - omega_if before the damping [s]
    #: [chosen]: 10 ms, a tenth of the swing's period at 60-300 A (0.2-0.5 s), so it keeps the
    #: sensor noise that omega_hat carries at low speed out of the vector's angle
    if_damping_filter: float = 0.01
    #: EKF covariances at its restart after the alignment [chosen]: the rotor is at rest on the
    #: vector, to within the swing left (~0.05 rad): (1 rad/s)^2 and (0.1 rad)^2, not the
    #: (10 rad/s)^2, pi^2 of an unknown start (EkfParams.p0_omega, p0_theta), whose first
    #: corrections on noisy currents would jolt omega_hat and with it the I-f damping
    p0_omega_aligned: float = 1.0
    p0_theta_aligned: float = 0.01
    #: the alignment damped (True) or plain [chosen]: a rotor that starts near the +90 deg vector's
    #: unstable point (-90 deg) falls onto it at up to 5.7 rad/s undamped. The vector is pulled back
    #: by the I-f damping's k times the speed the back-EMF shows on its q axis, v_q / (N psi) =
    #: omega_m cos(e), which needs no angle (docs/sensorless.md)
    align_damping: bool = True
    #: a rotor turning faster than this under the alignment's vector [rad/s] (|omega_hat|: the EKF,
    #: not yet restarted, sees its speed by the back-EMF) is pushed by a load beyond the vector (a car
    #: parked on a slope): the alignment ends and I-f takes over on the EKF's angle at the current
    #: limit [chosen: 6 rad/s, above the damped alignment's own swing, at most 4.5 rad/s from 48
    #: initial angles on a level road]; 0: never
    align_slip: float = 6.0
    #: ... for this long [s] [chosen]: 20 ms; the EKF's first corrections from its unknown start last
    #: under 0.3 ms above 6 rad/s with sigma = 1 A of current noise (8 angles, 3 seeds)
    align_slip_time: float = 0.02
    #: the car stands in I-f below this |omega_hat| and |omega_if| [rad/s] [chosen: 0.5 rad/s, back-EMF
    #: 0.18 V]: the rotor is held by the vector and no back-EMF shows its angle, which the EKF lets
    #: drift with current-sensor noise and offsets (0.7 rad in 10 s on 22 deg with +2/-1 A), and its load
    #: with it; the guard and the I-f sizing take the angle and the load of when the stand began, and
    #: the EKF is put back there when it ends; 0: never
    still_speed: float = 0.5
    #: what a stand is anchored on [rad/s] [chosen: 10 rad/s]: in I-f at this |omega_hat| or faster the
    #: EKF's angle less the vector's (the rotor's place on the vector) and its load are kept; a stand
    #: then takes the vector's angle plus that offset, and that load, and the EKF is restarted at the
    #: vector's angle plus that offset when the stand ends (the vector may have turned since it began).
    #: Below ~10 rad/s an EKF with a mismatched motor model is not to be trusted: the resistance error
    #: against a back-EMF of N omega psi = 3.6 V at 10 rad/s (+50 % R_s at 160 A: 0.69 V, ~0.2 rad), and
    #: the error grows as the back-EMF falls (a hot motor with L_q 24 % off: 0.03 rad at 10 rad/s, 0.46 rad
    #: at a stand's 0.5 rad/s, docs/sensorless.md); 0: the EKF's angle and load at the stand's start
    anchor_speed: float = 10.0
    #: design load angle of the I-f drive [rad] [chosen]: 60 deg. The I-f acceleration is held to
    #: what N psi i sin(60 deg) leaves over the load the EKF sees, and the current raised to what
    #: the asked acceleration and the load need at 60 deg: sin 60 = 0.87 of the pull-out torque
    #: is used, 13 % kept for what changes within the current's rise (docs/sensorless.md)
    if_load_angle: float = math.pi / 3.0
    #: rate of the I-f current while the guard holds the vector back [A/s] [chosen]: the load
    #: exceeds the vector's torque, the rotor is being pushed back: 5000 A/s, 60 -> 400 A in 68 ms
    #: (the current PIs follow that ramp 5000 / omega_c = 2.5 A behind); the swing this kicks is the
    #: lesser evil against a rotor that rolls back
    i_rate_load: float = 5000.0
    #: the synchronism guard on (True) or off: the I-f vector never leads or trails the EKF's angle by
    #: more than ``guard_angle`` (``pmsm_ev.kernels.sync_guard``); off: the plain I-f until a loss of
    #: synchronism is detected (the guard is then on while it is recovered), to test the detector
    sync_guard: bool = True
    #: the guard's angle [rad] [chosen]: 100 deg, past the pull-out angle (90 deg: the most torque per
    #: ampere) so that it never acts on a vector that sits on the q axis after a handover down, and
    #: close enough to keep sin(e) >= 0.98 of the pull-out torque while it holds the vector
    guard_angle: float = math.radians(100.0)
    #: loss-of-synchronism detector, I-f: |omega_hat - omega_if| (filtered, 10 ms) above ``slip_tol`` +
    #: ``agree_tol`` |omega_if| for ``slip_time`` [chosen]: 10 rad/s (the swing on the vector stays
    #: within +-3 rad/s; a rotor out of step differs by the vector's whole speed) and 0.1 s
    slip_tol: float = 10.0
    slip_time: float = 0.1
    #: a loss-of-synchronism episode ends after ``recover_time`` in synchronism [s] [chosen]; one that
    #: has not ended after ``fault_time`` [s] latches the fault: the safe state, a stop and hold (the
    #: speed reference taken as 0, FOC braking to a stand, the I-f vector holding at i_q_max), until
    #: the unit is reset; zero torque is not safe on a slope [chosen: 1 s, 3 s]
    recover_time: float = 1.0
    fault_time: float = 3.0
    #: the handover up overdue [s] [chosen: 1 s]: in I-f with |omega_ref| above ``omega_up`` this long
    #: (a healthy launch hands over ``agree_time`` after the I-f speed passes ``omega_up``: 0.3-0.5 s after
    #: the reference does, measured on the shipped sensorless cycles), the I-f speed above ``omega_up``,
    #: the EKF's speed of the same sign above ``omega_down`` and the rotor not slipping, the handover is
    #: forced: FOC on the EKF, as after a loss of synchronism at speed, an episode. A rotor that swings on a
    #: large I-f vector with a mismatched motor model (L_q 18 % below the EKF's: the EKF's speed swings
    #: +-10 rad/s about the I-f speed) never agrees for ``agree_time``, and the vector pulls out of step
    #: within seconds; the EKF's angle there is within 0.3 rad, enough for FOC (docs/sensorless.md); 0: never
    if_deadline: float = 1.0
    #: the drive stalled [s] [chosen: 3 s]: in I-f with |omega_ref| above ``omega_up`` this long (the
    #: handover neither came nor could be forced: the rotor does not follow the vector), the rotor is
    #: realigned: the alignment from standstill run again (the angle is unknown at a stand), the current
    #: PIs reset, an episode (a rotor turning the vector's way at |omega_hat| >= ``omega_down`` then gets
    #: FOC on the EKF instead, counted as a realignment); after ``realign_max`` realignments without a
    #: handover up in between, the fault latches (the safe state); 0: never
    stall_time: float = 3.0
    realign_max: int = 2
    #: the guard's soft limit [rad] [chosen: 90 deg]: beyond this lead over the rotor's angle the I-f vector
    #: turns no faster than the rotor. 90 deg is the pull-out angle of the magnet's torque N psi i sin e
    #: (past it more lead gives more torque only through the reluctance term, which is small against the
    #: magnet's at these currents): the lead stops growing where the torque per ampere is at its most,
    #: before the EKF, whose load state lags a sudden load, shows the rotor slowing
    soft_guard_angle: float = 0.5 * math.pi
    #: the guard lets go once the lead is back within ``soft_guard_angle`` less this [rad] [chosen: 3 deg]: a
    #: hysteresis against the swing of the EKF's angle at the limit (its noise at low speed with sigma = 1 A
    #: is of the order of a degree), so that a vector held there and turning with the rotor does not flicker
    #: in and out of the guard, and with it the current's rate (``i_rate_load``)
    guard_band: float = math.radians(3.0)
    #: in I-f at low speed the EKF is believed (``trust_rotor``) once it says the rotor has moved on the
    #: vector by more than this since it was last believed [rad] [chosen: 30 deg]: a load that changed pushes
    #: the rotor along the vector's spring, T = N psi i sin(e), and the motion shows the EKF the back-EMF.
    #: 30 deg is the move of a load change of half the vector's pull-out torque N psi i (sin 30 deg = 1/2;
    #: 10.8 N m at 60 A), half the design load angle (``if_load_angle``): the sizing follows while the
    #: other half is in reserve. What an EKF on a mismatched model drifts at a stop stays mostly below it
    #: (docs/sensorless.md, "What the stand is anchored on")
    trust_move: float = math.radians(30.0)
    #: a relocked vector (``relock``: after a slip at low speed, or a rotor running away under the alignment)
    #: leads the rotor in the direction of the torque that holds the EKF's load and brings the speed to the
    #: reference within this time [s] [chosen: 0.5 s]: the period of the rotor's swing on the vector
    #: (2 pi sqrt(J_eq / (N^2 psi i)): 0.49 s at 60 A, 0.19 s at 400 A), so that the direction is set by
    #: the load and the speed error, not by the swing's momentary speed
    relock_time: float = 0.5
    #: a stand in I-f ends once |omega_hat| has been above ``still_speed`` this long [s] [chosen: 50 ms]: the
    #: EKF's speed noise at a stand with sigma = 1 A of current noise crosses 0.5 rad/s for a few periods at a
    #: time; a rotor that really moves (a load beyond the vector) keeps above it. Half the slip detector's
    #: ``slip_time``, so that the stand's end (the EKF put back on the anchor) comes before a slip is declared
    still_time: float = 0.05

    @property
    def align_time(self) -> float:
        """Duration of the alignment [s]; the I-f start follows."""
        return self.t_ramp + self.t_hold + self.t_sweep + self.t_settle

    def validate(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            _require(math.isfinite(value) and value >= 0, f"{f.name} must be finite and >= 0 (got {value})")
        for name in ("i_align", "i_if", "if_accel", "i_rate", "omega_up", "agree_tol", "if_margin"):
            _require(getattr(self, name) > 0, f"{name} must be > 0 (got {getattr(self, name)})")
        _require(self.omega_down < self.omega_up,
                 f"omega_down must be < omega_up (got {self.omega_down} >= {self.omega_up} rad/s)")
        _require(self.if_margin >= 1.0, f"if_margin must be >= 1 (got {self.if_margin})")
        _require(0.0 < self.if_load_angle < 0.5 * math.pi,
                 f"if_load_angle must be in (0, pi/2) rad (got {self.if_load_angle})")
        _require(self.if_load_angle <= self.guard_angle < math.pi,
                 f"guard_angle must be in [if_load_angle, pi) rad (got {self.guard_angle})")
        for name in ("i_rate_load", "slip_time", "recover_time", "relock_time"):
            _require(getattr(self, name) > 0, f"{name} must be > 0 (got {getattr(self, name)})")
        _require(self.fault_time > self.recover_time,
                 f"fault_time must be > recover_time (got {self.fault_time} <= {self.recover_time} s)")
        _require(self.stall_time == 0 or self.stall_time > self.if_deadline,
                 f"stall_time must be > if_deadline or 0 (got {self.stall_time} <= {self.if_deadline} s)")
        _require(float(self.realign_max).is_integer(),
                 f"realign_max must be a whole number (got {self.realign_max})")


#: the sensorless unit's strategies at and near zero speed (``InjectionParams.low_speed``)
LOW_SPEED_STRATEGIES = ("if", "injection")


@dataclass(frozen=True)
class InjectionParams:
    """The sensorless unit at and near zero speed by high-frequency injection (``low_speed`` =
    "injection"; ``pmsm_ev.kernels.injection``, the unit's modes in ``pmsm_ev.kernels.modes``;
    docs/sensorless.md, "Closed loop at zero speed").

    At a stop no back-EMF shows the angle; the rotor's saliency does (Table I: L_q / L_d =
    1.44). A square wave of +-``inj_voltage`` on the estimated d axis changes the current by
    dt L^-1 v per period; seen from an axis off the rotor's by e, the q current answers
    dt v (1/L_d - 1/L_q) / 2 sin 2e (``pmsm_ev.kernels.demodulate``): an angle error signal,
    tracked by an observer with the drive's mechanical model (``inj_bandwidth``). It sees the
    axis, not its direction: the magnet's polarity comes from the d axis's saturation, which a
    positive d current deepens and a negative one relieves (pulses of +-``pol_current``).
    Above ``inj_blend_low`` the EKF's angle is blended in, and above ``inj_blend_high`` the
    EKF alone drives (injection off), as in the I-f strategy's FOC.

    Chosen values, each with its reason; where one comes from a publication it is named."""

    #: the strategy at and near zero speed [chosen]: "if" (``StartupParams``: alignment, I-f, handover;
    #: the default, as before) or "injection" (this class)
    low_speed: str = "if"
    #: the square wave's amplitude on the estimated d axis [V] [chosen]: 30 V, a seventh of the 208 V
    #: voltage limit. Its error signal, 2 dt V (1/L_d - 1/L_q) / 2 = 4.5 A per unit of sin 2e an answer
    #: with Table I, against the second difference of 1 A sensor noise (sqrt 6 x 1.15 A = 2.8 A): measured
    #: from 24 start angles with 1 A of noise, 0.05 rad rms of angle error at a stop (20 V: 0.08 rad). The
    #: d current's ripple is +-dt V / (2 L_d) = +-7.4 A, 4.3 A rms
    inj_voltage: float = 30.0
    #: the square wave's frequency [Hz]; 0 = half the control rate (5 kHz at 10 kHz) [chosen]: the
    #: highest there is, so the second difference of three samples cancels the fundamental's slope and no
    #: filter delays the signal (as motulator's square-wave injection, after Kim, Ha, Sul, "PWM switching
    #: frequency signal injection sensorless method in IPMSM", IEEE Trans. Ind. Appl. 48(5), 2012); lower
    #: ones are 1 / (2 m dt), m = 2 .. 8 control periods a half-wave. 5 kHz is audible (a tone at the
    #: square wave's frequency, as every injection method's)
    inj_frequency: float = 0.0
    #: the tracking observer's bandwidth [rad/s] [chosen]: its three poles at -50 rad/s (angle, speed and
    #: load torque with the drive's inertia and the model's torque, ``pmsm_ev.kernels.track``): it follows
    #: a load step in ~0.1 s, 25 times the speed loop's 2 rad/s; its noise bandwidth (about a, in Hz) sets
    #: the angle's noise (measured: 0.05 rad rms at 50 rad/s, 0.07 at 80)
    inj_bandwidth: float = 50.0
    #: the EKF's angle blended in from this |omega| [rad/s] ... [chosen: 15 rad/s, back-EMF 5.4 V]
    inj_blend_low: float = 15.0
    #: ... to this one, where the injection is off and the EKF alone drives [rad/s] [chosen: 30 rad/s,
    #: back-EMF 10.8 V, the I-f strategy's handover speed ``omega_up``]
    inj_blend_high: float = 30.0
    #: back into the injection below ``inj_blend_high`` less this [rad/s] [chosen: 5 rad/s]: a speed that
    #: hovers at the boundary does not switch the injection on and off
    inj_hysteresis: float = 5.0
    #: the angle's acquisition at enable, per axis [s] [chosen: 40 ms, 400 answers]: the axis is found
    #: from the q answers to injection on two axes 45 deg apart, sin 2e and -cos 2e (no bias from the mean
    #: inductance, no unstable point at e = 90 deg), averaged over this time (0.02 rad of noise). From
    #: enable to torque: 2 x 40 + 30 ms here, 120 ms of polarity test, 0.23 s
    inj_lock_time: float = 0.04
    #: then the tracking observer settles for this long before the polarity test [s] [chosen: 30 ms]
    inj_settle_time: float = 0.03
    #: the polarity test's d current [A] [chosen: 200 A, half of i_q_max]: the d axis's incremental
    #: inductance differs between +-i by the magnet's saturation (a few to ~15 % in IPMSMs, e.g. Jeong,
    #: Lorenz, Jahns, Sul, IEEE Trans. Ind. Appl. 41(1), 2005), more the larger i is; on the d axis it gives
    #: no torque. The test's contrast (``pol_contrast``) with the plant's default flux model is 0.047 at
    #: 100 A and 0.103 at 200 A (``pmsm_ev.kernels.incremental_inductances``), against a noise of its own of
    #: 0.013-0.016 rms with 1 A of sensor noise (measured over 30 start angles and motors each: L_d, L_q
    #: +-10 %, the d knee +-20 %). At 100 A one test in 13 ended unresolved (0.23 s more to torque; two in
    #: a row latch the fault); at 200 A the least of 30 was 0.071, 3.4 noise rms above ``pol_contrast``.
    #: 200 A for 2 x 40 ms heats the winding by far less than a second of the slope's current
    pol_current: float = 200.0
    #: its ramp to each sign [s] [chosen: 10 ms, 20 times the current loop's time constant]
    pol_ramp: float = 0.01
    #: ... and the time each sign is held and measured [s] [chosen: 40 ms, 400 samples]
    pol_hold: float = 0.04
    #: the least relative difference of the d axis's answers at +-``pol_current`` that decides the
    #: polarity [-] [chosen: 0.02]: the test's own noise is 0.013-0.016 rms (1 A of sensor noise), so a
    #: wrong decision needs the noise beyond the signal plus this (> 5 rms at 200 A), and an unresolved one
    #: below the signal less it. Below it the polarity is unresolved: the test is repeated once, then the
    #: fault latches (no torque is given on an unknown polarity)
    pol_contrast: float = 0.02
    #: cross-saturation compensated [chosen: True]: under load the incremental inductance's axes tilt (the
    #: plant's algebraic flux model: 15 deg at 233 A, 31 deg at 300 A), and the injection locks onto the axis
    #: nearest d, not onto d; the controller takes that offset from its model of the saturation (the
    #: algebraic model's defaults, ``PlantParams``, on its own motor's L_d, L_q, psi) against i_q (at
    #: i_d = 0), as a table every ``CROSS_STEP`` = 50 A (``pmsm_ev.kernels.cross_offset``). False: no compensation
    inj_cross_comp: bool = True
    #: loss of synchronism under injection: the tracking observer's angle error above this [rad] ...
    #: [chosen: 0.5 rad, four times the error at the load's saturation]
    inj_los_angle: float = 0.5
    #: ... for this long [s] [chosen: 50 ms, seven time constants of the tracking observer]
    inj_los_time: float = 0.05
    #: loss of synchronism on the EKF (the injection strategy's FOC on the EKF alone): the EKF's current
    #: innovation, low-pass filtered over ``inj_los_time`` / ``LOS_FILTER_CONSTANTS`` (3), above this [A] plus the
    #: current the back-EMF drives in a period, dt N |omega_hat| psi / L_q (25 A at 200 rad/s, 139 A at 1120 rad/s)
    #: ... [chosen: 60 A]. Healthy, the innovation is the sensors' noise and the share of the back-EMF a motor that is
    #: not the model's leaves unexplained: 2-8 A on the nominal motor, 25 A at 200 rad/s on a hot one (R_s +50 %,
    #: psi -12 %), more than 60 A at 1120 rad/s in field weakening on R_s +44 %, psi -10 % (a fixed bound there
    #: latched the safe state on a healthy drive); an EKF whose angle has left the rotor's leaves more than the
    #: whole back-EMF's current unexplained
    ekf_los_current: float = 60.0
    #: ... for this long [s] [chosen: 0.2 s]
    ekf_los_time: float = 0.2
    #: the q current while the injection carries the angle (mode 5) [A], rising to the drive's own limit with
    #: the EKF's weight in the blend (no step when the EKF takes over) [chosen: 300 A]. Load tilts the
    #: incremental inductance's axes (cross-saturation: the controller's model of the plant's defaults, 18 deg
    #: at 250 A, 31 deg at 300 A, 69 deg at 400 A), and the injection locks onto the axis nearest d; the
    #: offset is compensated from the controller's model, but where the tilt nears 45 deg the axis nearest d
    #: becomes the one nearest q, and on a motor that saturates earlier than the model the compensation turns
    #: into an error that feeds itself. Measured on the synchronism matrix's step to 200 rad/s at enable (8
    #: angles, 1 A of noise): with the full 393 A 1-6 turns slipped on the default motor; with 350 A none
    #: there, but 11 on a motor whose q knee is 20 % below the model's (the Monte-Carlo's range); with 300 A
    #: none on either. 250 A would cost 1-2.7 cm more roll-back when a creeping car meets 22 deg (the slope
    #: needs 227 A at a stop). Beyond it the car is held with 300 A: about 30 deg
    inj_current_limit: float = 300.0
    #: the polarity test's frame [rad] [chosen: 0.15 rad, three times the tracking observer's angle noise at
    #: a stop, 0.05 rad rms]: the frame stays on the axis the acquisition found (its average over 80 ms: 0.025
    #: rad rms with 1 A of noise, 0.05 with 2 us of dead time compensated) while the observer moves less than
    #: this from it (the rotor stands: the observer's noise would leak pol_current sin e onto q, torque that
    #: moves the car: 0.95 mm at 200 A when the frame followed it), and follows the observer this far behind
    #: when the rotor turns (a car that rolls while the test runs)
    pol_frame_band: float = 0.15
    #: the hill hold at enable [-] [chosen: 1]: from enable until the unit first gives torque (the
    #: acquisition and the polarity test, 0.23 s; for good where the polarity is never resolved) it asks the
    #: friction brake (output ``T_brake``) for this times the drive's own torque limit at the wheels,
    #: T_max n_g eta (1837 N m with Table I and II): the brake then holds any slope the drive itself could,
    #: and a car parked on one does not roll free while the unit finds the angle (1/2 g sin(delta) t^2: 4.3 cm
    #: on 8 deg in 0.23 s, 8.5 cm on 16 deg). A car's hill-hold function does the same until the drive reports
    #: torque (the unit's ``mode`` output: 5). The plant's brake opposes motion with the smooth sign
    #: tanh(v / v_eps) (``VehicleParams.v_eps``), so a held car creeps at v_eps atanh(load / brake): 4 mm/s on
    #: 16 deg with 900 kg. 0: no hold
    hold_brake: float = 1.0
    #: the identification at enable, on each axis [s] [chosen: 50 ms, 500 answers a side]: after the axis is
    #: found, the d admittance of the square wave's answers on the found d axis and then on the q axis is the
    #: motor's incremental 1/L_d and 1/L_q at zero current ((I1) at e = 0 and 90 deg, with the answers' cross parts
    #: whatever the found axis's error e, (ID5), ``pmsm_ev.kernels.identify``), and Y_x = (1/L_d - 1/L_q) / 2 the
    #: error signal's gain: the tracking
    #: observer then keeps the bandwidth its poles say on a motor that is not its data sheet (a saliency a third
    #: of the model's leaves it a third of the gain, and an error signal that never reaches the loss detector's
    #: angle). The second difference's noise at the square wave's frequency is 4 sigma an answer, over 500
    #: answers 4 sigma / sqrt(500) / (2 dt V) = 30 1/H a sigma of 1 A (0.7 % of 1/L_d with Table I; Y_x to 21
    #: 1/H, 3 % of Table I's 751). The acquisition then takes 2 x 40 + 30 + 2 x 50 ms and the polarity test
    #: 120 ms: 0.33 s from enable to torque, the car held (``hold_brake``). Only at the first acquisition after
    #: enable (a reacquisition may find the car rolling). 0: not measured, the model's L_d, L_q (a drive whose
    #: data sheet is its motor's)
    id_time: float = 0.06
    #: the least identified saliency L_q / L_d at which the injection is trusted [-] [chosen: 1.10]: the error
    #: signal's amplitude is Y_x = (1/L_d - 1/L_q) / 2, (L_q/L_d - 1) / (2 L_q) of it; at 1.10 that is 11 % of
    #: 1/L_d (Table I's 1.44: 31 %), 1.0 A an answer at 30 V against the second difference's 2.8 A of noise
    #: with sigma = 1 A, the angle's noise at a stop four times Table I's (0.05 rad rms there): 0.2 rad, where
    #: the load's tilt of the axes (cross-saturation) is of the same size. Below it the unit says so (output
    #: ``blind``)
    saliency_min: float = 1.10
    #: the least saliency a blind unit's pooled answers must show for it to trust the injection again [-] [chosen:
    #: 1.15, ``saliency_min`` and 4.6 % more]: at every stop a blind unit measures its motor again and pools the
    #: answers (``pmsm_ev.kernels.refining``), which takes the sensors' noise out but not, at one stop's rotor
    #: angle, the phase sensors' gain mismatch, which reads the saliency off by up to 2 |g_a - g_b| / sqrt 3 (4.6 %
    #: with gains +-2 %). Issue 47's motor A (1.146, gains 0.981 / 1.011) pooled 1.100 over its first stop and,
    #: trusted there, crept back 80 mm at a later stop on the injection (2.6 mm parked; the sensored drive 42 mm)
    saliency_trust: float = 1.15
    #: the tracking observer has lost the axis where cos 2e from the d admittance (``pmsm_ev.kernels.axis_cosine``:
    #: (I1), adm = Y_s + Y_x cos 2e with the identified Y_s, Y_x), filtered as the angle error is, stays below
    #: this for ``inj_los_time`` [-] [chosen: -0.5, 60 deg]: at 45 deg (cos 2e = 0) the error signal sin 2e no
    #: longer pulls the observer back harder the farther it is, and beyond it pulls it to the axis 90 deg on (the
    #: q axis, then the d axis pi from the right one); the margin to 0 is for the load: the d admittance under
    #: load (a negative d current relieves the d axis, the q current saturates the iron) is not the zero-current
    #: one the identification measured
    inj_axis_cos: float = -0.5
    #: the square wave's largest amplitude [V] [chosen: 90 V, below half the 208 V voltage limit, the rest for the
    #: current loops at a stop]: after the identification the amplitude is the one whose error signal has the
    #: current per unit of sin 2e the data sheet's motor gives at ``inj_voltage``, as the square wave sees it (the
    #: inverter's dead time's share of the answers made up, eq ID4 in ``pmsm_ev.kernels.identify``):
    #: a motor with a third of the saliency gets three times the voltage, so that the sensors' noise and the
    #: inverter's dead time (a voltage of a few V per half-wave, not compensated where the ripple crosses zero)
    #: take no larger a share of the angle than on the data sheet's motor. The d current's ripple grows with it
    #: (+-dt V / (2 L_d): +-20 A at 90 V on Table I's L_d)
    inj_voltage_max: float = 90.0
    #: the R_s test at enable, its upper d current [A] [chosen: 200 A, the polarity test's: the winding heats no
    #: more than there]; the lower level is half of it. After the identification, on the found d axis at
    #: standstill, the d current is held at each level (``rs_time``) and R_s = (v_2 - v_1) / (i_2 - i_1) from
    #: the d PI's integral (``pmsm_ev.kernels.identify_rs``, eq ID2): the difference cancels the inverter's
    #: dead-time voltage, which is the same at both levels where the phases' currents keep their signs. 100 A
    #: apart give 0.87 V on Table I's 8.7 mOhm
    rs_current: float = 200.0
    #: ... the time at each level [s] [chosen: 40 ms, the second half measured: the current loop settles in a
    #: few ms]; 0: no test (a drive already commissioned). Enable to torque with it: 0.41 s, within the 0.5 s a
    #: driver waits for a car that has said it is ready
    rs_time: float = 0.04
    #: the offset window at enable [s] [chosen: 20 ms, 200 samples: a sensor's offset to sigma / sqrt(200), 0.07 A
    #: at sigma = 1 A]: before the square wave starts the unit sends no voltage (the inverter's gates off, as a
    #: drive calibrates its current sensors), the motor at rest carries no current, and the mean of each sensor is
    #: its offset, subtracted from the measurements from then on (``pmsm_ev.kernels.modes``, outputs
    #: ``offset_a_id``, ``offset_b_id``). With the current loops closed the measured mean is held at 0 whatever the
    #: offset (the motor then carries minus the offset), so the offset shows only with no voltage. Only at the
    #: first acquisition after enable; 0: not measured
    ofs_time: float = 0.02
    #: the largest angle accuracy at a stop (eq ID3: the tracking observer's rms angle error from the measured
    #: saliency, noise floor and amplitude) at which the injection is trusted [rad] [chosen: 0.15 rad, the polarity
    #: test's frame band ``pol_frame_band`` and a third of the loss detector's ``inj_los_angle``]: a noisier angle
    #: moves the polarity test's frame with its noise (the torque it leaks moves the car) and meets the loss
    #: detector's angle at three of its rms. Beyond it the unit is blind as below ``saliency_min``. Table I's motor
    #: at sigma = 1 A and 30 V: 0.05 rad (as measured from 24 start angles); at the saliency limit 1.10 with the
    #: amplitude at ``inj_voltage_max``: 0.06 rad at 1 A, 0.15 rad at 2.6 A: below 2.6 A of noise the saliency
    #: limit is the stricter, beyond it this one
    inj_angle_max: float = 0.15
    #: the largest angle accuracy at a stop (eq ID3) at which a blind unit still finds the axis at every stop for its
    #: parked fallback (``pmsm_ev.kernels.cannot_see``); beyond it the unit cannot see and takes the I-f strategy for
    #: good [rad] [chosen: pi/12, 0.26 rad: three of its rms within pi/4, where the error signal sin 2e stops pointing
    #: back to the axis. The Monte-Carlo of the wide design's low-saliency corner (docs/robustness.md): at
    #: ``inj_angle_max`` (0.15) 9 motors of 30 fell back to the I-f strategy and 8 of them failed; 4 of the 6 with an
    #: accuracy of 0.16 to 0.25 rad passed on the parked fallback instead (model_source "identified", adaptation "use")]
    inj_see_max: float = math.pi / 12.0
    #: the back-EMF detector (``pmsm_ev.kernels.detect_emf_lost``, eqs LS1-LS2), in FOC on the injection and the
    #: blend: the back-EMF the current PIs' integrators carry beyond what the frame's speed explains, as a speed
    #: [rad/s], beyond this (plus ``emf_slip_rel`` of the rotor's speed the loops see) for ``inj_los_time`` is a
    #: rotor that turns under a frame that does not follow it, or a frame that spins over a standing rotor
    #: [chosen: 12 rad/s, 4.3 V with Table I's psi: above the voltages a healthy drive leaves unexplained at low
    #: speed, the dead-time compensation 30 % below the inverter's (2.2 V a phase) with a magnet 15 % weak (its EKF's
    #: speed 15 % low at the handover down) and the sensors' noise; below the blend's lower speed ``inj_blend_low``
    #: (15), where a frame that spins over a standing rotor is held by the EKF's pull as it enters the blend (issue 47's
    #: motor A with the identification off: 3 turns in 0.45 s at 14.9-16.8 rad/s, unseen at 15, an episode at 12).
    #: Measured on udds-sensorless, sigma = 1.5 A: issue 47's motors A and B 0 episodes at 10, 12 and 15 rad/s, motor
    #: A 17 at 5 rad/s; a motor with the compensation 30 % low, psi -15 %, R_s +60 %: at 12 and 15 rad/s the same 2
    #: episodes (its other detectors'), at 10 rad/s (before the identification's ID5) 2 more that were not slips]
    emf_slip_speed: float = 12.0
    #: ... plus this share of the rotor's speed the current loops see (all the back-EMF they carry, as a speed) [-]
    #: [chosen: 0.25: the magnet's psi up to 15 % below the model's (cold data sheet, warm magnet) and the
    #: decoupling's inductances (L_d, L_q +-15 %) at the injection's current; a frame at the rotor's speed but 0.5
    #: rad off its angle leaves 2 sin(e / 2) = 0.49 of it, a frame spinning over a standing rotor all of its speed]
    emf_slip_rel: float = 0.25
    #: the phase sensors' relative gain g_a / g_b is measured on the EKF over this many electrical turns before the
    #: unit uses it [-] [chosen: 200: the balanced phase currents have equal squares over whole turns, and the part
    #: turn left at either end of the sums is at most 1/200 of them, 0.25 % of the ratio, against the +-4 % that two
    #: sensors within +-2 % can differ by; 3 s at 50 km/h]. (eqs SG1-SG2, ``pmsm_ev.kernels.balance_sensors``:
    #: the phase b measurement is scaled by the ratio from then on, so that the two sensors read alike and their
    #: mismatch no longer shows in the injection's answers as a saliency fixed to the stator.) 0: not measured
    gain_turns: float = 200.0
    #: the least identified saliency L_q / L_d at which a seeing unit holds the car on the injection at its stops [-]
    #: [chosen: 1.30]; below it the unit parks at its stops (``park_car``, as a blind one does: the friction brake
    #: holds the car, the angle found afresh for each restart). Two reasons. A gain mismatch g_a - g_b reads as a
    #: saliency fixed to the stator, (g_a - g_b) / sqrt 3 of the mean admittance Y_s, against the rotor's
    #: Y_x = Y_s (s - 1) / (s + 1); two sensors within +-2 % (0.04 apart) turn the injection's axis by up to
    #: asin(0.023 (s + 1) / (s - 1)) / 2: 0.13 rad at s = 1.20, 0.25 rad at 1.10, until the ratio is measured (SG0,
    #: SG1); with the sensors' noise at 1.5 A (0.15-0.2 rad at a stop) the sum slipped turns at stops (the wide
    #: design's low-saliency corner, seed 5151: a motor of saliency 1.10, gains 1.020 / 0.993, 8 turns on UDDS).
    #: And a car that creeps under a hold on a slope turns the rotor faster than a weak error signal pulls the
    #: tracking observer: that corner's motor of 1.085 (seed 6464, read 1.13), its sensors measured, slipped a turn
    #: at a hold on a 1.9 % slope, twice (once reported, once not). The threshold is on the saliency as identified,
    #: which the mismatch reads up to 0.05 high and the sensors' noise (sigma = 1.5 A) 0.03 high and 0.04 rms apart
    #: (the 1.10 motor read 1.25): 1.20 and those, where Table I's motor (1.44) reads 1.36 on ``udds-sensorless``
    #: and keeps holding on the injection. 0: off (a blind unit parks whatever)
    saliency_hold: float = 1.30
    #: the standard error of the phase sensors' relative gain, measured at standstill from a parked unit's pooled
    #: answers (eq SG0, ``pmsm_ev.kernels.standstill_gain``), at which the unit takes it before it has driven [-].
    #: 0 (off) by default: the inverter's dead time biases it. Measured on a motor of 1.11 with sensors 3.2 % apart
    #: (g_a / g_b 1.0316) at 1.5 A: with 2 us of dead time compensated it read 1.0647 at one rotor angle and 1.0523
    #: at another (the compensation's sign decisions on noisy currents, phase c's noise the larger); with the dead
    #: time uncompensated 1.0391, without dead time 1.0373 (1.0305 without noise). A unit that took 1.0761 on a
    #: study's motor (the low-saliency corner, seed 8484, sample 24) read its sensors further apart than they were and
    #: slipped at its first drive-off. Where it is set (0.005: an eighth of the +-4 % two sensors within +-2 % can
    #: differ by) a parking unit pools its answers while parked (``pools``) and one that cannot see waits for it.
    gain_standstill_se: float = 0.0

    def half_wave(self, dt: float) -> int:
        """The square wave's half-period in control periods, m (``inj_frequency`` = 1 / (2 m dt))."""
        if self.inj_frequency == 0:
            return 1
        return round(1.0 / (2.0 * self.inj_frequency * dt))

    def validate(self, dt: float | None = None, u_max: float | None = None) -> None:
        _require(self.low_speed in LOW_SPEED_STRATEGIES,
                 f"low_speed must be one of {LOW_SPEED_STRATEGIES} (got {self.low_speed!r})")
        for f in fields(self):
            if f.name in ("low_speed", "inj_cross_comp", "inj_axis_cos"):
                continue
            value = getattr(self, f.name)
            _require(math.isfinite(value) and value >= 0, f"{f.name} must be finite and >= 0 (got {value})")
        for name in ("inj_voltage", "inj_bandwidth", "inj_blend_high", "inj_lock_time", "pol_current",
                     "pol_hold", "pol_contrast", "inj_los_angle", "inj_los_time", "ekf_los_current",
                     "ekf_los_time", "inj_current_limit", "pol_frame_band", "emf_slip_speed"):
            _require(getattr(self, name) > 0, f"{name} must be > 0 (got {getattr(self, name)})")
        _require(-1.0 < self.inj_axis_cos < 1.0,
                 f"inj_axis_cos must be within (-1, 1): a cosine of 2e (got {self.inj_axis_cos})")
        _require(self.saliency_min >= 1.0,
                 f"saliency_min must be >= 1: a saliency L_q / L_d (got {self.saliency_min})")
        _require(self.saliency_trust >= self.saliency_min,
                 f"saliency_trust must be >= saliency_min {self.saliency_min:g} (got {self.saliency_trust})")
        _require(self.saliency_hold == 0.0 or self.saliency_hold >= 1.0,
                 f"saliency_hold must be 0 (off) or >= 1: a saliency L_q / L_d (got {self.saliency_hold})")
        _require(self.gain_turns == 0.0 or self.gain_turns >= 10.0,
                 f"gain_turns must be 0 (not measured) or >= 10 electrical turns (got {self.gain_turns})")
        _require(self.gain_standstill_se < 0.04,
                 f"gain_standstill_se must be 0 (not measured) or below 0.04, the sensors' mismatch span "
                 f"(got {self.gain_standstill_se})")
        _require(self.rs_time == 0.0 or self.rs_time >= 0.002,
                 f"rs_time must be 0 (no test) or >= 0.002 s, ten current-loop time constants (got {self.rs_time})")
        _require(self.rs_time == 0.0 or self.rs_current > 0.0,
                 f"rs_current must be > 0 A (got {self.rs_current})")
        _require(self.ofs_time == 0.0 or self.ofs_time >= 0.001,
                 f"ofs_time must be 0 (not measured) or >= 0.001 s, ten samples (got {self.ofs_time})")
        _require(0.0 < self.inj_angle_max < 0.25 * math.pi,
                 f"inj_angle_max must be within (0, pi/4) rad: beyond pi/4 the error signal sin 2e no longer points "
                 f"back to the axis (got {self.inj_angle_max})")
        _require(self.inj_angle_max <= self.inj_see_max < 0.25 * math.pi,
                 f"inj_see_max must be within [inj_angle_max, pi/4) rad (got {self.inj_see_max})")
        _require(self.id_time == 0.0 or self.id_time >= 0.005,
                 f"id_time must be 0 (not measured) or >= 0.005 s, 50 answers an axis (got {self.id_time})")
        _require(self.inj_blend_low < self.inj_blend_high,
                 f"inj_blend_low must be < inj_blend_high (got {self.inj_blend_low} >= {self.inj_blend_high} rad/s)")
        _require(self.inj_hysteresis < self.inj_blend_high - self.inj_blend_low,
                 f"inj_hysteresis must be < inj_blend_high - inj_blend_low (got {self.inj_hysteresis} rad/s)")
        if u_max is not None:
            _require(self.inj_voltage < 0.5 * u_max,
                     f"inj_voltage must be < half the voltage limit {0.5 * u_max:.4g} V (got {self.inj_voltage})")
        _require(self.inj_voltage_max >= self.inj_voltage,
                 f"inj_voltage_max must be >= inj_voltage (got {self.inj_voltage_max} < {self.inj_voltage} V)")
        if u_max is not None:
            _require(self.inj_voltage_max < 0.5 * u_max,
                     f"inj_voltage_max must be < half the voltage limit {0.5 * u_max:.4g} V "
                     f"(got {self.inj_voltage_max})")
        if dt is not None and self.inj_frequency != 0:
            m = 1.0 / (2.0 * self.inj_frequency * dt)
            allowed = ", ".join(f"{1.0 / (2.0 * k * dt):.6g}" for k in range(1, 9))
            _require(m >= 1.0 - 1e-9 and abs(m - round(m)) < 1e-6 and round(m) <= 8,
                     f"inj_frequency must be half the control rate or a fraction 1/(2 m dt), m = 1..8: one of "
                     f"{allowed} Hz at dt = {dt:g} s (got {self.inj_frequency})")


#: the EKF of the sensorless unit: the paper's covariances, the drive's whole inertia J_eq
#: in the mechanical model (see ``EkfParams.J_model``)
SENSORLESS_EKF = EkfParams(J_model=equivalent_inertia(MotorParams(), VehicleParams()))


@dataclass(frozen=True)
class ScenarioParams:
    """Speed reference of section III: 200 rad/s, reached from standstill."""

    omega_ref: float = 200.0  #: speed reference [rad/s] (Fig. 8)
    #: start-up ramp time [s] [chosen]: 0 -> 200 rad/s in 10 s needs 20 rad/s^2, i.e.
    #: 10.5 N m of acceleration torque on J_eq; the first plateau (50 s) leaves ample
    #: time to settle. Fig. 8 shows only the constant reference.
    startup_time: float = 10.0

    def validate(self) -> None:
        _require(math.isfinite(self.omega_ref), "omega_ref must be finite")
        _require(self.startup_time >= 0, f"startup_time must be >= 0 s (got {self.startup_time})")


@dataclass(frozen=True)
class DriveParams:
    """Everything a run needs, grouped."""

    motor: MotorParams = field(default_factory=MotorParams)
    vehicle: VehicleParams = field(default_factory=VehicleParams)
    plant: PlantParams = field(default_factory=PlantParams)
    controller: ControllerParams = field(default_factory=ControllerParams)
    ekf: EkfParams = field(default_factory=EkfParams)
    scenario: ScenarioParams = field(default_factory=ScenarioParams)
    startup: StartupParams = field(default_factory=StartupParams)  #: the sensorless unit only
    #: the sensorless unit's injection at and near zero speed (``low_speed``; off by default)
    injection: InjectionParams = field(default_factory=InjectionParams)
    dt: float = DT_DEFAULT  #: control period = communication step [s]

    def validate(self) -> "DriveParams":
        for group in (self.motor, self.vehicle, self.plant, self.controller, self.ekf, self.scenario, self.startup,
                      self.injection):
            group.validate()
        self.controller.validate_limits(self.motor)
        _require(math.isfinite(self.dt) and self.dt > 0, f"dt must be > 0 s (got {self.dt})")
        return self


def with_overrides(params, **changes):
    """``dataclasses.replace`` that names the parameter group in its error."""
    names = {f.name for f in fields(params)}
    unknown = sorted(set(changes) - names)
    if unknown:
        raise ParameterError(f"{type(params).__name__} has no parameter {', '.join(unknown)}")
    return replace(params, **changes)
