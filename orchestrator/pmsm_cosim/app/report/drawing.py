"""How the report's sections draw: pyplot on the Agg backend, a figure saved as the report keeps it, a page's
links to the figures that were drawn, and a number as a page writes it."""

from __future__ import annotations

import math
from pathlib import Path


def num(x, fmt: str = ".2f") -> str:
    """A number as the pages write it: "-" for none or a non-finite one."""
    return "-" if x is None or (isinstance(x, float) and not math.isfinite(x)) else format(x, fmt)


def pyplot():
    """matplotlib.pyplot on the Agg backend, imported when a section first draws (matplotlib: ~0.5 s)."""
    import matplotlib  # noqa: PLC0415 - matplotlib: heavy, only when drawing

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415 - matplotlib: heavy, only when drawing

    return plt


def save_figure(fig, path: Path) -> Path:
    """Lay ``fig`` out, write it to ``path`` at the report's 90 dpi and close it; ``path``."""
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    pyplot().close(fig)
    return path


def figure_links(names, drawn) -> list[str]:
    """A page's image lines (results/NAME.png) for those of ``names`` that are among ``drawn``, in order."""
    return [f"![{name}](results/{name}.png)\n" for name in names if name in drawn]
