"""Ctrl-C as a terminal sends it: a command started in its own process group with Python's
default SIGINT handler, and SIGINT sent to that group (tests of Ctrl-C handling)."""
from __future__ import annotations

import os
import signal
import subprocess
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}


def start(cmd, cwd):
    return subprocess.Popen(cmd, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True, env=ENV,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))


def interrupt(p, wait: float):
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
