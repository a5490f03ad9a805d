"""The benchmarks run (``--smoke``: tiny models, seconds) and print their comparisons.
Nothing here is timed: the figures are the benchmarks' business, not CI's.  The scripts share
the run's compile cache (the element and tree libraries, the chains and robots several of them
build are compiled once); those that measure a first run make their own empty cache.  The scripts
compile at -O0 here (``QUICK_COMPILE``, tests/conftest.py: their runs are tiny, their time is gcc),
as the test modules that build the same packages do (the cart-pole MPC's, the contact pyramid's)."""
from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("mujoco")

BENCHMARKS = Path(__file__).resolve().parent.parent / "benchmarks"
QUICK_COMPILE = True
pytestmark = [pytest.mark.slow, pytest.mark.timeout(1800),   # each benchmark script end to end: minutes
              pytest.mark.skipif(shutil.which("cc") is None and shutil.which("gcc") is None,
                                 reason="no C compiler")]


@pytest.mark.parametrize("script, expected", [
    ("work_precision.py", ["=== chain of N = 2 bars", "explicit nc.Spherical joints", "reference check",
                           "first run (cold compile cache)", "bisection on the steps to 2 s",
                           "RATIO ncgen rattle4 / MuJoCo RK4 at 1e-03", "BEST ncgen setting at 1e-03",
                           "BEST ncgen with an error estimate", "local estimate:", "load average"]),
    ("work_precision.py --curves", ["=== chain of N = 2 bars", "RATIO ncgen stepper (end to end) / MuJoCo RK4",
                                    "reference check", "explicit nc.Spherical joints",
                                    "RATIO explicit joints / shared points", "end-to-end / stepping time"]),
    ("work_precision.py --sweep", ["=== chain of N = 2 bars", "spiral hanging", "stiff-spring pendulum",
                                   re.compile(r"mujoco RK4: 2\d step sizes"),
                                   re.compile(r"ncgen default \(rattle4, shadow estimate\): 2\d step sizes"),
                                   "RATIO ncgen default (rattle4, shadow estimate) / MuJoCo RK4 at 1e-03, hanging",
                                   "interleaved rounds, load average", "plot written to"]),
    ("rattle4.py", ["=== chain of N = 2 bars", "RATIO rattle4 / MuJoCo RK4 at 1e-03", "RATIO rattle4 / rattle"]),
    ("kernel.py", ["=== chain of N = 3 bars", "RATIO VM / generated C"]),
    ("kernel.py --looped", ["=== looped vs straight-line C: chain of N = 3 bars", "max |difference| = 0.0e+00",
                            re.compile(r"loops in the looped C: [1-9]"),
                            "RATIO looped -O2 / flat -O2, jacobian", "RATIO VM / looped -O2, residual"]),
    ("first_run.py", ["=== first ncgen simulate, cold cache", "vm backend", "=== model -> loaded library",
                      "monotonic in N"]),
    ("load_time.py", ["=== slider_crank: ncgen simulate", "later runs (model stored)", "later runs, store off",
                      "RATIO later run, store off / stored, CPU", "=== panda: MuJoCo and Pinocchio",
                      "RATIO ncgen later run / MuJoCo load process", "load average at the end",
                      "=== panda from Python", "from_urdf().build(), stored", "first run, derivations stored",
                      "heavy modules a later run imports: none"]),
    ("build_scaling.py", ["=== ncgen: chain of N bars", "KanesMethod", "EXTRAPOLATED"]),
    ("second_model.py", ["=== a model never seen -> first compiled step, no compiler on PATH", "chain    this",
                         "SymPy imported: False", "kernels tables"]),
    ("build_scaling.py --build-cpu ..", ["=== System -> build() of the chain", "made by build(): phi, A"]),
    ("long_run.py", ["=== heavy top", "=== chain of 5 bars", "RATIO ncgen / MuJoCo RK4"]),
    ("contact.py", ["=== chain of N = 3 bars falling on the ground", "RATIO ncgen / MuJoCo wall time",
                    "RATIO ncgen / MuJoCo penetration"]),
    ("table_contacts.py", ["=== falling_chain", "RATIO tables / package, time per step, falling_chain", "load average at the end"]),
    ("contact.py --pyramid", ["=== pyramid of 10 boxes", "ncgen first run, fresh process and empty cache",
                              "ncgen step search", "MuJoCo step search, Newton solver, elliptic cones, Euler",
                              "contact solves at the sweep cap: 0",
                              "RATIO ncgen / MuJoCo CPU interleaved (pyramid of 10", "keeping the shape",
                              "RATIO ncgen / MuJoCo penetration (pyramid of 10)"]),
    ("joint_space.py", ["=== call overhead", "RATIO casadi.external / direct", "=== Panda",
                        "RATIO ncgen joint kernel / pinocchio.aba", "RATIO ncgen joint kernel C loop"]),
    ("tree_algorithms.py", ["=== ur5", "RATIO ur5 ncgen forward dynamics / pinocchio.aba",
                            "RATIO ur5 ncgen RNEA / pinocchio.rnea",
                            "RATIO ur5 ncgen ABA derivatives / pinocchio.computeABADerivatives"]),
    ("call_overhead.py", ["=== ur10", "RATIO ur10 nc.inverse_dynamics / pinocchio.rnea",
                          "RATIO ur10 nc.aba / pinocchio.aba", "RATIO ur10 nc.joint_forward_dynamics / pinocchio.aba",
                          "rnea_agreement", "load average"]),
    ("animation.py", ["=== slider_crank", "RATIO PillowWriter / ncgen animate", "to_html:"]),
    ("joint_simulation.py", ["=== panda: 1 s fall", "RATIO ncgen / MuJoCo RK4, end to end, DOPRI5",
                             "RATIO ncgen / MuJoCo RK4, simulate only, DOPRI5", "agrees with Pinocchio"]),
    ("simulate_start_callgrind.py", ["=== panda: nc.simulate of one 1 ms output step from a new start",
                                     re.compile(r"this tree: +[\d,]+ instructions per call, start check")]),
    ("door_overhead.py", ["=== doors against their kernels alone in a C loop", re.compile(r"nc\.rnea +[\d.]+ "),
                          "nc.aba_derivatives, 4 rows, out=", "JointStep.jacobians, out=",
                          "nc.forward_dynamics compiled, out=", "StepFunction.jacobians, out=", "OVERHEAD",
                          "load average at the end"]),
    ("door_callgrind.py", ["=== ur10: one call of each door at one state",
                           re.compile(r"joint_forward_dynamics: this tree [\d,]+ instructions per call")]),
    ("simulate_fixed_cost.py --model balls", ["=== balls (4 bodies on spherical joints): nc.simulate of one 1 ms "
                                              "output step", "this tree: FIXED COST, a new start each call, CPU"]),
    ("simulate_fixed_cost.py", ["=== panda (the fall's URDF): nc.simulate of one 1 ms output step",
                                "this tree: FIXED COST (simulate - loop), CPU",
                                "this tree: FIXED COST, a new start each call, CPU", "load average at the end"]),
    ("batch.py", ["=== scaling: 8 runs", "RATIO one thread / two threads", "per-run cost of one-step runs",
                  "RATIO ncgen / mujoco.rollout, 1 thread(s)", "RATIO ncgen / mujoco.rollout, 2 thread(s)",
                  "CPU RATIO ncgen checked / mujoco.rollout, 1 thread(s)"]),
    ("batch_estimates.py", ["4 runs of 0.5 s", "estimate='shadow': flagged", "estimate='local': flagged"]),
    ("sharing_chain.py", ["=== chain of N = 3 bars", "RATIO explicit (shared by build) / shared-point chain"]),
    ("reactions_shared.py", ["=== explicit-joint chain of N = 3 bars", "unshared form built on first use",
                             "RATIO shared / share=False, joint_reactions per state"]),
    ("optimal_control.py", [re.compile(r"cartpole +8 \|"), re.compile(r"acrobot +8 \|"), re.compile(r"arm3d +8 \|"),
                            "RATIO ncgen / minimal, iterations", "RATIO ncgen / minimal, solve time",
                            "converged: ncgen 3/3, minimal 3/3"]),
    ("control.py", ["=== step Jacobians: chain of N = 3 bars", "RATIO ncgen / mujoco mjd_transitionFD forward",
                    "=== cart-pole MPC", "RATIO IPOPT re-solve / MPC step"]),
    ("tensegrity_clustered.py", ["=== deploying tower", "RATIO clustered / independent, IDAS",
                                 "RATIO clustered / independent, stepper"]),
    ("table_step_jacobians.py", ["ncgen's A against central differences of its step",
                                 "=== chain of N = 3 bars", "RATIO ncgen tables st.jacobians / mujoco mjd_transitionFD "
                                 "centred"]),
    ("step_jacobians.py", ["=== twodofs: nq = ", "C: ", "compiler peak RSS", "st.jacobians(x, u)",
                           "central differences: A", "TARGET twodofs"]),
    ("tree_tables_callgrind.py", ["=== ur5: instructions per state", "ur5 aba: tables",
                                  "RATIO ur5 crba instructions: tables / flat", "results agree"]),
    ("joint_mpc.py", ["Panda reach over 0.3 s", "JointMPC qp_solver='box', default BLAS threads: per step",
                     "JointMPC qp_solver='box', OPENBLAS_NUM_THREADS=1: per step", "load average at the end"]),
    ("joint_step_jacobians.py", ["AGREE to 1e-06", "RATIO ncgen JointStep.jacobians / mujoco mjd_transitionFD centred",
                                 "aba_derivatives is", "load average at end"]),
    ("joint_ilqr_reach.py", ["Panda reach over 0.2 s", "GAP (iLQR − IPOPT) / IPOPT", "converged True"]),
    ("contact_implicit.py", ["=== block push, T = 0.6 s", "RATIO contact-implicit / fixed sequence",
                             "=== hopper (examples/hopper_gait.py, N = 30) from standing"]),
    ("contact_implicit_pusher_box.py --scene hopper", ["=== hopper (examples/hopper_gait.py), N = 30",
                                                      "RATIO naive / fixed sequence, IPOPT CPU", "Solve_Succeeded"]),
    ("contact_implicit_pusher_box.py", ["=== pusher_box (examples/pusher_box.py), N = 10",
                                        "RATIO naive / fixed sequence, IPOPT CPU", "Solve_Succeeded"]),
    ("box_stack_first_run.py", ["box_stack first run (empty cache)", "round 1 this", "CPU s min / median"]),
    ("pair_kind_calls.py", ["heap20: stepping CPU s", "calls / built-in min", "max |Δq|"]),
    ("mjcf_import_time.py", ["first    parse wall", "later 1  parse wall", "n =   10:", "CPU per element",
                             "load average at the end"]),
])
def test_smoke(script, expected):
    if script in ("joint_space.py", "joint_simulation.py", "tree_algorithms.py", "load_time.py", "call_overhead.py",
                  "door_overhead.py"):
        pytest.importorskip("pinocchio")
        pytest.importorskip("yourdfpy")
    if script in ("step_jacobians.py", "joint_mpc.py", "joint_step_jacobians.py", "joint_ilqr_reach.py"):
        pytest.importorskip("yourdfpy")
    if script in ("tree_tables_callgrind.py", "simulate_start_callgrind.py", "door_callgrind.py"):
        pytest.importorskip("pinocchio")     # with example-robot-data's URDFs
        pytest.importorskip("yourdfpy")
        if shutil.which("valgrind") is None:
            pytest.skip("valgrind is not installed")
    root = str(BENCHMARKS.parent)        # the checkout under test, whatever ncgen is installed
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [root, os.environ.get("PYTHONPATH")]))}
    name, *options = script.split()
    out = subprocess.run([sys.executable, str(BENCHMARKS / name), *options, "--smoke"], cwd=BENCHMARKS,
                         capture_output=True, text=True, env=env)
    assert out.returncode == 0, out.stderr[-3000:]
    for text in expected:
        found = text.search(out.stdout) if isinstance(text, re.Pattern) else text in out.stdout
        assert found, (text, out.stdout[-3000:])
    assert "CPU:" in out.stdout and "versions:" in out.stdout
