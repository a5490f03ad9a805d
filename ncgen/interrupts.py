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

A long call into our own C loops (ctypes, which releases the GIL) runs in a worker thread
instead (:func:`call_interruptibly`): Ctrl-C in the waiting main thread sets the loop's stop
flag, which the loop reads before every step.
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


#: Seconds the main thread waits at a time in :func:`call_interruptibly` (the delay before
#: Ctrl-C is seen).
WAIT_SLICE = 0.05


def call_interruptibly(fn, *args, stop):
    """``(fn(*args), interrupted)``: ``fn`` (a C loop called through ctypes, which releases
    the GIL) run in a worker thread while the main thread waits; a ``KeyboardInterrupt``
    meanwhile sets ``stop.value = 1`` (``stop``: the ``ctypes.c_int`` the loop reads before
    every step) and the wait goes on until the loop returns.  ``interrupted``: whether that
    happened (also when the loop had just finished).  Off the main thread, where no
    ``KeyboardInterrupt`` arrives, a direct call.  Exceptions of ``fn`` are raised here."""
    if threading.current_thread() is not threading.main_thread():
        return fn(*args), False
    result, finished = [], threading.Event()

    def work():
        try:
            result.append(fn(*args))
        except BaseException as e:          # re-raised in the caller's thread
            result.append(e)
        finally:
            finished.set()

    # An Event, not Thread.join: a join interrupted by KeyboardInterrupt may report the
    # thread ended while it still runs.
    threading.Thread(target=work, name="ncgen-c-loop", daemon=True).start()
    interrupted = False
    while not finished.is_set():
        try:
            finished.wait(WAIT_SLICE)
        except KeyboardInterrupt:
            stop.value = 1
            interrupted = True
    if isinstance(result[0], BaseException):
        raise result[0]
    return result[0], interrupted
