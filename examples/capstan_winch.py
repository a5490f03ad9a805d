"""A winch reeling a rope over two friction drums lifts a weight (examples/capstan_winch.toml).

The winch reels in ``w(t) = r (t − τ (1 − e^{−t/τ}))`` (r = 0.1 m/s, τ = 0.05 s).  Closed forms
(massless, inextensible rope, both drums slipping towards the winch, μ = 0.3, wraps π/2):
the weight rises at r once steady, ``T_a = m g``, ``T_b = e^{μπ/2} T_a``, ``T_c = e^{μπ} T_a``.
The plot shows the weight's height against the reeled length and the sides' tensions against
those ratios; the script prints the steady figures beside the closed forms.

Run: python examples/capstan_winch.py
"""
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

import ncgen as nc

G, MU, RATE, TAU = 9.81, 0.3, 0.1, 0.05

if __name__ == "__main__":
    model = nc.System.from_toml(Path(__file__).with_suffix(".toml")).build()
    traj = nc.simulate(model, t_end=0.6, dt=0.005, backend="vm")
    z = traj.point("weight", (0, 0, 0))[:, 2]
    tension = np.array([np.array(model.springs.function(t, q, v, np.zeros(0), model.p0)[0]).reshape(-1)
                        for t, q, v in zip(traj.t, traj.q, traj.v)])
    late = traj.t >= 0.3
    rate = np.polyfit(traj.t[late], z[late], 1)[0]
    ratios = tension[late][-1] / tension[late][-1, 0]
    print(f"weight rises at {rate:.5f} m/s (reel rate {RATE}); T_a = {tension[-1, 0]:.4f} N (m g = {G:.4f}); "
          f"T_b/T_a = {ratios[1]:.4f} (e^(mu pi/2) = {np.exp(MU * np.pi / 2):.4f}), "
          f"T_c/T_a = {ratios[2]:.4f} (e^(mu pi) = {np.exp(MU * np.pi):.4f})")
    reeled = RATE * (traj.t - TAU * (1 - np.exp(-traj.t / TAU)))
    fig, (ax1, ax2) = plt.subplots(2, 1, sharex=True, figsize=(7, 6))
    ax1.plot(traj.t, z - z[0], label="weight height")
    ax1.plot(traj.t, reeled, "--", label="rope reeled in")
    ax1.set_ylabel("m")
    ax1.legend()
    for i, name in enumerate("abc"):
        ax2.plot(traj.t, tension[:, i], label=f"side {name}")
    for k, style in ((0, ":"), (0.5, ":"), (1, ":")):
        ax2.axhline(G * np.exp(MU * np.pi * k), color="gray", ls=style, lw=0.8)
    ax2.set_xlabel("t (s)")
    ax2.set_ylabel("tension (N)")
    ax2.legend()
    fig.savefig("capstan_winch.png", dpi=100)
    print("wrote capstan_winch.png")
