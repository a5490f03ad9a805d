"""Progress bars on stderr (tqdm) for work that can take more than a couple of seconds:
IDAS and stepper runs, compiling, GIF rendering, IPOPT iterations.

``mode``: ``True`` shows the bar at once, ``False`` never, ``None`` (auto) only when stderr
is a terminal and the work lasts longer than :data:`DELAY` seconds; ``NCGEN_PROGRESS=0``
turns every bar off.  Bars are cleared when closed, so logs and captured output stay clean.
"""
from __future__ import annotations

import sys
import threading

from ncgen.environment import getenv

DELAY = 2.0


def enabled(mode: bool | None = None) -> bool:
    """Whether a bar with ``mode`` is drawn at all (see module docstring)."""
    if mode is False:
        return False
    if not mode:                            # auto: a terminal
        isatty = getattr(sys.stderr, "isatty", None)
        if not (isatty and isatty()):
            return False
    return getenv("NCGEN_PROGRESS", "") != "0"


def bar(total: float | None, desc: str, unit: str = "it", mode: bool | None = None, **kw):
    """A tqdm bar on stderr (disabled per :func:`enabled`), shown after :data:`DELAY` s in auto mode;
    the notebook's bar inside a Jupyter kernel (``tqdm.auto``, whose import costs a tenth of a
    second: asyncio), the terminal's elsewhere."""
    if "ipykernel" in sys.modules:
        from tqdm.auto import tqdm
    else:
        from tqdm.std import tqdm

    return tqdm(total=total, desc=desc, unit=unit, disable=not enabled(mode), delay=0.0 if mode else DELAY,
                leave=False, file=sys.stderr, dynamic_ncols=True, **kw)


class Ticker:
    """A bar without a known end for a single long call (a C loop): elapsed time, refreshed by a
    thread while the call runs.  Use as a context manager."""

    def __init__(self, desc: str, mode: bool | None = None):
        self.desc, self.mode = desc, mode
        self._stop = threading.Event()

    def __enter__(self):
        if enabled(self.mode):
            self._bar = bar(None, self.desc, unit="s", mode=self.mode, bar_format="{desc}: {elapsed}")
            self._thread = threading.Thread(target=self._tick, daemon=True)
            self._thread.start()
        return self

    def _tick(self) -> None:
        while not self._stop.wait(0.25):
            self._bar.refresh()

    def __exit__(self, *exc) -> None:
        if enabled(self.mode):
            self._stop.set()
            self._thread.join()
            self._bar.close()
