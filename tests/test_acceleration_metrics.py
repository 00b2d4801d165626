"""The whole speed range's figures of merit (``pmsm_ev.results``): where a car that cannot follow
its route fell behind, and the data sheet's acceleration figures, on synthetic runs whose answers
are known in closed form."""

from __future__ import annotations

import numpy as np
import pytest

from pmsm_cosim.app.metrics.run import compute_metrics
from pmsm_cosim.app.metrics.speed_range import acceleration_figures, behind_figures

RATIO = 0.2933 / 12.5  # r_w / n_g [m/rad]


def _run(t, omega_ref, omega_m, **extra):
    r = {"time": t, "omega_ref": omega_ref, "omega_m": omega_m, "v_vehicle": omega_m * RATIO}
    r.update(extra)
    return r


def test_a_car_that_follows_is_never_behind():
    t = np.arange(0.0, 20.0, 0.01)
    w = np.minimum(t, 10.0) * 20.0
    assert behind_figures(_run(t, w, w - 0.5)) is None


def test_a_route_faster_than_the_car_says_where_and_by_how_much():
    t = np.arange(0.0, 30.0, 0.01)
    w_ref = np.where(t < 10.0, 100.0, 2000.0)  # far above the car's top speed from 10 s on
    w_m = np.where(t < 10.0, 100.0, np.minimum(100.0 + 100.0 * (t - 10.0), 1500.0))
    b = behind_figures(_run(t, w_ref, w_m))
    assert b["episodes"] == 1
    assert b["largest_kmh"] == pytest.approx((2000.0 - 100.0) * RATIO * 3.6, rel=1e-3)
    assert b["t_largest"] == pytest.approx(10.0, abs=0.011)
    assert b["t_behind"] == pytest.approx(20.0, abs=0.02)
    assert b["first"][0] == pytest.approx(10.0, abs=0.011)


def test_a_short_lag_is_not_falling_behind_but_a_long_one_is():
    t = np.arange(0.0, 10.0, 0.01)
    w_ref = np.full_like(t, 200.0)
    lag = 3.0 / 3.6 / RATIO  # 3 km/h short
    short = _run(t, w_ref, np.where((t > 2.0) & (t < 2.8), 200.0 - lag, 200.0))
    long = _run(t, w_ref, np.where((t > 2.0) & (t < 3.5), 200.0 - lag, 200.0))
    assert behind_figures(short) is None
    assert behind_figures(long)["largest_kmh"] == pytest.approx(3.0, rel=1e-6)
    # reversing: behind is measured in the reference's direction (a car faster backwards is not behind)
    assert behind_figures(_run(t, -w_ref, np.where(t > 2.0, -200.0 - lag, -200.0))) is None
    assert behind_figures(_run(t, -w_ref, np.where(t > 2.0, -200.0 + lag, -200.0)))["episodes"] == 1


def test_acceleration_figures_of_a_constant_acceleration():
    t = np.arange(0.0, 40.0, 0.01)
    a = 4.0  # [m/s^2]
    v_top = 130.0 / 3.6
    t_launch, t_brake = 2.0, 25.0
    v = np.clip(a * (t - t_launch), 0.0, v_top)
    v = np.where(t >= t_brake, np.maximum(v_top - 3.0 * (t - t_brake), 0.0), v)
    w_m = v / RATIO
    w_ref = np.where(t < t_launch, 0.0, np.where(t < t_brake, v_top / RATIO, 0.0))
    m_v = 900.0
    e_kin = 0.5 * m_v * v**2
    e_regen = np.where(t >= t_brake, 0.6 * (e_kin[np.searchsorted(t, t_brake)] - e_kin), 0.0)
    f = acceleration_figures(_run(t, w_ref, w_m, E_kinetic=e_kin, E_regen=e_regen))
    assert f["t_launch"] == pytest.approx(t_launch, abs=0.011)
    assert f["v_launch_kmh"] == 0.0
    assert f["t_0_50"] == pytest.approx(50.0 / 3.6 / a, abs=0.011)
    assert f["t_0_100"] == pytest.approx(100.0 / 3.6 / a, abs=0.011)
    assert f["top_speed_kmh"] == pytest.approx(130.0, rel=1e-9)
    assert f["t_brake"] == pytest.approx(t_brake, abs=0.011)
    assert f["braking_time"] == pytest.approx((v_top - 1.0 / 3.6) / 3.0, abs=0.02)
    assert f["recovered_share"] == pytest.approx(0.6, rel=1e-6)
    assert f["kinetic_Wh"] == pytest.approx(0.5 * m_v * v_top**2 / 3600.0, rel=1e-6)


def test_no_acceleration_block_below_50_kmh_and_none_in_a_paper_run():
    t = np.arange(0.0, 20.0, 0.01)
    w = np.minimum(t, 10.0) * 20.0  # 200 rad/s: 16.9 km/h
    assert acceleration_figures(_run(t, w, w)) is None
    r = _run(t, w, w, delta_deg=np.zeros_like(t), omega_hat=w, theta_e=np.zeros_like(t),
             theta_hat=np.zeros_like(t), T_L_mech=np.zeros_like(t), T_L_hat=np.zeros_like(t),
             T_e=np.zeros_like(t))
    m = compute_metrics(r)
    assert "acceleration" not in m and "behind" not in m


def test_a_flying_start_launches_where_the_reference_rises():
    t = np.arange(0.0, 20.0, 0.01)
    v0 = 200.0 * RATIO
    v = np.where(t < 2.0, v0, np.minimum(v0 + 4.0 * (t - 2.0), 130.0 / 3.6))
    w_ref = np.where(t < 2.0, 200.0, 130.0 / 3.6 / RATIO)
    f = acceleration_figures(_run(t, w_ref, v / RATIO))
    assert f["t_launch"] == pytest.approx(2.0, abs=0.011)
    assert f["v_launch_kmh"] == pytest.approx(v0 * 3.6, rel=1e-9)
    assert f["t_0_50"] == pytest.approx((50.0 / 3.6 - v0) / 4.0, abs=0.011)
