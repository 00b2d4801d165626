"""Clarke and Park transforms (amplitude-invariant), as used around eqs 10-20.

The plant's terminals are in the stationary alpha-beta frame; eqs 10-13 and the
controller work in the rotor (dq) frame at electrical angle theta. ``park``,
``inverse_park`` and ``wrap_angle`` run at every step: they are written in
``pmsm_ev.kernels`` and exported here.
"""

from __future__ import annotations

import math

from .kernels import inverse_park, park, wrap_angle  # noqa: F401

_SQRT3 = math.sqrt(3.0)


def clarke(i_a: float, i_b: float, i_c: float) -> tuple[float, float]:
    """abc -> alpha-beta, amplitude-invariant (i_a + i_b + i_c = 0 assumed for beta)."""
    alpha = (2.0 * i_a - i_b - i_c) / 3.0
    beta = (i_b - i_c) / _SQRT3
    return alpha, beta


def inverse_clarke(alpha: float, beta: float) -> tuple[float, float, float]:
    """alpha-beta -> abc, amplitude-invariant."""
    a = alpha
    b = -0.5 * alpha + 0.5 * _SQRT3 * beta
    c = -0.5 * alpha - 0.5 * _SQRT3 * beta
    return a, b, c
