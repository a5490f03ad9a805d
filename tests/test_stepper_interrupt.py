"""Ctrl-C stops a compiled stepper (or joint-space) run within seconds (the C loops check a
stop flag before every step; Python waits for them in a worker thread): exit 130 from the CLI, the previous
result file untouched, the partial trajectory written as ``*.incomplete.*``; from Python a
:class:`~ncgen.errors.SimulationInterrupted` carrying the trajectory so far."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

import ncgen as nc
from ncgen.runtime.stepper_library import load_stepper

ROOT = Path(__file__).resolve().parents[1]
CHAIN = str(ROOT / "examples" / "chain.toml")
PENDULUM = str(ROOT / "examples" / "double_pendulum.toml")        # a tree, for the joint-space loop
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


# Runs of ~10^7 steps: many minutes uninterrupted on this machine.
RUNS = {"fixed": "method='stepper', substeps=1000", "adaptive": "method='stepper', rtol=1e-11, atol=1e-11",
        "joint": "method='joint', integrator='rk4', substeps=100000"}


@pytest.mark.parametrize("mode", sorted(RUNS))
def test_interrupt_in_python_stops_within_seconds_with_the_trajectory_so_far(mode):
    code = ("import ncgen as nc, time\n"
            f"m = nc.System.from_toml({PENDULUM if mode == 'joint' else CHAIN!r}).build()\n"
            "from ncgen.runtime.stepper_library import load_stepper\n"
            "from ncgen.runtime.joint_simulation import joint_loop\n"
            f"{'joint_loop(m)' if mode == 'joint' else 'load_stepper(m)'}\n"
            "print('built', flush=True)\n"
            "start = time.monotonic()\n"
            "try:\n"
            f"    nc.simulate(m, 2000.0, 0.1, {RUNS[mode]})\n"
            "except nc.errors.SimulationInterrupted as e:\n"
            "    tr = e.trajectory\n"
            "    print('stopped', e.time, len(tr), tr.complete, tr.t[-1], isinstance(e, KeyboardInterrupt),\n"
            "          time.monotonic() - start, flush=True)\n")
    p = start([sys.executable, "-c", code], ROOT)
    line = p.stdout.readline()
    assert line.strip() == "built", line + p.stderr.read()[-2000:]
    rc, out, err, after = interrupt(p, 3.0)
    assert rc == 0, err
    assert after < 5.0, f"{after:.1f} s after SIGINT"
    words = out.split("stopped", 1)[1].split()
    t_stop, rows, complete, t_last, is_kb, ran = float(words[0]), int(words[1]), words[2], float(words[3]), \
        words[4], float(words[5])
    assert 0 < t_stop < 2000 and t_last == t_stop and rows > 1 and complete == "False" and is_kb == "True"
    assert ran < 30


def test_ctrl_c_stops_a_stepper_run_keeps_the_old_result_and_writes_the_partial_one(tmp_path):
    load_stepper(nc.System.from_toml(CHAIN).build())     # compiled once, cached
    old = tmp_path / "chain.npz"
    old.write_bytes(b"the previous result")
    p = start([sys.executable, "-m", "ncgen.cli", "simulate", CHAIN, "--method", "stepper", "--t-end", "2000",
               "--dt", "0.1", "--substeps", "1000", "-o", str(old)], tmp_path)
    rc, out, err, after = interrupt(p, 10.0)
    assert rc == 130, err
    assert "interrupted" in err and "internal error" not in err and "Traceback" not in err, err
    assert after < 5.0, f"{after:.1f} s after SIGINT"
    assert old.read_bytes() == b"the previous result"
    traj = nc.runtime.Trajectory.load(tmp_path / "chain.incomplete.npz")
    assert 0 < traj.t[-1] < 2000 and not traj.complete
    assert traj.constraint_residual.max() < 1e-8
