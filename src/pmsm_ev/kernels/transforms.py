"""Frame transforms of the kernels: Park and inverse Park (the amplitude-invariant turns between
the stationary alpha-beta frame and the rotor's dq frame at the electrical angle) and the angle
wrap to [-pi, pi)."""

from __future__ import annotations

import math

from .jit import kernel

_TWO_PI = 2.0 * math.pi


@kernel()
def park(alpha, beta, theta):
    """alpha-beta -> dq at electrical angle theta (d axis on the magnet)."""
    c = math.cos(theta)
    s = math.sin(theta)
    return c * alpha + s * beta, -s * alpha + c * beta


@kernel()
def inverse_park(d, q, theta):
    """dq -> alpha-beta at electrical angle theta."""
    c = math.cos(theta)
    s = math.sin(theta)
    return c * d - s * q, s * d + c * q


@kernel()
def wrap_angle(theta):
    """Wrap an angle to [-pi, pi)."""
    return (theta + math.pi) % _TWO_PI - math.pi
