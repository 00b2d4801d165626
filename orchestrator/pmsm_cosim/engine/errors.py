"""The orchestrator's one user-facing error type."""

from __future__ import annotations

import difflib


class CosimError(Exception):
    """A user error (bad system file, unknown variable, FMU refusing a value, ...).

    The message is one line; the CLI prints it as ``error: <message>`` and exits 2.
    """


def close_matches(name: str, candidates, n: int = 3) -> str:
    """`` (did you mean: a, b?)`` for the closest candidates, or ``""``."""
    candidates = list(candidates)
    found = difflib.get_close_matches(name, candidates, n=n, cutoff=0.6)
    if not found:  # q_tl -> q_TL
        lower = {c.lower(): c for c in candidates}
        found = [lower[c] for c in difflib.get_close_matches(name.lower(), list(lower), n=n, cutoff=0.6)]
    return f" (did you mean: {', '.join(found)}?)" if found else ""


def one_line(text: str) -> str:
    """Collapse a (possibly multi-line) message to one line."""
    return " ".join(part.strip() for part in str(text).splitlines() if part.strip())
