"""Clarke and Park transforms (amplitude-invariant), as used around eqs 10-20.

The plant's terminals are in the stationary alpha-beta frame; eqs 10-13 and the
controller work in the rotor (dq) frame at electrical angle theta.
"""

from __future__ import annotations

import math

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


def park(alpha: float, beta: float, theta: float) -> tuple[float, float]:
    """alpha-beta -> dq at electrical angle theta (d axis on the magnet)."""
    c = math.cos(theta)
    s = math.sin(theta)
    return c * alpha + s * beta, -s * alpha + c * beta


def inverse_park(d: float, q: float, theta: float) -> tuple[float, float]:
    """dq -> alpha-beta at electrical angle theta."""
    c = math.cos(theta)
    s = math.sin(theta)
    return c * d - s * q, s * d + c * q


def wrap_angle(theta: float) -> float:
    """Wrap an angle to [-pi, pi)."""
    return (theta + math.pi) % (2.0 * math.pi) - math.pi
