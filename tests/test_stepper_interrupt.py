"""Ctrl-C stops a compiled stepper (or joint-space) run within seconds (the C loops check a
stop flag before every step, set by a watcher thread woken by SIGINT): exit 130 from the CLI, the previous
result file untouched, the partial trajectory written as ``*.incomplete.*``; from Python a
:class:`~ncgen.errors.SimulationInterrupted` carrying the trajectory so far."""
from __future__ import annotations

import sys

import pytest

import ncgen as nc

from interrupt_helpers import IN_C_LOOP, ROOT, cli, interrupt, start, wait_until_running

CHAIN = str(ROOT / "examples" / "chain.toml")
PENDULUM = str(ROOT / "examples" / "double_pendulum.toml")        # a tree, for the joint-space loop
# Runs of ~10^7 steps: many minutes uninterrupted on this machine.
RUNS = {"fixed": "method='stepper', substeps=1000", "adaptive": "method='stepper', rtol=1e-11, atol=1e-11",
        "joint": "method='joint', integrator='rk4', substeps=100000"}


@pytest.mark.parametrize("mode", sorted(RUNS))
def test_interrupt_in_python_stops_within_seconds_with_the_trajectory_so_far(mode):
    code = (IN_C_LOOP + "import ncgen as nc, time\n"
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
    wait_until_running(p)                # SIGINT 1 s into the C loop (rows > 1), long before its end (minutes)
    rc, out, err, after = interrupt(p)
    assert rc == 0, err
    assert after < 5.0, f"{after:.1f} s after SIGINT"
    words = out.split("stopped", 1)[1].split()
    t_stop, rows, complete, t_last, is_kb, ran = float(words[0]), int(words[1]), words[2], float(words[3]), \
        words[4], float(words[5])
    assert 0 < t_stop < 2000 and t_last == t_stop and rows > 1 and complete == "False" and is_kb == "True"
    assert ran < 30


@pytest.mark.slow      # fast: Ctrl-C in the C loop (test above, stepper and joint) and the CLI's partial result (IDAS, test_reliability_interrupt.py)
def test_ctrl_c_stops_a_stepper_run_keeps_the_old_result_and_writes_the_partial_one(tmp_path):
    old = tmp_path / "chain.npz"
    old.write_bytes(b"the previous result")
    p = start(cli(IN_C_LOOP, "simulate", CHAIN, "--method", "stepper", "--t-end", "2000", "--dt", "0.1",
                  "--substeps", "1000", "-o", str(old)), tmp_path)
    wait_until_running(p)                # SIGINT 1 s into the C loop, long before its end, however loaded the machine
    rc, out, err, after = interrupt(p)
    assert rc == 130, err
    assert "interrupted" in err and "internal error" not in err and "Traceback" not in err, err
    # wall time by nature: the C loop checks the flag every step (microseconds) and the partial
    # trajectory is written in ~0.3 s unloaded; 5 s leaves > 10× for load 8 on 2 cores
    assert after < 5.0, f"{after:.1f} s after SIGINT"
    assert old.read_bytes() == b"the previous result"
    traj = nc.Trajectory.load(tmp_path / "chain.incomplete.npz")
    assert 0 < traj.t[-1] < 2000 and not traj.complete
    assert traj.constraint_residual.max() < 1e-8
