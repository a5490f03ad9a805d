"""Double pendulum (double_pendulum.toml): chaotic motion, conserved energy.

Run:  python examples/double_pendulum.py
"""
from pathlib import Path

import matplotlib.pyplot as plt

import ncgen as nc

model = nc.System.from_toml(Path(__file__).with_name("double_pendulum.toml")).build()
print(model)
traj = nc.simulate(model, t_end=5.0, dt=0.005, rtol=1e-10, atol=1e-12, backend="auto")
print(traj.summary())

tip = traj.marker("link2.tip")
fig, ax = plt.subplots(1, 2, figsize=(10, 4), layout="constrained")
ax[0].plot(tip[:, 0], tip[:, 2], lw=0.6)
ax[0].set(aspect="equal", xlabel="x (m)", ylabel="z (m)", title="tip of the second link")
ax[1].plot(traj.t, traj.energy - traj.energy[0])
ax[1].set(xlabel="t (s)", ylabel="E - E(0) (J)", title="energy drift")
fig.savefig("double_pendulum.png", dpi=100)
print("wrote double_pendulum.png")
