"""Progress of a simulation in simulated time, on a tqdm bar (:mod:`ncgen.progress`).

``mode``: ``True`` shows it, ``False`` never, ``None`` (auto) only when stderr is a terminal
and the run lasts longer than :data:`ncgen.progress.DELAY` seconds.
"""
from __future__ import annotations

from ncgen.progress import bar, enabled


class Progress:
    """Progress of simulated time ``t0 → t_end`` (s)."""

    def __init__(self, t0: float, t_end: float, mode: bool | None = None, stream=None, label: str = ""):
        self.t0, self.t_end, self.t = t0, t_end, t0
        #: Whether a bar may be drawn (:func:`ncgen.progress.enabled`; none is built otherwise).
        self.shown = enabled(mode)
        self._bar = bar(round(t_end - t0, 12), label.rstrip(": ") or "simulating", unit="s", mode=mode,
                        bar_format="{desc}: {percentage:3.0f}%|{bar}| t = {n:.4g}/{total:.4g} s "
                                   "[{elapsed}<{remaining}]") if self.shown else None

    def update(self, t: float, force: bool = False) -> None:
        """Report that simulated time ``t`` was reached."""
        self.t = t
        if self._bar is not None:
            self._bar.update(round(t - self.t0, 12) - self._bar.n)

    def close(self) -> None:
        """Remove the bar."""
        if self._bar is not None:
            self._bar.close()
