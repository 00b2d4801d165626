"""The motor's thermal network outside the step (``pmsm_ev.params.PlantParams.thermal_model``; the per-step numerics
are ``pmsm_ev.kernels.thermal_network_step``, once): its conductance matrix and the temperatures it settles at under
losses held, the network's P R (docs/speed-range.md, "A motor that warms")."""

from __future__ import annotations

import numpy as np

from .params import THERMAL_EDGES, PlantParams, thermal_network


def conductance_matrix(p: PlantParams) -> np.ndarray:
    """The thermal network's conductance matrix G [W/K] over its nodes (stator yoke, stator tooth, winding, magnet;
    ``pmsm_ev.kernels.TH_Y`` .. ``TH_M``), the coolant grounded: G_ii the sum of the node's conductances, G_ij minus
    the one between i and j (``thermal_network``, ``THERMAL_EDGES``)."""
    g, _ = thermal_network(p)
    mat = np.zeros((4, 4))
    for gk, (a, b) in zip(g, THERMAL_EDGES):
        mat[a, a] += gk
        if b >= 0:
            mat[b, b] += gk
            mat[a, b] -= gk
            mat[b, a] -= gk
    return mat


def node_losses(p: PlantParams, p_cu: float, p_res: float) -> np.ndarray:
    """The heat [W] into each node of the copper losses ``p_cu`` and the residual (iron and friction) losses ``p_res``
    as ``thermal_network_step`` puts them: copper into the winding; with 'lptn' the residual ones' rotor share into
    the magnet, of the stator's the yoke's share into the yoke and the rest into the tooth (the one-node winding takes
    the copper losses only)."""
    res = p_res if p.thermal_model == "lptn" else 0.0
    rotor = p.lptn_rotor_share * res
    yoke = p.lptn_yoke_share * (res - rotor)
    return np.array([yoke, res - rotor - yoke, p_cu, rotor])


def steady_temperatures(p: PlantParams, p_cu: float, p_res: float) -> np.ndarray:
    """The temperatures [degC] of the nodes (yoke, tooth, winding, magnet) the network settles at with the losses held:
    T = T_ambient + G^-1 P (``conductance_matrix``, ``node_losses``). Nodes without a path to the coolant (the
    one-node winding's others) are not solved: NaN."""
    mat = conductance_matrix(p)
    power = node_losses(p, p_cu, p_res)
    live = np.flatnonzero(np.diag(mat) > 0.0)
    out = np.full(4, np.nan)
    out[live] = p.T_ambient + np.linalg.solve(mat[np.ix_(live, live)], power[live])
    return out
