"""Helpers for the tests of the sensorless unit's state machines (``pmsm_ev.kernels.machine``)."""

from __future__ import annotations


def reachable(table, start: float) -> set[float]:
    """The modes a transition table (rows of mode, event, next mode, entry action) reaches from ``start``."""
    seen, todo = {start}, [start]
    while todo:
        m = todo.pop()
        for mode, _, new, _ in table:
            if mode == m and new not in seen:
                seen.add(new)
                todo.append(new)
    return seen
