"""The verdict on a drive-cycle sample (a run of a cycle Monte-Carlo: one row of its summary.csv), defined here
once; the robustness report and ``pmsm-cosim sweep`` quote it.

**The failure rule**: a sample fails if it did not complete, or its speed was inside the tolerance band
(``trace.trace_figures``: +-2 km/h around the trace, taken over +-1 s) for less than ``INSIDE_MIN`` of the cycle
(``inside_share``; a completed run without it fails too), or its angle slipped an electrical turn
(``synchronism.slipped_turns``), or the controller's safe state latched (``fault_latched``).

**An unseen slip**: a sample that slipped at least one electrical turn and whose unit reported no
loss-of-synchronism episode (``episodes`` 0): the unit lost the angle without knowing it. Counted apart from the
failures (a slip is a failure either way): a drive must never slip silently.
"""

from __future__ import annotations

import math

#: a sample follows the cycle if its speed is inside the tolerance band for at least this share of it (issue 24's
#: requirement; the report's cycle section and the cycle Monte-Carlo's failure rule both judge by it)
#: [chosen: the WLTP's test tolerance leaves no room for a drive that is out of it for more than 1 % of the cycle]
INSIDE_MIN = 0.99
#: the failure reasons, in the reports' order
REASONS = ("did not complete", "left the band", "slipped a turn", "fault latched")


def failure_reasons(status: str, inside_share: float, slipped_turns: float, fault_latched: float) -> list[str]:
    """Why a sample failed (``REASONS``; empty: it passed). NaN slipped_turns or fault_latched (a controller
    without the sensorless unit's columns) count as none; a NaN inside_share of a completed run fails."""
    if status != "completed":
        return [REASONS[0]]
    out = []
    if not inside_share >= INSIDE_MIN:
        out.append(REASONS[1])
    if slipped_turns > 0:
        out.append(REASONS[2])
    if fault_latched > 0:
        out.append(REASONS[3])
    return out


def unseen_slip(slipped_turns: float, episodes: float) -> bool:
    """Whether a sample slipped at least one electrical turn with no episode reported by its unit (NaN: neither)."""
    return slipped_turns >= 1.0 and episodes == 0.0


def _num(x) -> float:
    try:
        return float(x)
    except (TypeError, ValueError):
        return math.nan


def cycle_verdict(rows: list[dict]) -> dict | None:
    """The verdict on the samples of a cycle sweep (summary rows: ``status``, ``inside_share``, ``slipped_turns``,
    ``fault_latched``, ``episodes``): {"samples", "failed", "by_reason", "unseen_slips"}; None where no row has a
    cycle's figures (not a cycle sweep)."""
    if not any(math.isfinite(_num(r.get("inside_share"))) for r in rows):
        return None
    by_reason = dict.fromkeys(REASONS, 0)
    failed = unseen = 0
    for r in rows:
        reasons = failure_reasons(r.get("status", ""), _num(r.get("inside_share")), _num(r.get("slipped_turns")),
                                  _num(r.get("fault_latched")))
        failed += bool(reasons)
        for reason in reasons:
            by_reason[reason] += 1
        unseen += unseen_slip(_num(r.get("slipped_turns")), _num(r.get("episodes")))
    return {"samples": len(rows), "failed": failed, "by_reason": by_reason, "unseen_slips": unseen}


def verdict_line(verdict: dict) -> str:
    """One line of ``cycle_verdict``: failures by reason and the unseen slips."""
    reasons = ", ".join(f"{reason} {n}" for reason, n in verdict["by_reason"].items())
    return (f"cycle verdict: {verdict['failed']} of {verdict['samples']} samples failed ({reasons}; the rule: "
            f"pmsm_cosim.app.metrics.verdicts); {verdict['unseen_slips']} slipped with no episode reported")
