"""Ctrl-C (SIGINT to the process group, as a terminal sends it) stops a run within seconds
with exit code 130, leaves the previous result file untouched and writes the partial
trajectory as ``*.incomplete.*``."""
from __future__ import annotations

import os
import signal
import sys
import time

import pytest

from ncgen.errors import SimulationInterrupted
from ncgen.runtime.trajectory import Trajectory

from interrupt_helpers import IN_IDAS, ROOT, cli, interrupt, start, wait_until_running


def interrupt_running(cmd, cwd):
    """SIGINT 1 s into ``cmd``'s IDAS run (started with :data:`IN_IDAS`), whose end is hours away;
    ``(returncode, out, err, seconds to exit)``."""
    p = start(cmd, cwd)
    wait_until_running(p)
    return interrupt(p)


def test_ctrl_c_stops_an_idas_run_keeps_the_old_result_and_writes_the_partial_one(tmp_path):
    old = tmp_path / "chain.npz"
    old.write_bytes(b"the previous result")
    cmd = cli(IN_IDAS, "simulate", str(ROOT / "examples" / "chain.toml"), "--t-end", "5000", "--dt", "0.01",
              "-o", str(old), "--backend", "vm")
    rc, out, err, after = interrupt_running(cmd, tmp_path)
    assert rc == 130, err
    assert "interrupted" in err and "internal error" not in err and "Traceback" not in err
    # wall time by nature (how soon Ctrl-C is obeyed): IDAS returns within one of its steps
    # and the partial trajectory is written in well under 1 s unloaded; 10 s leaves 10× for a
    # machine at load 8 on 2 cores (each process then gets a quarter of a core)
    assert after < 10.0
    assert old.read_bytes() == b"the previous result"
    assert "partial trajectory" in err, err
    traj = Trajectory.load(tmp_path / "chain.incomplete.npz")
    assert 0 < traj.t[-1] < 5000 and not traj.complete


def test_interrupt_in_python_carries_the_trajectory_so_far():
    code = (IN_IDAS + "import ncgen as nc, sys\n"
            f"m = nc.System.from_toml({str(ROOT / 'examples' / 'chain.toml')!r}).build()\n"
            "print('built', flush=True)\n"
            "try:\n"
            "    nc.simulate(m, 5000.0, 0.01, backend='vm')\n"
            "except nc.errors.SimulationInterrupted as e:\n"
            "    print('stopped', e.time, len(e.trajectory), e.trajectory.complete, isinstance(e, KeyboardInterrupt))\n")
    rc, out, err, _ = interrupt_running([sys.executable, "-c", code], ROOT)
    assert rc == 0, err
    words = out.split("stopped", 1)[1].split()
    assert float(words[0]) > 0 and int(words[1]) > 1 and words[2] == "False" and words[3] == "True"
    assert issubclass(SimulationInterrupted, KeyboardInterrupt)


@pytest.mark.slow      # a subprocess solving an OCP until SIGINT; fast:
#                       test_ctrl_c_stops_an_idas_run_keeps_the_old_result_and_writes_the_partial_one (the same signal
#                       path), test_deferred_interrupt_raises_on_leaving_and_replaces_the_solver_failure
def test_ctrl_c_stops_ipopt_at_its_next_iteration(tmp_path):
    for name in ("cartpole.toml", "cartpole_swingup.toml"):
        text = (ROOT / "examples" / name).read_text()
        (tmp_path / name).write_text(text.replace("N = 50 ", "N = 300 ").replace("tol = 1e-8", "tol = 1e-8\nverbose = true"))
    old = tmp_path / "sw.npz"
    old.write_bytes(b"the previous result")
    p = start([sys.executable, "-m", "ncgen.cli", "optimize", str(tmp_path / "cartpole_swingup.toml"), "-o", str(old)],
              tmp_path)
    printed = ""
    while not any(line.split()[:1] == ["1"] for line in printed.splitlines()):   # IPOPT's first iteration
        line = p.stdout.readline()
        assert line, f"ended before IPOPT's first iteration: {printed[-2000:]}"
        printed += line
    sent = time.monotonic()
    os.killpg(p.pid, signal.SIGINT)
    out, err = p.communicate(timeout=60)
    assert "EXIT: Optimal" not in out, "the solve ended before the interrupt could stop it"
    assert p.returncode == 130, printed[-1000:] + out[-1000:] + err
    assert time.monotonic() - sent < 10.0      # wall by nature: IPOPT's next iteration, < 1 s unloaded; 10× margin
    assert "interrupted" in err and "Traceback" not in err
    assert old.read_bytes() == b"the previous result"


def test_deferred_interrupt_raises_on_leaving_and_replaces_the_solver_failure():
    from ncgen.interrupts import deferred_interrupt
    with pytest.raises(KeyboardInterrupt):
        with deferred_interrupt() as flag:
            signal.raise_signal(signal.SIGINT)
            assert flag.hit
    with pytest.raises(KeyboardInterrupt):
        with deferred_interrupt():
            signal.raise_signal(signal.SIGINT)
            raise RuntimeError("User_Requested_Stop")
    with pytest.raises(RuntimeError):
        with deferred_interrupt():
            raise RuntimeError("a real failure")
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
