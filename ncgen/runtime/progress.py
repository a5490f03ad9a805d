"""A one-line progress bar on stderr for long simulations (no dependency).

``mode``: ``True`` shows it, ``False`` never, ``None`` (auto) only when the stream is a
terminal and the run lasts longer than :data:`DELAY` seconds.  The line is redrawn in place
(carriage return) at most every :data:`INTERVAL` seconds and ends with a newline on close.
"""
from __future__ import annotations

import sys
import time

DELAY = 1.0
INTERVAL = 0.1
WIDTH = 30


class Progress:
    """Progress of simulated time ``t0 → t_end`` (s)."""

    def __init__(self, t0: float, t_end: float, mode: bool | None = None, stream=None, label: str = ""):
        self.stream = sys.stderr if stream is None else stream
        if mode is None:
            isatty = getattr(self.stream, "isatty", None)
            mode = bool(isatty and isatty())
            self.delay = DELAY
        else:
            self.delay = 0.0
        self.enabled = bool(mode)
        self.t0, self.t_end, self.label = t0, t_end, label
        self.start = time.monotonic()
        self.last = -float("inf")
        self.shown = False
        self.t = t0

    def update(self, t: float, force: bool = False) -> None:
        """Report that simulated time ``t`` was reached."""
        self.t = t
        if not self.enabled:
            return
        now = time.monotonic()
        if now - self.start < self.delay or (now - self.last < INTERVAL and not force):
            return
        self.last = now
        self.shown = True
        frac = min(1.0, max(0.0, (t - self.t0) / (self.t_end - self.t0)))
        elapsed = now - self.start
        bar = "#" * int(round(frac * WIDTH))
        eta = f", {elapsed * (1 - frac) / frac:.1f} s left" if 0 < frac < 1 else ""
        self.stream.write(f"\r{self.label}[{bar:<{WIDTH}}] {100 * frac:5.1f}%  t = {t:.4g}/{self.t_end:.4g} s"
                          f"  ({elapsed:.1f} s{eta})  ")
        self.stream.flush()

    def close(self) -> None:
        """Draw the last time reached (if the bar was shown) and end the line."""
        if self.shown:
            self.update(self.t, force=True)
            self.stream.write("\n")
            self.stream.flush()
