"""Ctrl-C as a terminal sends it: a command started in its own process group with Python's
default SIGINT handler, and SIGINT sent to that group (tests of Ctrl-C handling)."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}


def running_signal(caller: str, callee: str) -> str:
    """Python source to put first in a child's script: a thread that prints ``running`` once the
    main thread is in function ``callee`` called from function ``caller`` (the run that SIGINT
    is to stop), so the signal is timed from the run's start, not the process's, however fast
    or loaded the machine."""
    return textwrap.dedent(f"""\
        import sys as _sys, threading as _threading, time as _time
        def _watch():
            main = _threading.main_thread().ident
            while True:
                frame = _sys._current_frames().get(main)
                while frame is not None and frame.f_back is not None:
                    if frame.f_code.co_name == {callee!r} and frame.f_back.f_code.co_name == {caller!r}:
                        print("running", flush=True)
                        return
                    frame = frame.f_back
                _time.sleep(0.01)
        _threading.Thread(target=_watch, daemon=True).start()
        """)


#: :func:`running_signal` for the C loops (:func:`ncgen.interrupts.call_interruptibly` calling
#: the loop, ``_in_c``) and for IDAS (a chunk advanced in ``idas_integrator._run``).
IN_C_LOOP, IN_IDAS = running_signal("call_interruptibly", "_in_c"), running_signal("_run", "advance")


def cli(watcher: str, *args) -> list[str]:
    """The command line of ``ncgen args`` (run as ``python -m ncgen.cli`` runs it) with
    ``watcher`` (:data:`IN_C_LOOP` or :data:`IN_IDAS`) started first."""
    return [sys.executable, "-c", watcher + "import runpy\nrunpy.run_module('ncgen.cli', run_name='__main__', "
            "alter_sys=True)\n", *args]


def wait_until_running(p) -> str:
    """``p``'s standard output up to its ``running`` line (:func:`running_signal`)."""
    printed = ""
    while True:
        line = p.stdout.readline()
        if not line:
            p.kill()
            pytest.fail(f"ended before its run started: {printed[-1000:]} {p.stderr.read()[-2000:]}")
        printed += line
        if line.strip() == "running":
            return printed


def start(cmd, cwd):
    return subprocess.Popen(cmd, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True, env=ENV,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))


#: Seconds a run goes on (after :func:`wait_until_running`) before SIGINT: at load 8 on 2 cores the
#: compiled chain makes 5 (adaptive, rtol 1e-11) to 12 (fixed) output rows in 0.5 s, the
#: pendulum's joint loop 6; IDAS (dt 0.01) many more, so the partial trajectories' rows > 1 hold.
RUN_BEFORE_SIGINT = 1.0


def interrupt(p, wait: float = RUN_BEFORE_SIGINT):
    """SIGINT to ``p``'s process group after ``wait`` s; ``(returncode, out, err, seconds to exit)``."""
    time.sleep(wait)
    sent = time.monotonic()
    os.killpg(p.pid, signal.SIGINT)
    try:
        out, err = p.communicate(timeout=60)
    except subprocess.TimeoutExpired:
        p.kill()
        out, err = p.communicate()
        pytest.fail(f"still running 60 s after SIGINT: {err[-500:]}")
    return p.returncode, out, err, time.monotonic() - sent
