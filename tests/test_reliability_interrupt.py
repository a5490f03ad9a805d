"""Ctrl-C (SIGINT to the process group, as a terminal sends it) stops a run within seconds
with exit code 130, leaves the previous result file untouched and writes the partial
trajectory as ``*.incomplete.*``."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

import ncgen as nc
from ncgen.errors import SimulationInterrupted

ROOT = Path(__file__).resolve().parents[1]


def interrupt_after(cmd, seconds, cwd):
    p = subprocess.Popen(cmd, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         start_new_session=True, env={**os.environ, "PYTHONPATH": str(ROOT)},
                         preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    time.sleep(seconds)
    sent = time.monotonic()
    os.killpg(p.pid, signal.SIGINT)
    try:
        out, err = p.communicate(timeout=60)
    except subprocess.TimeoutExpired:
        p.kill()
        out, err = p.communicate()
        pytest.fail(f"still running 60 s after SIGINT: {err[-500:]}")
    return p.returncode, out, err, time.monotonic() - sent


def test_ctrl_c_stops_an_idas_run_keeps_the_old_result_and_writes_the_partial_one(tmp_path):
    old = tmp_path / "chain.npz"
    old.write_bytes(b"the previous result")
    cmd = [sys.executable, "-m", "ncgen.cli", "simulate", str(ROOT / "examples" / "chain.toml"), "--t-end", "5000",
           "--dt", "0.01", "-o", str(old), "--backend", "vm"]
    rc, out, err, after = interrupt_after(cmd, 12.0, tmp_path)
    assert rc == 130, err
    assert "interrupted" in err and "internal error" not in err and "Traceback" not in err
    assert after < 10.0
    assert old.read_bytes() == b"the previous result"
    partial = tmp_path / "chain.incomplete.npz"
    if "partial trajectory" in err:                       # the run had started (not still building)
        traj = nc.runtime.Trajectory.load(partial)
        assert 0 < traj.t[-1] < 5000 and not traj.complete


def test_interrupt_in_python_carries_the_trajectory_so_far():
    code = ("import ncgen as nc, sys\n"
            f"m = nc.System.from_toml({str(ROOT / 'examples' / 'chain.toml')!r}).build()\n"
            "print('built', flush=True)\n"
            "try:\n"
            "    nc.simulate(m, 5000.0, 0.01, backend='vm')\n"
            "except nc.errors.SimulationInterrupted as e:\n"
            "    print('stopped', e.time, len(e.trajectory), e.trajectory.complete, isinstance(e, KeyboardInterrupt))\n")
    rc, out, err, _ = interrupt_after([sys.executable, "-c", code], 12.0, ROOT)
    assert rc == 0, err
    if "built" in out:
        words = out.split("stopped", 1)[1].split()
        assert float(words[0]) > 0 and int(words[1]) > 1 and words[2] == "False" and words[3] == "True"
    assert issubclass(SimulationInterrupted, KeyboardInterrupt)
