"""Long-run quality: energy and constraint drift over 100 s at a fixed step, the ncgen
stepper against MuJoCo, for the heavy top and the chain.

Models: ``examples/heavy_top.toml`` (a symmetric top on a fixed tip in steady precession,
spin 150 rad/s) and the chain of 5 bars of benchmarks/common.py (examples/chain.toml,
chaotic).  Their MuJoCo twins: the top as one body with a ball joint at the tip, the same
mass, centre of mass, principal inertia, orientation and angular velocity; the chain as in
benchmarks/common.py.  Both conservative: the exact energy is constant.

Quantities, sampled every 10 ms: relative energy error max |E(t) − E(0)| / max(|E(0)|, T),
and its mean over the first and the last tenth of the run (equal means: no drift); for
ncgen the constraint drift max |Φ| and max |A v + Φ_t| (MuJoCo integrates in joint
coordinates, so its joints cannot drift: not applicable).  Steps: the same fixed step for
every method (MuJoCo RK4, MuJoCo Euler = its default); wall time of the whole run.

    python benchmarks/long_run.py            100 s, h = 1 ms (top: 0.5 ms)
    python benchmarks/long_run.py --smoke    1 s (CI)
"""
from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from common import chain_mjcf, chain_system, machine

ROOT = Path(__file__).resolve().parent.parent
SAMPLE = 0.01


def top_mjcf(model, timestep: float, integrator: str) -> str:
    """The heavy top of examples/heavy_top.toml in MJCF (values read from the ncgen member)."""
    top = model.member("top")
    R, com = top.R0, top.p0
    local_com = R.T @ com                               # the tip is the world origin
    J = top.rigid.Jbar                                  # J̄ = ½ tr(Ī) I − Ī  ⇒  Ī = tr(J̄) I − J̄
    inertia = np.diag(np.trace(J) * np.eye(3) - J)
    quat = _quat(R)
    return (f'<mujoco model="heavy_top"><compiler inertiafromgeom="false" angle="radian"/>'
            f'<option timestep="{timestep!r}" integrator="{integrator}" gravity="0 0 -9.81">'
            f'<flag contact="disable" energy="enable"/></option><worldbody>'
            f'<body name="top" pos="0 0 0" quat="{_nums(quat)}">'
            f'<joint type="ball" damping="0" armature="0"/>'
            f'<inertial pos="{_nums(local_com)}" mass="{top.rigid.mass!r}" '
            f'diaginertia="{_nums(inertia)}"/></body></worldbody></mujoco>')


def _nums(x) -> str:
    return " ".join(repr(float(v)) for v in x)


def _quat(R: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of a rotation matrix."""
    w = np.sqrt(max(0.0, 1 + np.trace(R))) / 2
    if w > 1e-8:
        return np.array([w, (R[2, 1] - R[1, 2]) / (4 * w), (R[0, 2] - R[2, 0]) / (4 * w), (R[1, 0] - R[0, 1]) / (4 * w)])
    i = int(np.argmax(np.diag(R)))
    j, k = (i + 1) % 3, (i + 2) % 3
    x = np.sqrt(max(0.0, 1 + R[i, i] - R[j, j] - R[k, k])) / 2
    q = np.zeros(4)
    q[1 + i], q[1 + j], q[1 + k] = x, (R[j, i] + R[i, j]) / (4 * x), (R[k, i] + R[i, k]) / (4 * x)
    q[0] = (R[k, j] - R[j, k]) / (4 * x)
    return q


def mujoco_energy(xml: str, t_end: float, qvel=None) -> tuple[np.ndarray, float]:
    """``(E, seconds)``: total energy every SAMPLE s, and the wall time of a separate run
    stepped in one call."""
    import mujoco

    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    steps = int(round(SAMPLE / model.opt.timestep))
    n = int(round(t_end / SAMPLE))

    def reset():
        mujoco.mj_resetData(model, data)
        if qvel is not None:
            data.qvel[:] = qvel
        mujoco.mj_forward(model, data)

    reset()
    E = [data.energy.sum()]
    for _ in range(n):
        mujoco.mj_step(model, data, nstep=steps)
        mujoco.mj_forward(model, data)
        E.append(data.energy.sum())
    reset()
    start = time.perf_counter()
    mujoco.mj_step(model, data, nstep=steps * n)
    return np.array(E), time.perf_counter() - start


def drift(E: np.ndarray, scale: float) -> tuple[float, float, float]:
    err = np.abs(E - E[0]) / scale
    tenth = max(1, len(err) // 10)
    return float(np.max(err)), float(np.mean(err[:tenth])), float(np.mean(err[-tenth:]))


def run_case(name, model, xml_of, qvel, t_end, h) -> None:
    import ncgen as nc

    print(f"\n=== {name}: {t_end:g} s, step {h:g} s ===")
    # unchecked: over 100 s the phase error of any fixed step passes the checks' 1 % of the size;
    # energy and constraint drift are what this benchmark measures
    traj = nc.simulate(model, t_end, SAMPLE, method="stepper", substeps=int(round(SAMPLE / h)), check=False)
    scale = traj.energy_scale
    mx, first, last = drift(traj.energy, scale)
    print(f"  {'method':<22} {'max rel. energy error':>22} {'mean, first 10%':>16} {'mean, last 10%':>15} "
          f"{'max |phi|':>10} {'max |A v|':>10} {'wall time':>10}")
    print(f"  {'ncgen stepper':<22} {mx:>22.2e} {first:>16.2e} {last:>15.2e} "
          f"{np.max(traj.constraint_residual):>10.1e} {np.max(traj.velocity_residual):>10.1e} "
          f"{traj.info['wall_time']:>9.3f}s")
    results = {"ncgen": (mx, traj.info["wall_time"])}
    for integrator in ("RK4", "Euler"):
        E, secs = mujoco_energy(xml_of(h, integrator), t_end, qvel)
        mx, first, last = drift(E, scale)
        print(f"  {'MuJoCo ' + integrator:<22} {mx:>22.2e} {first:>16.2e} {last:>15.2e} "
              f"{'n/a':>10} {'n/a':>10} {secs:>9.3f}s")
        results[integrator] = (mx, secs)
    for integrator in ("RK4", "Euler"):
        (e1, t1), (e2, t2) = results["ncgen"], results[integrator]
        print(f"  RATIO ncgen / MuJoCo {integrator}: energy error {e1 / e2:.2g}, wall time {t1 / t2:.2f}")


def main(argv=None) -> int:
    import ncgen as nc

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--smoke", action="store_true", help="1 s instead of 100 s (CI)")
    parser.add_argument("--t-end", type=float, default=100.0, help="simulated time (s)")
    args = parser.parse_args(argv)
    t_end = 1.0 if args.smoke else args.t_end
    print(machine())
    warnings.simplefilter("ignore")
    top = nc.System.from_toml(ROOT / "examples" / "heavy_top.toml").build()
    R = top.member("top").R0
    omega = np.asarray(top.member("top").omega0, float)
    run_case("heavy top (examples/heavy_top.toml)", top, lambda h, i: top_mjcf(top, h, i), R.T @ omega, t_end, 5e-4)
    chain = chain_system(5).build()
    run_case("chain of 5 bars", chain, lambda h, i: chain_mjcf(5, integrator=i, timestep=h, energy=True), None,
             t_end, 1e-3)
    return 0


if __name__ == "__main__":
    sys.exit(main())
