"""The Franka Panda arm (URDF of example-robot-data) released from a bent posture with zero
joint torques: it falls under gravity, conserving its energy.

Needs the robots extra:  pip install 'ncgen[robots]'
Run:  python examples/panda.py
"""
import matplotlib.pyplot as plt
import numpy as np

import ncgen as nc

s = nc.System.from_urdf(nc.robots.urdf_path("panda"))     # joint torques: the input tau
model = s.build()
print(model)
qj = np.zeros(model.joint_space.nq)
qj[model.joint_names.index("panda_joint4")] = -1.5          # elbow bent (within its limits)
q0, v0 = model.from_joint_space(qj, np.zeros(model.joint_space.nv))
traj = nc.simulate(model, t_end=1.0, dt=0.005, q0=q0, v0=v0)   # zero torques: u = None
print(traj.summary())

fig, ax = plt.subplots(1, 2, figsize=(10, 4), layout="constrained")
for name in model.joint_names[:7]:
    ax[0].plot(traj.t, traj.joint(name)[0], lw=0.8, label=name.removeprefix("panda_"))
ax[0].set(xlabel="t (s)", ylabel="joint angle (rad)", title="Panda falling, zero torques")
ax[0].legend(fontsize=7)
ax[1].plot(traj.t, traj.energy - traj.energy[0])
ax[1].set(xlabel="t (s)", ylabel="E - E(0) (J)", title="energy (conservative: constant)")
fig.savefig("panda.png", dpi=100)
print("wrote panda.png")
