"""Cart-pole stabilisation by model-predictive control, in Python and as a C program.

The problem of examples/cartpole_mpc.toml (20 intervals of 0.05 s, push within ±20 N) becomes
a receding-horizon controller (nc.MPC: one real-time SQP iteration per control step on the
RATTLE step with exact Jacobians, generated C).  The plant is ncgen's RATTLE step at h/5;
the pole starts 0.2 rad off the upright and the cart gets an 8 N push at t = 1 s.  Then the
same controller is exported as a standalone C package (nc.export_mpc), built with `make`
and run without Python: its closed loop matches the Python one.

Run:  python examples/cartpole_mpc.py        (writes the package to ./cartpole_mpc)
"""
import shutil
import subprocess
from pathlib import Path

import numpy as np

import ncgen as nc
from ncgen.control.export import closed_loop
from ncgen.optim.problem_file import load_problem

here = Path(__file__).parent
model = nc.System.from_toml(here / "cartpole.toml").build()
ocp = load_problem(here / "cartpole_mpc.toml", model)[0]
mpc = nc.MPC(ocp, terminal_weight=100.0)

tilt = 0.2
x0 = np.concatenate([[0, 0, 1, 0, 0, 1, 0.5 * np.sin(tilt), 0.5 * np.cos(tilt)], np.zeros(8)])
push = [(1.0, 1.1, [8.0])]
t, U, X = closed_loop(mpc, x0, 4.0, disturbance=push)
print(f"Python closed loop: |push| ≤ {np.max(np.abs(U)):.2f} N; at t = {t[-1]:.2f} s the cart is at "
      f"{X[-1, 0]:+.1e} m and the pole tip at {X[-1, 6:8].round(5)} m")

pkg = nc.export_mpc(ocp, "cartpole_mpc", terminal_weight=100.0, x0=x0, t_end=4.0, disturbance=push)
if shutil.which("make") and shutil.which("cc"):
    subprocess.run(["make", "-s", "demo"], cwd=pkg.path, check=True)
    out = subprocess.run(["./demo"], cwd=pkg.path, check=True, capture_output=True, text=True).stdout
    C = np.array([[float(v) for v in line.split()] for line in out.splitlines()])
    print(f"C closed loop ({pkg.path}/demo): max |u_C − u_Python| = {np.max(np.abs(C[:, 1] - U[:, 0])):.1e}")
