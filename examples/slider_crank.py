"""Slider-crank (slider_crank.toml) at three crank speeds: one compiled kernel, parameter p.

The crank speed 'omega' is a parameter, symbolic in the generated C, so the same compiled
DAE runs every speed.  The multiplier of the drive equation is the motor's effort.
Run:  python examples/slider_crank.py
"""
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

import ncgen as nc

model = nc.System.from_toml(Path(__file__).with_name("slider_crank.toml")).build()
x = model.coordinate_names.index("slider.r_i.x")
drive = model.constraint_names.index("motor.drive")
fig, ax = plt.subplots(2, 1, sharex=True)
for omega in (2 * np.pi, 4 * np.pi, 6 * np.pi):
    traj = nc.simulate(model, t_end=1.0, dt=0.005, p={"omega": omega}, backend="auto")
    print(f"omega = {omega:5.2f} rad/s: slider stroke {np.ptp(traj.q[:, x]):.4f} m, "
          f"peak |lambda_drive| = {np.abs(traj.lam[:, drive]).max():.3g}")
    ax[0].plot(traj.t, traj.q[:, x], label=f"omega = {omega:.1f} rad/s")
    ax[1].plot(traj.t, traj.lam[:, drive])
ax[0].set(ylabel="slider x (m)")
ax[0].legend()
ax[1].set(xlabel="t (s)", ylabel="drive multiplier")
fig.savefig("slider_crank.png", dpi=100)
print("wrote slider_crank.png")
