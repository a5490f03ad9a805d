"""Ctrl-C (SIGINT) that C code cannot swallow.

CasADi checks for Ctrl-C inside its functions and solvers and turns it into an error (IDAS:
``IDA_RES_FAIL``; IPOPT: a stop that may still report success), clearing Python's
``KeyboardInterrupt`` on the way; code that falls back on such an error then goes on.  Two
remedies, both active only in the main thread while SIGINT has Python's default handler
(neither ignored nor taken by the application):

* :func:`sticky_interrupt`: SIGINT raises ``KeyboardInterrupt`` as usual and is also
  remembered, and :func:`raise_if_interrupted` raises it again at the checkpoints of long runs
  (the start of a simulation, between IDAS chunks, the end of a build).
* :func:`deferred_interrupt`: SIGINT only sets a flag that the caller polls where it can
  stop cleanly (IPOPT's iteration callback); leaving the block with the flag set raises
  ``KeyboardInterrupt``.
"""
from __future__ import annotations

import contextlib
import signal
import threading


_remembered = [0, False]          # [depth of sticky_interrupt blocks, an interrupt not yet raised again]


def _usable() -> bool:
    return (threading.current_thread() is threading.main_thread()
            and signal.getsignal(signal.SIGINT) is signal.default_int_handler)


@contextlib.contextmanager
def sticky_interrupt():
    """See the module docstring (nests; the outermost block installs the handler)."""
    if _remembered[0] == 0 and not _usable():
        yield
        return

    def handler(signum, frame):
        _remembered[1] = True
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGINT, handler) if _remembered[0] == 0 else None
    _remembered[0] += 1
    try:
        yield
    finally:
        _remembered[0] -= 1
        if previous is not None:
            signal.signal(signal.SIGINT, previous)
            _remembered[1] = False


def raise_if_interrupted() -> None:
    """Raise ``KeyboardInterrupt`` if SIGINT arrived in a :func:`sticky_interrupt` block and
    was swallowed since (a no-op otherwise)."""
    if _remembered[1]:
        _remembered[1] = False
        raise KeyboardInterrupt


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
    if threading.current_thread() is not threading.main_thread() or not (
            _usable() or _remembered[0]):
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
