"""The Whipple–Carvallo benchmark bicycle (Meijaard, Papadopoulos, Ruina & Schwab 2007):
its linearised lean and steer equations derived from a four-body model with two wheels
rolling without slipping, eigenvalues from 0 to 10 m/s, and the weave and capsize speeds.

Run:  python examples/whipple_bicycle.py   (writes whipple_bicycle.png)
"""
import time

import numpy as np

from ncgen.analysis.whipple import WhippleBicycle, WhippleParameters

#: Table 1 of the paper, in its axes (x forward, y right, z down).
BENCHMARK = WhippleParameters(
    w=1.02, c=0.08, lam=np.pi / 10, g=9.81,
    r_R=0.3, m_R=2.0, I_R=(0.0603, 0.12),
    x_B=0.3, z_B=-0.9, m_B=85.0, I_B=((9.2, 0.0, 2.4), (0.0, 11.0, 0.0), (2.4, 0.0, 2.8)),
    x_H=0.9, z_H=-0.7, m_H=4.0, I_H=((0.05892, 0.0, -0.00756), (0.0, 0.06, 0.0), (-0.00756, 0.0, 0.00708)),
    r_F=0.35, m_F=3.0, I_F=(0.1405, 0.28),
)


def main():
    import matplotlib.pyplot as plt

    bike = WhippleBicycle(BENCHMARK)
    M, C1, K0, K2 = bike.matrices()
    np.set_printoptions(precision=14, suppress=True)
    print(f"M =\n{M}\nC1 =\n{C1}\nK0 =\n{K0}\nK2 =\n{K2}")
    speeds = np.linspace(0.0, 10.0, 100)
    start = time.perf_counter()
    lam = bike.eigenvalues(speeds)
    print(f"eigenvalues at {speeds.size} speeds in {time.perf_counter() - start:.2f} s")
    print("at 5 m/s:", bike.linearize(5.0).eigenvalues())
    weave, capsize = bike.weave_speed(), bike.capsize_speed()
    print(f"weave speed {weave:.14f} m/s, capsize speed {capsize:.14f} m/s")

    fig, ax = plt.subplots(figsize=(7, 5))
    ax.plot(speeds, lam.real, "k.", ms=3)
    ax.plot(speeds, np.abs(lam.imag), ".", color="tab:blue", ms=3)
    for v in (weave, capsize):
        ax.axvline(v, color="grey", lw=0.8, ls="--")
    ax.axhline(0.0, color="grey", lw=0.8)
    ax.set(xlabel="forward speed v (m/s)", ylabel="eigenvalues (1/s): real (black), |imaginary| (blue)",
           ylim=(-10, 10), title="Whipple bicycle, benchmark parameters")
    fig.savefig("whipple_bicycle.png", dpi=100)
    print("wrote whipple_bicycle.png")


if __name__ == "__main__":
    main()
