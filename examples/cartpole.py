"""Cart-pole (cartpole.toml) pushed back and forth by its input force.

The input 'push' stays symbolic in the generated code; here it is a sine, u(t) in N.
Run:  python examples/cartpole.py
"""
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

import ncgen as nc

model = nc.System.from_toml(Path(__file__).with_name("cartpole.toml")).build()
print(model, "inputs:", model.input_names)
traj = nc.simulate(model, t_end=4.0, dt=0.01, u=lambda t: [2.0 * np.sin(2 * np.pi * t)], backend="auto")
print(traj.summary())

cart = traj.q[:, model.coordinate_names.index("cart.r_i.x")]
tip = traj.marker("pole.tip")
angle = np.degrees(np.arctan2(tip[:, 0] - cart, -tip[:, 1]))
fig, ax = plt.subplots(3, 1, sharex=True, figsize=(6, 6), layout="constrained")
ax[0].plot(traj.t, traj.u[:, 0])
ax[0].set(ylabel="push (N)")
ax[1].plot(traj.t, cart)
ax[1].set(ylabel="cart x (m)")
ax[2].plot(traj.t, angle)
ax[2].set(xlabel="t (s)", ylabel="pole angle (deg)")
fig.savefig("cartpole.png", dpi=100)
print("wrote cartpole.png")
