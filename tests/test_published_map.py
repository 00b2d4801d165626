"""The published efficiency map (ORNL/TM-2006/423 Table B-1, the 2004 Prius motor and inverter) loads whole and
consistent, and the comparison of ``pmsm-cosim envelope --published`` computes its figures from the table and
the model (a changed row or parameter moves them)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pmsm_cosim.app import envelope, published
from pmsm_ev import references


@pytest.fixture(scope="module")
def pub():
    return published.load()


def test_the_table_loads_whole_and_consistent(pub):
    """428 points over 297-6005 rpm; each row's powers and efficiencies agree (the transcription's checks)."""
    assert pub["speed_rpm"].size == 428
    assert pub["speed_rpm"].min() == 297 and pub["speed_rpm"].max() == 6005
    assert np.all(np.abs(pub["torque_Nm"] * pub["omega"] - pub["p_mech_W"]) <= 0.005 * pub["p_mech_W"])
    assert np.all((pub["p_dc_W"] > pub["p_ac_W"]) & (pub["p_ac_W"] > pub["p_mech_W"]))
    assert np.all(np.abs(pub["eta"] - pub["eta_total"]) < 0.0015)
    assert np.all(np.abs(pub["eta_inverter"] * pub["eta_motor"] - pub["eta_total"]) < 0.0015)
    assert np.all(np.abs(pub["group"] - pub["speed_rpm"]) <= 0.07 * pub["group"])
    assert published.corner_speed(published.PRIUS_2004) == pytest.approx(125.0)


def test_level_crossings_interpolate_the_contour():
    c = published.level_crossings([1.0, 2.0, 3.0, 4.0], [0.85, 0.95, 0.95, 0.85], 0.9)
    assert (c["T_from"], c["T_to"], c["best"]) == pytest.approx((1.5, 3.5, 0.95))
    c = published.level_crossings([1.0, 2.0, 3.0], [0.91, 0.95, np.nan], 0.9)
    assert c["from_edge"] and c["to_edge"] and (c["T_from"], c["T_to"]) == pytest.approx((1.0, 2.0))
    assert published.level_crossings([1.0, 2.0], [0.8, 0.85], 0.9)["T_from"] is None


def test_the_comparison_is_computed(pub):
    """The published figures follow the table (a row made better becomes the peak) and the model's follow the
    model (a larger stator resistance lowers them); the model's efficiency at its peak point is its own."""
    sub = {k: v[::4] for k, v in pub.items()}
    p = envelope.parameters()
    c = published.compare(p, sub, line_torques=12)
    pp, mm = c["published"], c["model"]
    k = int(np.argmax(sub["eta"]))
    assert pp["max"] == sub["eta"][k] and (pp["at_omega"], pp["at_T"]) == (sub["omega"][k], sub["torque_Nm"][k])
    assert pp["share_above"] == pytest.approx(np.mean(sub["eta"] >= 0.9))
    assert mm["points"] <= pp["points"] == sub["speed_rpm"].size
    assert 0.5 < mm["max"] < 1.0 and 0.0 < mm["share_above"] <= 1.0
    lim = references.limits(p["controller"], p["motor"])
    assert published.efficiency_at(p, lim, mm["at_omega"], mm["at_T"])[0] == pytest.approx(mm["max"])
    assert len(c["by_speed"]) == np.unique(sub["group"]).size and len(c["loss_split"]) == len(published.SPLIT_AT_PU)
    for r in c["loss_split"]:
        m = r["measured"]
        assert m["eta"] + m["motor"] + m["inverter"] == pytest.approx(1.0)
    table = published.table(c)
    assert f"{100 * pp['max']:.1f} %" in table and f"{100 * mm['max']:.1f} %" in table

    better = {k: v.copy() for k, v in sub.items()}
    better["eta"][0] = 0.99
    moved = published.point_summary(better["omega"], better["torque_Nm"], better["eta"], pp["omega_corner"],
                                    pp["T_peak"])
    assert moved["max"] == 0.99 and moved["at_T"] == sub["torque_Nm"][0]

    worse = published.compare(envelope.parameters(["R_s=0.0347"]), sub, line_torques=12)["model"]
    assert worse["max"] < mm["max"] and worse["share_above"] < mm["share_above"]
    assert math.isclose(worse["omega_corner"], mm["omega_corner"], rel_tol=0.05)
