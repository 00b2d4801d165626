"""One-line progress bars on stderr: :class:`ProgressBar` (simulated time, simulated s per
wall s, ETA) for a run, :class:`CountBar` (finished runs, ETA) for a sweep."""

from __future__ import annotations

import sys
import time


def _duration(seconds: float) -> str:
    if seconds != seconds or seconds == float("inf"):
        return "--"
    seconds = int(round(seconds))
    h, rem = divmod(seconds, 3600)
    m, s = divmod(rem, 60)
    return f"{h}:{m:02d}:{s:02d}" if h else f"{m}:{s:02d}"


class ProgressBar:
    """Redrawn at most ``rate`` times per second; call ``update(t)`` as often as you like."""

    def __init__(self, stop_time: float, stream=None, rate: float = 4.0, width: int = 30):
        self.stop_time = stop_time
        self.stream = stream if stream is not None else sys.stderr
        self.min_interval = 1.0 / rate
        self.width = width
        self.start = time.monotonic()
        self.last = -1.0e9
        self.drawn = False

    @staticmethod
    def wanted(quiet: bool, stream=None) -> bool:
        """Only on an interactive stderr, and not with --quiet."""
        stream = stream if stream is not None else sys.stderr
        try:
            return not quiet and stream.isatty()
        except (AttributeError, ValueError):
            return False

    def update(self, t: float) -> None:
        now = time.monotonic()
        if now - self.last < self.min_interval:
            return
        self.last = now
        elapsed = now - self.start
        frac = min(max(t / self.stop_time, 0.0), 1.0) if self.stop_time > 0 else 1.0
        rate = t / elapsed if elapsed > 0 else 0.0
        eta = (self.stop_time - t) / rate if rate > 0 else float("nan")
        filled = int(round(frac * self.width))
        bar = "#" * filled + "." * (self.width - filled)
        line = (f"\r[{bar}] {t:9.3f}/{self.stop_time:g} s  {rate:7.3f} sim-s/s  "
                f"ETA {_duration(eta)}  ")
        self.stream.write(line)
        self.stream.flush()
        self.drawn = True

    def close(self) -> None:
        if self.drawn:
            self.stream.write("\r" + " " * 78 + "\r")
            self.stream.flush()
            self.drawn = False


class CountBar(ProgressBar):
    """Counts finished items (the runs of a sweep): ``update(done)``; ``force`` redraws at once
    (after a line was printed over the bar)."""

    def __init__(self, total: int, unit: str = "runs", stream=None, rate: float = 4.0, width: int = 30):
        super().__init__(float(total), stream, rate, width)
        self.total = total
        self.unit = unit
        self.done = 0

    def update(self, done: int, force: bool = False) -> None:
        self.done = done
        now = time.monotonic()
        if not force and now - self.last < self.min_interval:
            return
        self.last = now
        elapsed = now - self.start
        frac = min(max(done / self.total, 0.0), 1.0) if self.total > 0 else 1.0
        eta = elapsed * (self.total - done) / done if done > 0 else float("nan")
        filled = int(round(frac * self.width))
        bar = "#" * filled + "." * (self.width - filled)
        self.stream.write(f"\r[{bar}] {done}/{self.total} {self.unit}  elapsed {_duration(elapsed)}  "
                          f"ETA {_duration(eta)}  ")
        self.stream.flush()
        self.drawn = True
