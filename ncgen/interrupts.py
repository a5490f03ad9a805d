"""Ctrl-C (SIGINT) that C code cannot swallow.

CasADi checks for Ctrl-C inside its solvers and turns it into a solver failure (IDAS:
``IDA_RES_FAIL``; IPOPT: a stop that may still report success), clearing Python's
``KeyboardInterrupt`` on the way.  Inside :func:`deferred_interrupt`, SIGINT only sets a flag
that the caller polls where it can stop cleanly (IPOPT's iteration callback), and leaving the
block with the flag set raises ``KeyboardInterrupt``.  Outside the main thread, or when
SIGINT is not Python's default handler (ignored, or taken by the application), the block
changes nothing.
"""
from __future__ import annotations

import contextlib
import signal
import threading


class InterruptFlag:
    """Whether SIGINT arrived; :meth:`check` raises ``KeyboardInterrupt`` if it did."""

    def __init__(self):
        self.hit = False

    def check(self, *_) -> None:
        if self.hit:
            raise KeyboardInterrupt


@contextlib.contextmanager
def deferred_interrupt():
    """See the module docstring; yields the :class:`InterruptFlag`."""
    flag = InterruptFlag()
    if (threading.current_thread() is not threading.main_thread()
            or signal.getsignal(signal.SIGINT) is not signal.default_int_handler):
        yield flag
        return

    def handler(signum, frame):
        flag.hit = True

    previous = signal.signal(signal.SIGINT, handler)
    try:
        yield flag
    except Exception:
        if flag.hit:                       # the solver's failure was the interrupt
            raise KeyboardInterrupt from None
        raise
    finally:
        signal.signal(signal.SIGINT, previous)
    if flag.hit:
        raise KeyboardInterrupt
