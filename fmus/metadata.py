"""Units and descriptions of the FMU variables (data only, no physics).

``PARAMETERS`` describes every field of the parameter dataclasses in ``pmsm_ev.params``
that an FMU exposes: ``name -> (unit, description)``; ``unit`` is ``None`` for
dimensionless, Integer, Boolean and String variables. The tests check that every field
of those dataclasses has an entry here, so a new field in ``pmsm_ev.params`` shows up as
a failing test rather than as an FMU variable without unit or description.

``UNITS`` holds the SI base-unit exponents written to ``<UnitDefinitions>`` (FMI 2.0,
section 2.2.2); ``DISPLAY_UNITS`` the display units offered for some of them.
"""

from __future__ import annotations

import math

#: unit name -> exponents of the SI base units (FMI 2.0 BaseUnit attributes)
UNITS: dict[str, dict[str, float]] = {
    "V": {"kg": 1, "m": 2, "s": -3, "A": -1},
    "A": {"A": 1},
    "A2": {"A": 2},
    "rad": {"rad": 1},
    "rad2": {"rad": 2},
    "rad/s": {"rad": 1, "s": -1},
    "rad2/s2": {"rad": 2, "s": -2},
    "s": {"s": 1},
    "N.m": {"kg": 1, "m": 2, "s": -2},
    "W": {"kg": 1, "m": 2, "s": -3},
    "N2.m2": {"kg": 2, "m": 4, "s": -4},
    "N.m.s/rad": {"kg": 1, "m": 2, "s": -1, "rad": -1},
    "N.m.s2/rad2": {"kg": 1, "m": 2, "rad": -2},
    "m/s": {"m": 1, "s": -1},
    "m/s2": {"m": 1, "s": -2},
    "m": {"m": 1},
    "m2": {"m": 2},
    "kg": {"kg": 1},
    "kg/m3": {"kg": 1, "m": -3},
    "kg.m2": {"kg": 1, "m": 2},
    "Ohm": {"kg": 1, "m": 2, "s": -3, "A": -2},
    "H": {"kg": 1, "m": 2, "s": -2, "A": -2},
    "Wb": {"kg": 1, "m": 2, "s": -2, "A": -1},
    "V/A": {"kg": 1, "m": 2, "s": -3, "A": -2},
    "V/(A.s)": {"kg": 1, "m": 2, "s": -4, "A": -2},
    "A.s/rad": {"A": 1, "s": 1, "rad": -1},
    "A/s": {"A": 1, "s": -1},
    "rad/s2": {"rad": 1, "s": -2},
    "A/rad": {"A": 1, "rad": -1},
    "degC": {"K": 1, "offset": 273.15},  # FMI 2.0 BaseUnit: value in K = value in degC + offset
    "1/K": {"K": -1},
    "1/s": {"s": -1},
    "Hz": {"s": -1},
    "K/W": {"K": 1, "kg": -1, "m": -2, "s": 3},
    "J/K": {"kg": 1, "m": 2, "s": -2, "K": -1},
    "J": {"kg": 1, "m": 2, "s": -2},
    "C": {"A": 1, "s": 1},
}

#: unit name -> [(display unit, factor)], display value = factor * value
DISPLAY_UNITS: dict[str, list[tuple[str, float]]] = {
    "rad": [("deg", 180.0 / math.pi)],
    "rad/s": [("rpm", 30.0 / math.pi)],
    "m/s": [("km/h", 3.6)],
    "J": [("Wh", 1.0 / 3600.0)],
    "W": [("kW", 1.0e-3)],
}

_T1 = " (Table I)"
_T2 = " (Table II)"

#: parameter name -> (unit, description); names are the dataclass field names
PARAMETERS: dict[str, tuple[str | None, str]] = {
    # MotorParams: Table I of the paper plus the friction terms of eq 8
    "N": (None, "pole pairs" + _T1),
    "psi": ("Wb", "permanent-magnet flux linkage [V s/rad]" + _T1),
    "L_d": ("H", "d-axis inductance" + _T1),
    "L_q": ("H", "q-axis inductance" + _T1),
    "R_s": ("Ohm", "stator resistance" + _T1),
    "J_m": ("kg.m2", "rotor inertia" + _T1),
    "B_m": ("N.m.s/rad", "viscous friction coefficient of eq 8"),
    "T_m0": ("N.m", "constant (Coulomb) friction torque of eq 8"),
    "omega_eps": ("rad/s", "speed scale of the smooth sign of T_m0 (load_model 'physical')"),
    "k_wind": (None, "windage coefficient k_wind [N m s^2/rad^2] of the drag k_wind omega |omega| beside eq 8, a "
                     "power k_wind |omega|^3 (0 = off)"),
    "dq_convention": (None, "dq convention: 'paper' (eq 12 as printed, power v_d i_d + v_q i_q) or "
                            "'amplitude_invariant' (amplitude-invariant dq quantities: torque and power x 3/2)"),
    # VehicleParams: Table II
    "c_r": (None, "rolling-resistance coefficient" + _T2),
    "g": ("m/s2", "gravitational acceleration" + _T2),
    "rho_a": ("kg/m3", "air density" + _T2),
    "c_d": (None, "aerodynamic drag coefficient" + _T2),
    "A_f": ("m2", "frontal area" + _T2),
    "r_w": ("m", "wheel radius" + _T2),
    "eta": (None, "gear efficiency, in (0, 1]" + _T2),
    "n_g": (None, "gear ratio, motor speed / wheel speed" + _T2),
    "m_v": ("kg", "vehicle mass" + _T2),
    "v_a": ("m/s", "head-wind speed, added to the vehicle speed in the drag force (eq 4)" + _T2),
    "load_model": (None, "road-load model: 'physical' (rolling resistance and friction oppose motion, "
                         "drag along the relative air speed) or 'paper' (eqs 3-4 and 8 as printed)"),
    "v_eps": ("m/s", "speed scale of the smooth sign of rolling resistance (load_model 'physical')"),
    "gear_model": (None, "gear efficiency: 'paper' (eq 9 as printed: the reflected mass and every wheel force "
                         "divided by eta) or 'power_flow' (eta in the direction the power flows through the gear)"),
    # PlantParams: numerics and initial state
    "rk4_substeps": (None, "RK4 sub-steps per communication step (at least; see substep_angle)"),
    "substep_angle": ("rad", "largest electrical angle per RK4 sub-step: a step takes max(rk4_substeps, "
                             "ceil(N |omega_m| h / substep_angle)) sub-steps; 0 = off (integrator 'rk4_rotor')"),
    "integrator": (None, "the frame the plant's RK4 integrates in: 'rk4_rotor' (the rotor's dq frame, sub-steps by "
                         "substep_angle) or 'rk6_stationary' (the flux linkages in the stationary frame, where the "
                         "held voltage is constant; docs/performance.md)"),
    "stationary_substep_angle": ("rad", "largest electrical angle per sub-step of the stationary-frame RK4 "
                                        "(integrator 'rk6_stationary')"),
    "i_d0": ("A", "initial d-axis current"),
    "i_q0": ("A", "initial q-axis current"),
    "omega_m0": ("rad/s", "initial mechanical rotor speed"),
    "theta_e0": ("rad", "initial electrical rotor angle"),
    # ControllerParams: FOC, eqs 14-20; the gains derived at initialisation (pmsm_ev.controller.controller_gains)
    "omega_c": ("rad/s", "current-loop bandwidth: the current PIs get K_p = L omega_c, K_i = R_s omega_c (L_d, L_q, "
                         "R_s of this controller's motor model), T_d = 1/omega_c"),
    "omega_n": ("rad/s", "speed-loop natural frequency: K_p = 2 zeta omega_n J / (N psi), K_i = omega_n^2 J / (N psi), "
                         "J = J_m + J_load"),
    "zeta": (None, "speed-loop damping ratio"),
    "J_load": ("kg.m2", "vehicle inertia at the motor shaft the speed-loop design assumes, r_w^2 m_v / (eta n_g^2) "
                        "of eq 9 (Table II); the speed PI is tuned on J_m + J_load"),
    "kp_w": ("A.s/rad", "speed PI proportional gain (eq 14); 0 = derived, 2 zeta omega_n (J_m + J_load) / (N psi)"),
    "ki_w": ("A/rad", "speed PI integral gain (eq 14); 0 = derived, omega_n^2 (J_m + J_load) / (N psi)"),
    "kp_id": ("V/A", "d-current PI proportional gain (eq 15); 0 = derived, L_d omega_c"),
    "ki_id": ("V/(A.s)", "d-current PI integral gain (eq 15); 0 = derived, R_s omega_c"),
    "kp_iq": ("V/A", "q-current PI proportional gain (eq 16); 0 = derived, L_q omega_c"),
    "ki_iq": ("V/(A.s)", "q-current PI integral gain (eq 16); 0 = derived, R_s omega_c"),
    "T_d": ("s", "time constant of the decoupling low-pass filters (eqs 17-18); 0 = derived, 1/omega_c"),
    "i_d_ref": ("A", "d-current reference"),
    "i_q_max": ("A", "q-current reference limit"),
    "u_max": ("V", "voltage-vector magnitude limit"),
    "reference": (None, "current references: 'paper' (i_d = i_d_ref, i_q from the speed PI), 'mtpa' (the speed PI "
                        "commands a torque, MTPA within i_max and T_max) or 'fw' (MTPA, field weakening and MTPV "
                        "under the voltage limit v_dc/sqrt(3) x fw_margin; needs v_dc)"),
    "i_max": ("A", "current-magnitude limit of the references 'mtpa' and 'fw'"),
    "T_max": ("N.m", "torque limit of the references 'mtpa' and 'fw' (0 = what i_max gives on MTPA)"),
    "fw_margin": (None, "share of the voltage limit that field weakening plans with (the rest: R_s drop, "
                        "current-loop transients, the rotation during a period)"),
    "P_regen_max": ("W", "regenerative power limit of the references 'mtpa' and 'fw' (0 = no limit): a braking "
                         "demand beyond it goes to the friction brake (T_brake)"),
    "speed_feedforward": (None, "the speed loop's feedforward (references 'mtpa' and 'fw'): 'none', 'inertia' "
                                "(J_eq x the reference's acceleration) or 'inertia+road' (plus the level road's "
                                "load at the reference speed, ff_T0 + ff_T1 |w| + ff_T2 w^2); docs/cycles.md"),
    "ff_T0": ("N.m", "road-load feedforward at the shaft: constant term (Table II's rolling and head-wind drag)"),
    "ff_T1": ("N.m.s/rad", "road-load feedforward at the shaft: term in |omega_ref|"),
    "ff_T2": ("N.m.s2/rad2", "road-load feedforward at the shaft: term in omega_ref^2"),
    "decoupling": (None, "decoupling signs: 'physical' (cancels the back-EMF and cross-coupling of eq 11) "
                         "or 'paper' (eq 20 as printed)"),
    "angle_advance": (None, "advance of the inverse-Park angle, in control periods of omega_hat"),
    "zoh_compensation": (None, "lengthen the held voltage vector by a/sin(a), a = omega_e dt/2"),
    "current_control": (None, "current control: 'paper' (eqs 15-20, decoupling on the filtered references, the "
                              "whole vector scaled at u_max, integrators held) or 'high_speed' (decoupling on the "
                              "current predicted at mid-period, back-EMF priority under the voltage limit with "
                              "realisable-reference anti-windup, ZOH gain sin(a)/a; docs/speed-range.md)"),
    # EkfParams: diagonal covariances of eqs 24-27
    "q_i": ("A2", "EKF process noise of the currents, per step"),
    "q_omega": ("rad2/s2", "EKF process noise of the speed, per step (5-state EKFs)"),
    "q_theta": ("rad2", "EKF process noise of the angle, per step"),
    "q_TL": ("N2.m2", "EKF process noise of the load torque, per step (5-state EKFs)"),
    "r_i": ("A2", "EKF measurement noise of the currents"),
    "p0_i": ("A2", "EKF initial covariance of the currents"),
    "p0_omega": ("rad2/s2", "EKF initial covariance of the speed"),
    "p0_theta": ("rad2", "EKF initial covariance of the angle"),
    "p0_TL": ("N2.m2", "EKF initial covariance of the load torque (5-state EKFs)"),
    "q_omega_ekf4": ("rad2/s2", "EKF process noise of the speed, per step (EKF4 only)"),
    "sensor_noise": ("A", "white noise on each measured phase current, standard deviation (0 = off)"),
    "sensor_seed": (None, "seed of the sensor noise; the same seed gives the same noise"),
    "sensor_offset_a": ("A", "offset of the phase-a current sensor"),
    "sensor_offset_b": ("A", "offset of the phase-b current sensor"),
    "sensor_gain_a": (None, "gain of the phase-a current sensor (1 = exact)"),
    "sensor_gain_b": (None, "gain of the phase-b current sensor (1 = exact)"),
    "adc_bits": (None, "ADC resolution in bits (0 = no quantisation)"),
    "adc_range": ("A", "ADC full scale: the converter spans -adc_range..+adc_range"),
    "v_dc": ("V", "DC-link voltage; the voltage vector is limited to v_dc/sqrt(3) (0 = not given: the plant's "
                  "inverter ideal, the controller's limit u_max)"),
    "switching_period": ("s", "switching (PWM) period T_s of the inverter, independent of the communication "
                              "step: the dead time's voltage error and the inverter delay use it"),
    "inverter_delay": (None, "actuation delay in switching periods, 0 or 1 (rounded to whole communication "
                             "steps)"),
    "dead_time": ("s", "inverter dead time per leg (0 = off); per-phase voltage error v_dc dead_time / "
                       "switching_period in the sign of the phase current; needs v_dc > 0"),
    "dead_time_i0": ("A", "current scale of the dead-time error's soft sign tanh(i / dead_time_i0)"),
    "inverter_losses": (None, "inverter conduction and switching losses on, drawn from the DC link: per phase "
                              "d (inv_v0 |i| + inv_r_on i^2) + (1 - d) (inv_vf0 |i| + inv_r_f i^2) + f_sw inv_e_sw "
                              "v_dc / (inv_v_ref inv_i_ref) |i|, d the IGBT's share of the period (needs v_dc)"),
    "inv_v0": ("V", "inverter: the IGBT's knee V_CE0 (straight-line on-state model V_CE = V_CE0 + r_CE i)"),
    "inv_r_on": ("Ohm", "inverter: the IGBT's on-state slope resistance r_CE"),
    "inv_vf0": ("V", "inverter: the diode's knee V_F0 (straight-line forward model V_F = V_F0 + r_F i)"),
    "inv_r_f": ("Ohm", "inverter: the diode's forward slope resistance r_F"),
    "inv_e_sw": ("J", "inverter: switching energy of one leg per switching period (E_on + E_off + E_rec) at "
                      "inv_v_ref, inv_i_ref"),
    "inv_v_ref": ("V", "inverter: DC voltage at which inv_e_sw is given"),
    "inv_i_ref": ("A", "inverter: current at which inv_e_sw is given"),
    "iron_c_h": (None, "iron losses, hysteresis coefficient c_h [W/(rad/s Wb^2)] of P_fe = (c_h |omega_e| + c_e "
                       "omega_e^2) (psi_d^2 + psi_q^2), a drag on the shaft (0 = off)"),
    "iron_c_e": (None, "iron losses, eddy-current coefficient c_e [W/((rad/s)^2 Wb^2)] (0 = off)"),
    "sat_i_q": ("A", "q-axis saturation current: psi_q = L_q i_q / (1 + |i_q| / sat_i_q) (0 = off, linear)"),
    "sat_i_d": ("A", "d-axis saturation current: psi_d = psi + L_d i_d / (1 + |i_d| / sat_i_d) (0 = off)"),
    "flux_model": (None, "the plant's magnetic model: 'linear' (eqs 10-12, or per axis saturated with sat_i_q, "
                         "sat_i_d) or 'algebraic' (flux linkages with self- and cross-saturation and the magnet's "
                         "asymmetry, Hinkkanen et al. 2017's algebraic model; L_d, L_q, psi at zero current)"),
    "flux_q_current": ("A", "algebraic flux model: the q current at which flux_q_ratio is given"),
    "flux_q_ratio": (None, "algebraic flux model: incremental L_q at (0, flux_q_current) over L_q, in (0, 1]"),
    "flux_d_current": ("A", "algebraic flux model: the d current at which flux_d_asymmetry is given"),
    "flux_d_asymmetry": (None, "algebraic flux model: (L_dd(-flux_d_current) - L_dd(+flux_d_current)) / L_d, in "
                               "[0, 1): the magnet's asymmetry of the d axis"),
    "flux_cross": (None, "algebraic flux model: fall of psi_d at (0, flux_q_current) below psi, in [0, 1): "
                         "cross-saturation"),
    "flux_S": (None, "algebraic flux model: exponent of the d axis's self-saturation, > 0"),
    "flux_T": (None, "algebraic flux model: exponent of the q axis's self-saturation, > 0"),
    "flux_U": (None, "algebraic flux model: cross-saturation exponent U (of psi_d), >= 0"),
    "flux_V": (None, "algebraic flux model: cross-saturation exponent V (of psi_q), >= 0"),
    "T_winding": ("degC", "winding temperature: R_s(T) = R_s (1 + alpha_R (T - 20 degC))"),
    "T_magnet": ("degC", "magnet temperature: psi(T) = psi (1 + alpha_psi (T - 20 degC))"),
    "thermal_R": ("K/W", "thermal resistance winding -> coolant of the one-node thermal model (0 = off: "
                         "T_winding constant; thermal_model 'lptn' needs 0)"),
    "thermal_C": ("J/K", "heat capacity of the winding in the thermal model"),
    "T_ambient": ("degC", "coolant temperature of the thermal model (both boundaries of the 'lptn' network)"),
    "alpha_R": ("1/K", "temperature coefficient of the winding resistance (copper 0.00393)"),
    "alpha_psi": ("1/K", "temperature coefficient of the magnet flux (NdFeB about -0.0012)"),
    "thermal_model": (None, "the motor's thermal model: 'off' (the temperatures constant, or the one-node winding "
                            "of thermal_R) or 'lptn' (Wallscheid and Boecker's four-node lumped-parameter thermal "
                            "network: stator yoke, tooth, winding, magnet; R_s and psi follow it)"),
    "lptn_C_yoke": ("J/K", "thermal network: heat capacity of the stator yoke's node"),
    "lptn_C_tooth": ("J/K", "thermal network: heat capacity of the stator tooth's node"),
    "lptn_C_winding": ("J/K", "thermal network: heat capacity of the winding's node"),
    "lptn_C_magnet": ("J/K", "thermal network: heat capacity of the magnet's (rotor's) node"),
    "lptn_R_yoke_coolant": ("K/W", "thermal network: thermal resistance yoke -> coolant (water jacket)"),
    "lptn_R_yoke_winding": ("K/W", "thermal network: thermal resistance yoke -> winding"),
    "lptn_R_yoke_tooth": ("K/W", "thermal network: thermal resistance yoke -> tooth"),
    "lptn_R_tooth_winding": ("K/W", "thermal network: thermal resistance tooth -> winding"),
    "lptn_R_tooth_magnet": ("K/W", "thermal network: thermal resistance tooth -> magnet (the air gap)"),
    "lptn_R_winding_magnet": ("K/W", "thermal network: thermal resistance winding -> magnet (end windings' air)"),
    "lptn_R_magnet_ambient": ("K/W", "thermal network: thermal resistance magnet -> ambient (at T_ambient)"),
    "lptn_rotor_share": (None, "thermal network: the share of the iron and friction losses that heats the magnet's "
                               "node, in [0, 1]"),
    "lptn_yoke_share": (None, "thermal network: the stator's share of the iron and friction losses that heats the "
                              "yoke (the rest the tooth), in [0, 1]"),
    "T_winding_max": ("degC", "the winding's temperature limit (insulation class), above T_ambient: the output "
                              "over_temperature flags it"),
    "T_magnet_max": ("degC", "the magnet's maximum temperature, above T_ambient: the output over_temperature flags "
                             "it"),
    "dead_time_comp": ("V", "dead-time compensation: per-phase voltage added in the sign of the measured "
                            "current (0 = off; v_dc t_d / T_s cancels the plant's dead time)"),
    "dead_time_comp_i0": ("A", "current scale of the dead-time compensation's soft sign"),
    "delay_compensation": (None, "actuation delay the controller accounts for, 0 or 1 periods (observer input)"),
    "x0_omega": ("rad/s", "EKF initial speed estimate (flying start: set to the plant's initial speed)"),
    "x0_theta": ("rad", "EKF initial electrical-angle estimate, the observer's guess of theta(0)"),
    "J_model": ("kg.m2", "inertia of the EKF's mechanical model (0 = the motor's J_m, the paper's eq 22; "
                         "the drive's J_eq of eq 9 is 0.526 kg m^2)"),
    "adaptation": (None, "adaptation while driving: 'off', 'observe' (psi_est, R_s_est computed, the controller "
                         "unchanged) or 'use' (the controller's model and its EKF take them)"),
    "model_source": (None, "the controller's model of the motor: 'given' (its L_d, L_q, R_s parameters) or "
                           "'identified' (L_d, L_q, R_s as the injection unit measures them at enable: the EKF, the "
                           "current loops' gains, the feed-forward and the references use them)"),
    "adapt_time": ("s", "the adaptation's memory: its least-squares sums forget with this time constant over the "
                        "periods where their parameter is observable"),
    "adapt_psi_speed": ("rad/s", "psi is observable (psi_est moves) at this |omega| or faster"),
    "adapt_rs_speed": ("rad/s", "R_s is observable (R_s_est moves) at this |omega| or slower ..."),
    "adapt_rs_current": ("A", "... and at this current magnitude or more"),
    "adapt_current_rate": ("A/s", "the adaptation's fits update only while the currents' |di/dt|, filtered over "
                                  "50 ms, is at most this (quasi-steady)"),
    "psi_adapt": ("1/s", "magnet-flux adaptation gain of the stationary-frame EKF5 (ekf5ab, sensorless); 0 = off"),
    "psi_adapt_speed": ("rad/s", "the magnet-flux adaptation runs while |omega_hat| exceeds this"),
    "discretisation": (None, "the EKFs' current model A2-A3: 'euler' (the paper's forward Euler) or 'bilinear' "
                             "(Tustin's rule, exact input for a stationary held vector; docs/speed-range.md)"),
    # StartupParams: the sensorless unit's low-speed range
    "i_align": ("A", "alignment current at standstill"),
    "t_ramp": ("s", "alignment: ramp of the current to i_align on the +90 deg axis"),
    "t_hold": ("s", "alignment: hold on +90 deg"),
    "t_sweep": ("s", "alignment: sweep of the current vector from +90 deg to 0 deg"),
    "t_settle": ("s", "alignment: hold on 0 deg before the I-f start"),
    "i_if": ("A", "I-f current (start-up; least current after a handover down)"),
    "if_accel": ("rad/s2", "largest acceleration of the I-f speed, which follows omega_ref"),
    "i_rate": ("A/s", "rate of change of the I-f current magnitude"),
    "omega_up": ("rad/s", "handover from I-f to the EKF above this I-f speed"),
    "omega_down": ("rad/s", "handover from the EKF back to I-f below this |omega_hat|"),
    "agree_tol": (None, "handover up: relative agreement of omega_hat with the I-f speed"),
    "agree_time": ("s", "handover up: how long omega_hat must agree with the I-f speed"),
    "if_margin": (None, "I-f current after a handover down, times the present current"),
    "if_damping": (None, "damping ratio of the rotor's swing on the I-f vector (0 = plain I-f)"),
    "if_damping_filter": ("s", "time constant of the low-pass filter on omega_hat - omega_if before the I-f "
                                "damping (0 = none)"),
    "p0_omega_aligned": ("rad2/s2", "EKF covariance of the speed at its restart after the alignment"),
    "p0_theta_aligned": ("rad2", "EKF covariance of the angle at its restart after the alignment"),
    "if_load_angle": ("rad", "design load angle of the I-f drive: its acceleration and current are sized from "
                             "eq 12's torque at this angle against the EKF's load"),
    "i_rate_load": ("A/s", "rate of the I-f current while the synchronism guard holds the vector (the load "
                           "exceeds it)"),
    "sync_guard": (None, "synchronism guard on: the I-f vector never leads or trails the EKF's angle by more than "
                         "guard_angle, nor turns away from the rotor past 90 deg (off: only while recovering)"),
    "guard_angle": ("rad", "the synchronism guard's angle (I-f vector against the EKF's angle)"),
    "slip_tol": ("rad/s", "loss-of-synchronism detector: |omega_hat - omega_if| above slip_tol + agree_tol "
                          "|omega_if| ..."),
    "slip_time": ("s", "... for this long"),
    "recover_time": ("s", "a loss-of-synchronism episode ends after this long in synchronism"),
    "fault_time": ("s", "an episode older than this latches the fault output (2) and the safe state: stop and "
                        "hold at i_q_max, until reset"),
    "align_damping": (None, "the alignment damped on the back-EMF of the vector's q axis"),
    "align_slip": ("rad/s", "a rotor turning faster than this under the alignment's vector (|omega_hat|) ends "
                            "the alignment: I-f on the EKF's angle at i_q_max (a car parked on a slope); 0 = never"),
    "align_slip_time": ("s", "... for this long"),
    "still_speed": ("rad/s", "below this |omega_hat| and |omega_if| in I-f the car stands: the guard and the I-f "
                             "sizing use the angle and load it is anchored on (anchor_speed), the EKF is put back "
                             "there when it ends (no back-EMF shows the angle); 0 = never"),
    "anchor_speed": ("rad/s", "in I-f at this |omega_hat| or faster the EKF's angle relative to the vector and its "
                              "load are kept: a stand is anchored on them, and the EKF restarted on the vector's "
                              "angle plus that offset when it ends; 0 = the EKF's at the stand's start"),
    "if_deadline": ("s", "in I-f with |omega_ref| above omega_up this long, the handover up to FOC on the EKF is "
                         "forced (the I-f speed above omega_up, the EKF's alike, not slipping): an episode; 0 = never"),
    "stall_time": ("s", "in I-f with |omega_ref| above omega_up this long, the drive has stalled: the rotor is "
                        "realigned from standstill (an episode; a rotor turning at omega_down or faster: FOC "
                        "on the EKF); 0 = never"),
    "realign_max": (None, "realignments after a stall, without a handover up in between, before the fault latches"),
    "soft_guard_angle": ("rad", "the synchronism guard's soft limit: beyond this lead over the rotor's angle the I-f "
                                "vector turns no faster than the rotor (90 deg: the magnet torque's pull-out angle)"),
    "guard_band": ("rad", "the guard lets go once the lead is back within soft_guard_angle less this (hysteresis)"),
    "trust_move": ("rad", "in I-f at low speed the EKF is believed once it says the rotor has moved on the vector by "
                          "more than this (a load change of half the vector's pull-out torque moves it 30 deg)"),
    "relock_time": ("s", "a relocked vector leads the rotor in the direction of the torque that holds the load and "
                         "brings the speed to the reference within this time"),
    "still_time": ("s", "a stand in I-f ends once |omega_hat| has been above still_speed this long (the EKF's "
                        "speed noise at a stand crosses it for a few periods)"),
    # InjectionParams: the sensorless unit at and near zero speed by high-frequency injection
    "low_speed": (None, "the strategy at and near zero speed: 'if' (alignment, I-f, handover) or 'injection' "
                        "(a square wave on the estimated d axis, the angle from the rotor's saliency, closed loop "
                        "at zero speed; docs/sensorless.md)"),
    "inj_voltage": ("V", "the injection's square-wave amplitude on the estimated d axis"),
    "inj_frequency": ("Hz", "the square wave's frequency: 1 / (2 m dt), m = 1..8; 0 = half the control rate"),
    "inj_bandwidth": ("rad/s", "the injection's tracking observer: its three poles at -inj_bandwidth"),
    "inj_blend_low": ("rad/s", "the EKF's angle blended in from this |omega| ..."),
    "inj_blend_high": ("rad/s", "... to this one, where the injection is off and the EKF alone drives"),
    "inj_hysteresis": ("rad/s", "back into the injection below inj_blend_high less this"),
    "inj_lock_time": ("s", "the angle's acquisition at enable: the time on each of its two axes"),
    "inj_settle_time": ("s", "the tracking observer's settling after the acquisition"),
    "pol_current": ("A", "the magnet-polarity test's d current (pulses of both signs)"),
    "pol_ramp": ("s", "the polarity test's current ramps"),
    "pol_hold": ("s", "the polarity test's hold at each sign"),
    "pol_contrast": (None, "the least relative difference of the d admittances at +-pol_current that decides the "
                           "polarity (below: unresolved; twice: the fault latches without torque)"),
    "inj_cross_comp": (None, "cross-saturation's offset of the injection's axis compensated with the controller's "
                             "model of the saturation (the algebraic flux model's defaults on its L_d, L_q, psi)"),
    "inj_current_limit": ("A", "the q current limit while the injection carries the angle (cross-saturation tilts "
                          "the axes it sees), rising to the drive's own with the EKF's weight in the blend"),
    "pol_frame_band": ("rad", "the polarity test's frame holds while the tracking observer stays within this of "
                       "it, and follows it this far behind beyond"),
    "hold_brake": (None, "the hill hold: from enable to the unit's first torque it asks the friction brake (output "
                         "T_brake) for this times the drive's torque limit at the wheels, T_max n_g eta; 0: none"),
    "inj_los_angle": ("rad", "loss of synchronism under injection: the tracking observer's angle error (or, in the "
                             "blend, its disagreement with the EKF) beyond this ..."),
    "inj_los_time": ("s", "... for this long"),
    "ekf_los_current": ("A", "loss of synchronism on the EKF: its current innovation (filtered) beyond this ..."),
    "ekf_los_time": ("s", "... for this long"),
    "id_time": ("s", "the identification at enable: the d admittance of the injection's answers on the found d axis, "
                     "then on the q axis, this long each (1/L_d, 1/L_q and the error signal's gain measured); 0: "
                     "not measured, the motor model's L_d, L_q"),
    "saliency_min": (None, "the least identified saliency L_q / L_d the injection is trusted at (output blind: 1 "
                           "below it)"),
    "saliency_trust": (None, "a blind unit measures its motor again at every stop; it trusts the injection again "
                             "where the answers pooled since enable give at least this saliency L_q / L_d"),
    "inj_voltage_max": ("V", "the square wave's largest amplitude: after the identification it is the one whose "
                             "error signal, the dead time's share made up, has the data sheet motor's current per "
                             "unit of sin 2e at inj_voltage"),
    "rs_current": ("A", "the R_s test at enable: the upper d current level (the lower: half of it), on the found d "
                        "axis at standstill"),
    "rs_time": ("s", "the R_s test: the time at each level (the second half measured); 0: no test"),
    "ofs_time": ("s", "the offset window at enable: no voltage, each current sensor's mean is its offset, subtracted "
                      "from then on; 0: not measured"),
    "inj_angle_max": ("rad", "the largest angle accuracy at a stop (eq ID3, from the measured saliency and noise "
                             "floor) at which the injection is trusted; beyond it the unit is blind"),
    "inj_see_max": ("rad", "the largest angle accuracy at a stop (eq ID3) at which a blind unit still finds the axis "
                           "at every stop (the parked fallback); beyond it the unit takes the I-f strategy for good"),
    "emf_slip_speed": ("rad/s", "loss of synchronism under injection and in the blend: the back-EMF the current PIs' "
                                "integrators carry beyond what the frame's speed explains, as a speed (eq LS1), "
                                "beyond this plus emf_slip_rel times the rotor's speed the loops see for inj_los_time"),
    "emf_slip_rel": (None, "... the share of the rotor's speed the current loops see (all the back-EMF they "
                           "carry) added to emf_slip_speed"),
    "gain_turns": (None, "the phase sensors' relative gain g_a / g_b is measured on the EKF over this many electrical "
                         "turns (eqs SG1-SG2) and taken out of the measurements from then on; 0: not measured"),
    "gain_standstill_se": (None, "the phase sensors' relative gain is also measured at standstill, from a parked "
                                 "unit's pooled identification answers (eq SG0), and taken once its standard error "
                                 "is at most this; 0: not measured at standstill"),
    "saliency_hold": (None, "below this identified saliency L_q / L_d a seeing unit parks at its stops (the friction "
                            "brake holds the car, the angle found afresh for each restart) instead of holding the car "
                            "on the injection; 0: off"),
    "inj_axis_cos": (None, "the tracking observer has lost the axis where cos 2e from the d admittance (with the "
                           "identified admittances), filtered, stays below this for inj_los_time"),
    # ControlUnit
    "angle_source": (None, "frame angle of the controller: 'measured' (theta_meas input, as in the paper's "
                           "simulation) or 'estimated' (observer angle, truly sensorless)"),
    # the controller FMUs' sample clock (fmus/foc_slave.py)
    "dt": ("s", "sample period of the controller and observer: one control period at each instant "
                "start + k dt; 0 (default): the size of the first communication step"),
    # BatteryParams (the plant's DC link)
    "battery": (None, "the DC link: 'ideal' (a constant source of v_dc, the paper's) or 'ecm' (the battery's "
                      "equivalent circuit: OCV(soc) - R0 i - v_rc, one RC pair; the plant's v_dc, losses and voltage "
                      "limit follow its terminal voltage)"),
    "bat_soc0": (None, "the battery's state of charge at the start, in [0, 1]"),
    "bat_capacity": (None, "the battery's capacity [Ah], > 0"),
    "bat_ocv_soc": (None, "the open-circuit voltage table's states of charge, comma-separated, rising from 0 to 1"),
    "bat_ocv_v": (None, "the open-circuit voltage table's voltages [V], comma-separated, rising with the state of "
                        "charge"),
    "bat_R0": ("Ohm", "the battery's series resistance R0"),
    "bat_R1": ("Ohm", "the battery's RC pair: its resistance R1 (0 = no RC pair)"),
    "bat_C1": (None, "the battery's RC pair: its capacitance C1 [F]"),
    "bat_i_discharge_max": ("A", "the battery's discharge current limit"),
    "bat_i_charge_max": ("A", "the battery's charge current limit (charge acceptance)"),
    "bat_v_max": ("V", "the terminal voltage a charge current may raise the battery to"),
    "bat_v_min": ("V", "the terminal voltage a discharge current may lower the battery to"),
    "bat_soc_taper": (None, "above this state of charge the charge current limit falls linearly to 0 at 1"),
}
