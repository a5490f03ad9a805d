"""Tensegrity prism (tensegrity.toml): pretension holds it up; gravity makes it sag a little.

Prints the cable tensions at rest, then simulates the small damped oscillation about the
sagged equilibrium.  Run:  python examples/tensegrity.py
"""
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

import ncgen as nc

model = nc.System.from_toml(Path(__file__).with_name("tensegrity.toml")).build()
print(model, "parameters:", dict(zip(model.parameter_names, model.p0)))
traj = nc.simulate(model, t_end=2.0, dt=0.005, backend="auto")
print(traj.summary())

top = traj.marker("strut1.top")
sag = (top[:, 2] - top[0, 2]) * 1e3
print(f"top of strut 1: at most {-sag.min():.3f} mm below its start, {-sag[-1]:.3f} mm below at the end")
fig, ax = plt.subplots()
ax.plot(traj.t, sag)
ax.set(xlabel="t (s)", ylabel="height change (mm)", title="tensegrity prism: top of strut 1")
fig.savefig("tensegrity.png", dpi=100)
print("wrote tensegrity.png")
