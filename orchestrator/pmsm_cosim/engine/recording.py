"""Recording: ``results.csv`` streamed row by row, and ``metrics.json``.

``DIR/results.csv``: one header row (the recorded column names), then one row per output
interval, every value written with ``repr`` (the shortest text that reads back as the same
double), flushed row by row so that an interrupted run keeps what it had written.
``DIR/metrics.json``: the run's bookkeeping (status, times, settings) and whatever figures
of merit the application computed, written atomically.
"""

from __future__ import annotations

import json
import os
import warnings
from pathlib import Path

import numpy as np


class ResultWriter:
    """Streams rows to ``results.csv``; every row is flushed when written."""

    def __init__(self, out_dir, columns):
        self.dir = Path(out_dir)
        self.dir.mkdir(parents=True, exist_ok=True)
        self.columns = tuple(columns)
        self.path = self.dir / "results.csv"
        self._fh = open(self.path, "w", encoding="ascii", newline="")
        self._fh.write(",".join(self.columns) + "\n")
        self._fh.flush()
        self.rows = 0

    def write(self, values) -> None:
        # repr() is the shortest string that round-trips the double exactly
        self._fh.write(",".join([repr(float(v)) for v in values]) + "\n")
        self._fh.flush()
        self.rows += 1

    def close(self) -> None:
        if not self._fh.closed:
            self._fh.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def read_results(path, columns=None) -> dict[str, np.ndarray]:
    """results.csv (or its directory) -> {column: array}. Tolerates a cut last line.

    Read line by line (the complete lines: as many fields as the header) into one array of
    doubles by numpy's parser (the same doubles as ``float``): memory is the size of the numbers
    (8 bytes each), not of the text and its Python objects, whatever the length of the run.
    ``columns``: only those of the file's columns (the others not parsed, nor held; a name the file
    lacks is left out of the result), in the file's order."""
    path = Path(path)
    if path.is_dir():
        path = path / "results.csv"
    with open(path, encoding="ascii") as fh:
        header = fh.readline().strip().split(",")
        commas = len(header) - 1
        wanted = set(header) if columns is None else set(columns)
        keep = [i for i, name in enumerate(header) if name in wanted]
        if not keep:
            return {}
        with warnings.catch_warnings():  # a run cut before its first row: no data, no warning
            warnings.simplefilter("ignore", UserWarning)
            data = np.loadtxt((line for line in fh if line.count(",") == commas), delimiter=",", dtype=float,
                              ndmin=2, comments=None, usecols=None if columns is None else keep)
    data = data.reshape(-1, len(keep))
    return {header[i]: data[:, j] for j, i in enumerate(keep)}


def write_metrics(out_dir, metrics: dict) -> Path:
    """Write metrics.json atomically (a reader never sees half a file)."""
    path = Path(out_dir) / "metrics.json"
    tmp = path.with_suffix(".json.tmp")
    text = json.dumps(metrics, indent=2, allow_nan=True)
    tmp.write_text(text + "\n", encoding="utf-8")
    os.replace(tmp, path)
    return path
