"""A 3D chain of N bars with spherical joints, written with the Python API.

With N = 5 this is exactly the model of chain.toml (same system functions, same initial
state: the model hashes agree).  Run:  python examples/chain.py [N]
"""
import sys
from pathlib import Path

import matplotlib.pyplot as plt

import ncgen as nc
from ncgen.codegen.model_package import model_hash


def chain(n: int = 5, length: float = 0.3, mass: float = 0.2) -> nc.System:
    """N 'rr' bars, horizontal as a staircase in the x-y plane; consecutive bars share an end
    (a spherical joint without extra coordinates), the first end is a ground point."""
    s = nc.System("chain", gravity=(0.0, 0.0, -9.81))
    start, x, y = s.ground.point((0.0, 0.0, 0.0)), 0.0, 0.0
    for k in range(1, n + 1):
        x, y = (round(x + length, 12), y) if k % 2 else (x, round(y + length, 12))
        bar = s.add_bar(f"bar{k}", coords="rr", mass=mass, ends=[start, (x, y, 0.0)])
        start = bar.end(1)
    bar.add_marker("tip", (length / 2, 0.0, 0.0))
    return s


if __name__ == "__main__":
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 5
    model = chain(n).build()
    print(model)
    if n == 5:
        toml_model = nc.System.from_toml(Path(__file__).with_name("chain.toml")).build()
        print("same model as chain.toml:", model_hash(model) == model_hash(toml_model))
    traj = nc.simulate(model, t_end=3.0, dt=0.01, backend="auto")
    print(traj.summary())
    tip = traj.marker(f"bar{n}.tip")
    fig, ax = plt.subplots(subplot_kw={"projection": "3d"})
    ax.plot(tip[:, 0], tip[:, 1], tip[:, 2])
    ax.set(xlabel="x (m)", ylabel="y (m)", zlabel="z (m)", title=f"tip of a chain of {n} bars, 3 s")
    fig.savefig("chain.png", dpi=100)
    print("wrote chain.png")
