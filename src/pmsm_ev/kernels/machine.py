"""The sensorless unit's state machines: what both strategies at and near zero speed share.

Each strategy (``kernels.startup``: alignment, I-f and handover, ``low_speed`` = "if"; ``kernels.modes``:
injection) is written the same way:

* **modes** (``MODE_*`` in ``kernels.layout``, the unit's ``S_MODE``), each with its own control;
* **detectors**: small functions, one purpose and (where it needs time) one timer each, that return an
  **event** (``EV_*``, a float; ``EV_NONE`` for none);
* **one ordered transition table** per strategy: rows (mode, event, next mode, entry action), looked up by
  ``lookup``, the first match taken; a pair not in the table changes nothing;
* **entry actions** (``A_*``): what a transition does to the state, each a small function, run by the
  strategy's ``enter``.

Event and action codes are distinct across the strategies, so that a row says which strategy it is of.
"""

from __future__ import annotations

from .jit import kernel

EV_NONE = 0.0  #: no event this period


@kernel()
def lookup(table, mode, event):
    """The row of ``table`` for (mode, event): (next mode, entry action), or (mode, -1.0) where none."""
    for row in table:
        if row[0] == mode and row[1] == event:
            return row[2], row[3]
    return mode, -1.0
