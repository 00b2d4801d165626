"""The interval of a failure rate: the robustness report's Monte-Carlo runs quote it (``metrics``, ``cycle``)."""

from __future__ import annotations

import math


def wilson(failures: int, n: int, z: float = 1.959963984540054) -> tuple[float, float]:
    """The Wilson score interval of a proportion failures / n (95 % by default)."""
    if n == 0:
        return math.nan, math.nan
    p = failures / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z / (1 + z * z / n) * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    return max(0.0, centre - half), min(1.0, centre + half)
