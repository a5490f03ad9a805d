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

A call into our own C loops (ctypes, which releases the GIL) is stopped by Ctrl-C through the
loop's stop flag, which the loop reads before every step (:func:`call_interruptibly`): the
main thread calls the loop itself while SIGINT, written to a pipe by Python's C-level signal
handler (``signal.set_wakeup_fd``), wakes a watcher thread (started once per process) that
sets the flag; no thread is started per call, so a short run costs microseconds more than
its loop.
"""
from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading

try:                                       # signal's functions without its enum conversions (8 µs a call)
    import _signal as _raw
except ImportError:                        # pragma: no cover - not CPython
    _raw = signal

_remembered = [0, False]          # [depth of sticky_interrupt blocks, an interrupt not yet raised again]


def _usable() -> bool:
    return (threading.current_thread() is threading.main_thread()
            and _raw.getsignal(signal.SIGINT) is signal.default_int_handler)


def _sticky_handler(signum, frame):
    """:func:`sticky_interrupt`'s SIGINT handler: remember the interrupt, then raise it."""
    _remembered[1] = True
    raise KeyboardInterrupt


_sticky_handler.sticky = True              # call_interruptibly: a handler that raises KeyboardInterrupt


class sticky_interrupt:
    """See the module docstring (nests; the outermost block installs the handler).  A class,
    where a ``contextlib.contextmanager`` generator costs four times as much to enter and
    leave (every ``simulate`` enters one)."""

    __slots__ = ("previous", "entered")

    def __enter__(self) -> None:
        self.previous, self.entered = None, False
        if _remembered[0] == 0 and not _usable():
            return
        if _remembered[0] == 0:
            self.previous = _raw.signal(signal.SIGINT, _sticky_handler)
        _remembered[0] += 1
        self.entered = True

    def __exit__(self, *exc) -> bool:
        if self.entered:
            _remembered[0] -= 1
            if self.previous is not None:
                _raw.signal(signal.SIGINT, self.previous)
                _remembered[1] = False
        return False


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

    previous = _raw.signal(signal.SIGINT, handler)
    try:
        yield flag
    except Exception:
        if flag.hit:                       # the solver's failure was the interrupt
            raise KeyboardInterrupt from None
        raise
    finally:
        _raw.signal(signal.SIGINT, previous)
    if flag.hit:
        raise KeyboardInterrupt


#: Seconds the main thread waits at a time in :func:`_call_in_thread` (the delay before
#: Ctrl-C is seen).
WAIT_SLICE = 0.05


def call_interruptibly(fn, *args, stop):
    """``(fn(*args), interrupted)``: ``fn`` (a C loop called through ctypes, which releases
    the GIL, reading ``stop``, a ``ctypes.c_int``, before every step) called while Ctrl-C sets
    ``stop.value = 1``; ``interrupted``: whether SIGINT arrived meanwhile (also when the loop
    had just finished).  The SIGINT handler in place (Python's, or :func:`sticky_interrupt`'s)
    then runs as it would have, its ``KeyboardInterrupt`` caught.  In the main thread under
    such a handler: a direct call watched by the :class:`_Watcher`; under another handler, in
    a worker thread while the main thread waits (the handler decides what Ctrl-C does); off
    the main thread, where no SIGINT arrives, and where SIGINT is ignored (a job started in
    the background by a shell, ``nohup``) or has its default action (the process ends), a
    direct call.  Exceptions of ``fn`` are raised here."""
    if threading.current_thread() is not threading.main_thread():
        return fn(*args), False
    previous = _raw.getsignal(signal.SIGINT)
    if previous == _raw.SIG_IGN or previous == _raw.SIG_DFL:
        return fn(*args), False
    if not (previous is signal.default_int_handler or getattr(previous, "sticky", False)) or sys.platform == "win32":
        return _call_in_thread(fn, *args, stop=stop)
    flag = InterruptFlag()

    def record(signum, frame):
        flag.hit = True

    _raw.signal(signal.SIGINT, record)        # from here SIGINT only records: no KeyboardInterrupt mid-setup
    watcher = _watcher()
    try:
        watcher.stop = stop
        watcher.forward = _raw.set_wakeup_fd(watcher.write, warn_on_full_buffer=False)
        try:
            if flag.hit:
                stop.value = 1
            result = _in_c(fn, args)
        finally:
            _raw.set_wakeup_fd(watcher.forward)
            watcher.stop, watcher.forward = None, -1
    finally:
        _raw.signal(signal.SIGINT, previous)
    if flag.hit:
        try:                                      # what the handler does on Ctrl-C (sticky: remember it)
            previous(signal.SIGINT, None)
        except KeyboardInterrupt:
            pass
    return result, flag.hit


def _in_c(fn, args):
    """``fn(*args)``: the frame the main thread is in while a C loop runs (tests find it)."""
    return fn(*args)


class _Watcher:
    """A thread reading the pipe that Python's C-level signal handler writes signal numbers to
    (``signal.set_wakeup_fd``, set by :func:`call_interruptibly` around a C loop): SIGINT sets
    the loop's stop flag ``stop``; other signals' bytes go on to the descriptor that was set
    before (``forward``, an event loop's)."""

    def __init__(self):
        self.read, self.write = os.pipe()
        os.set_blocking(self.write, False)
        self.stop, self.forward = None, -1
        threading.Thread(target=self._watch, name="ncgen-interrupt-watcher", daemon=True).start()

    def _watch(self) -> None:
        while True:
            data = os.read(self.read, 64)
            stop = self.stop
            if int(signal.SIGINT) in data and stop is not None:
                stop.value = 1
            other = bytes(b for b in data if b != int(signal.SIGINT))
            if other and self.forward >= 0:
                with contextlib.suppress(OSError):
                    os.write(self.forward, other)


_WATCHER: list = []
if hasattr(os, "register_at_fork"):          # a forked child has no watcher thread: it starts its own
    os.register_at_fork(after_in_child=_WATCHER.clear)


def _watcher() -> _Watcher:
    """The process's :class:`_Watcher`, started on first use."""
    if not _WATCHER:
        _WATCHER.append(_Watcher())
    return _WATCHER[0]


def _call_in_thread(fn, *args, stop):
    """:func:`call_interruptibly` under a SIGINT handler of the application's: ``fn`` in a
    worker thread while the main thread waits; a ``KeyboardInterrupt`` meanwhile sets
    ``stop.value = 1`` and the wait goes on until the loop returns."""
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
