"""Robots falling: ncgen's joint-space simulation (``simulate(method="joint")``, a compiled C
loop around the joint-space forward dynamics) against MuJoCo's RK4, end to end and at equal
final-angle accuracy.

Robots (example-robot-data, as shipped; the Panda's ``<mimic>`` tag dropped for all engines,
``<dynamics>`` dropped, limits and contacts off in MuJoCo): the Panda (9 joints, fixed base)
from a bent pose at rest, and Talos (``talos_reduced.urdf``, floating base, 32 joints,
``--talos``) tumbling from a bent pose with random joint rates and base twist (2 rad/s,
m/s; at rest it would fall without relative motion), 1 s under gravity with zero torque.
MuJoCo loads the same URDF (visual and collision geometry removed; a free joint added to
Talos's root), RK4 integrator.

Reference: scipy DOP853 on ``pinocchio.aba`` at rtol = atol = 1e-13.  Error: the largest
final joint-angle error (rad; for Talos the joint angles and the base position).

Per target accuracy (``--targets``, default 1e-6 and 1e-3 rad):

* MuJoCo: its best step, searched finely (``--steps`` geometric values of ``h`` between
  2e-5 s and 0.05 s, ``round(1/h)`` steps): the largest ``h`` whose error is within the target;
* ncgen: the loosest ``rtol`` (half-decades from 1e-3 to 1e-13, ``atol = rtol``) of the
  error-controlled Dormand–Prince 5(4) loop within the target, and for comparison the
  fewest RK4 ``substeps`` (``dt`` = 1 s) within it.

Timed, interleaved, ``--repeat`` times each (seconds, min and median, wall clock and this
process's CPU time):

* "end to end": ncgen ``from_urdf → build → simulate`` (compile cache warm: the library is
  found by content) vs MuJoCo ``MjModel.from_xml_string → MjData → steps``;
* "first run": the same ncgen path once with an empty compile cache (generation and
  compilation of the loop included), against MuJoCo's median;
* "simulate only": ``nc.simulate`` on the built model with its loop loaded vs MuJoCo's
  stepping loop on a loaded model.

    python benchmarks/joint_simulation.py [--repeat 5] [--talos] [--smoke]
"""
from __future__ import annotations

import argparse
import importlib.metadata as md
import math
import os
import re
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import ncgen as nc  # noqa: E402
from common import machine, terminal_sigint  # noqa: E402

terminal_sigint()

ROBOTS = {"panda": ("panda_description/urdf/panda.urdf", False),
          "talos": ("talos_data/robots/talos_reduced.urdf", True)}


def robot_file(rel: str) -> Path:
    for f in md.files("example-robot-data") or []:
        if str(f).endswith(rel):
            return Path(f.locate())
    raise SystemExit(f"example-robot-data has no {rel}; pip install example-robot-data")


def ident(s: str) -> str:
    return re.sub(r"\W", "_", s)


class Robot:
    """The URDF text, Pinocchio's model, the initial state and the reference."""

    def __init__(self, name: str):
        import pinocchio as pin

        rel, self.floating = ROBOTS[name]
        self.name = name
        self.text = re.sub(r"<mimic[^>]*/>", "", robot_file(rel).read_text())
        self.text = re.sub(r"<dynamics[^>]*/>", "", self.text)
        self.mj_text = re.sub(r"<(visual|collision)\b.*?</\1>", "", self.text, flags=re.S)
        self.pm = pin.buildModelFromXML(self.text, pin.JointModelFreeFlyer()) if self.floating \
            else pin.buildModelFromXML(self.text)
        rng = np.random.default_rng(7)
        q0 = pin.neutral(self.pm)
        lo, hi = self.pm.lowerPositionLimit, self.pm.upperPositionLimit
        start = 7 if self.floating else 0
        for j in range(start, self.pm.nq):
            if np.isfinite(lo[j]) and np.isfinite(hi[j]) and hi[j] - lo[j] < 10:
                q0[j] = lo[j] + (hi[j] - lo[j]) * (0.3 + 0.4 * rng.random())
        self.q0 = q0
        # a floating robot at rest falls without relative motion (uniform gravity): give it a tumble
        self.v0 = 2.0 * rng.standard_normal(self.pm.nv) if self.floating else np.zeros(self.pm.nv)
        self.joint_names = [ident(self.pm.names[j]) for j in range(1, self.pm.njoints)
                            if self.pm.joints[j].shortname() != "JointModelFreeFlyer"]
        self.reference = self._reference()

    def _reference(self) -> np.ndarray:
        import pinocchio as pin
        from scipy.integrate import solve_ivp

        pm, pd, nq = self.pm, self.pm.createData(), self.pm.nq

        def f(_, x):
            q, v = x[:nq], x[nq:]
            if self.floating:
                q = pin.normalize(pm, q)
            a = pin.aba(pm, pd, q, v, np.zeros(pm.nv))
            dq = np.zeros(pm.nv)
            dq[:] = v
            qd = np.zeros(nq)
            if self.floating:
                R = pin.Quaternion(q[6], q[3], q[4], q[5]).toRotationMatrix()
                x_, y_, z_, w_ = q[3:7]
                wx, wy, wz = v[3:6]
                qd[:3] = R @ v[:3]
                qd[3:7] = 0.5 * np.array([w_ * wx + y_ * wz - z_ * wy, w_ * wy + z_ * wx - x_ * wz,
                                          w_ * wz + x_ * wy - y_ * wx, -x_ * wx - y_ * wy - z_ * wz])
                qd[7:] = v[6:]
            else:
                qd[:] = v
            return np.concatenate([qd, a])

        sol = solve_ivp(f, (0.0, 1.0), np.concatenate([self.q0, self.v0]), method="DOP853", rtol=1e-13, atol=1e-13)
        return self.compared(sol.y[:nq, -1])

    def compared(self, q_pin_order: np.ndarray) -> np.ndarray:
        """The compared final values: joint angles (and the base position)."""
        q = np.asarray(q_pin_order, float)
        return np.concatenate([q[:3], q[7:]]) if self.floating else q.copy()

    # ---------------------------------------------------------------- ncgen
    def ncgen_state(self, model):
        js = model.joint_space
        sq = js.slices()
        sv = js.slices(rates=True)
        qj, vj = np.zeros(js.nq), np.zeros(js.nv)
        k = 7 if self.floating else 0
        if self.floating:
            qj[sq["root"]], vj[sv["root"]] = self.q0[:7], self.v0[:6]
        for n in self.joint_names:
            qj[sq[n]], vj[sv[n]] = self.q0[k], self.v0[k - 1 if self.floating else k]
            k += 1
        return model.from_joint_space(qj, vj)

    def ncgen_final(self, model, traj) -> np.ndarray:
        sq = model.joint_space.slices()
        qj = traj.qj[-1]
        angles = np.array([qj[sq[n]][0] for n in self.joint_names])
        return np.concatenate([qj[sq["root"]][:3], angles]) if self.floating else angles

    def ncgen_run(self, options: dict):
        model = nc.System.from_urdf(self.text, floating_base=self.floating).build()
        q0, v0 = self.ncgen_state(model)
        traj = nc.simulate(model, 1.0, 1.0, q0=q0, v0=v0, method="joint", **options)
        return model, traj

    # ---------------------------------------------------------------- MuJoCo
    def mujoco_model(self, h: float):
        import mujoco

        spec = mujoco.MjSpec.from_string(self.mj_text)
        if self.floating:
            spec.worldbody.first_body().add_freejoint()
        m = spec.compile()
        m.opt.timestep = h
        m.opt.integrator = mujoco.mjtIntegrator.mjINT_RK4
        m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
        m.jnt_limited[:] = 0
        m.dof_damping[:] = 0
        m.dof_frictionloss[:] = 0
        m.dof_armature[:] = 0
        return m

    def _mujoco_index(self, m):
        """Pinocchio's one-coordinate joints' (q index, v index) -> MuJoCo's (qpos, qvel) address, by name."""
        by_name = {m.joint(i).name: (int(m.jnt_qposadr[i]), int(m.jnt_dofadr[i])) for i in range(m.njnt)}
        out = []
        for j in range(1, self.pm.njoints):
            jm = self.pm.joints[j]
            if jm.shortname() != "JointModelFreeFlyer":
                out.append((jm.idx_q, jm.idx_v, *by_name[self.pm.names[j]]))
        return out

    def mujoco_run(self, h: float, m=None):
        import mujoco

        m = self.mujoco_model(h) if m is None else m
        d = mujoco.MjData(m)
        index = self._mujoco_index(m)
        for iq, iv, mq, mv in index:
            d.qpos[mq], d.qvel[mv] = self.q0[iq], self.v0[iv]
        if self.floating:        # MuJoCo: quaternion [w, x, y, z], linear velocity in world axes
            import pinocchio as pin
            R = pin.Quaternion(self.q0[6], self.q0[3], self.q0[4], self.q0[5]).toRotationMatrix()
            d.qpos[:7] = [*self.q0[:3], self.q0[6], self.q0[3], self.q0[4], self.q0[5]]
            d.qvel[:6] = [*(R @ self.v0[:3]), *self.v0[3:6]]
        for _ in range(int(round(1.0 / h))):
            mujoco.mj_step(m, d)
        q = np.zeros(self.pm.nq)
        for iq, _, mq, _ in index:
            q[iq] = d.qpos[mq]
        if self.floating:
            q[:7] = [*d.qpos[:3], d.qpos[4], d.qpos[5], d.qpos[6], d.qpos[3]]
        return m, self.compared(q)


def error(a, b) -> float:
    return float(np.max(np.abs(np.asarray(a) - np.asarray(b))))


def mujoco_best_steps(robot: Robot, targets, n_steps: int) -> dict:
    """The largest step within each target (None: not reached)."""
    hs = np.geomspace(2e-5, 0.05, n_steps)
    errs = {}
    for h in hs:
        N = int(round(1.0 / h))
        h = 1.0 / N
        try:
            _, q = robot.mujoco_run(h)
            errs[h] = error(q, robot.reference)
        except Exception:       # noqa: BLE001 - diverged at a large step
            errs[h] = math.inf
    best = {}
    for tgt in targets:
        ok = [h for h, e in errs.items() if e <= tgt]
        best[tgt] = (max(ok), errs[max(ok)]) if ok else None
    fine = errs[min(errs)]
    print(f"  MuJoCo RK4 error at its finest step {min(errs):.2e} s: {fine:.2e} rad "
          f"({'the model agrees with Pinocchio' if fine < 1e-8 else 'THE MODELS DISAGREE'})")
    return best


def ncgen_best(robot: Robot, targets, model) -> dict:
    """Loosest rtol of the DOPRI5 loop and fewest RK4 substeps within each target."""
    q0, v0 = robot.ncgen_state(model)
    out = {}
    rtols = [10 ** (-k / 2) for k in range(6, 27)]
    subs = sorted({int(round(x)) for x in np.geomspace(5, 50_000, 60)})
    def err(**options) -> float:
        try:
            traj = nc.simulate(model, 1.0, 1.0, q0=q0, v0=v0, method="joint", **options)
        except nc.NcgenError:        # diverged (RK4 at a large step)
            return math.inf
        return error(robot.ncgen_final(model, traj), robot.reference)

    for tgt in targets:
        r = next(((rt, e) for rt in rtols for e in [err(rtol=rt, atol=rt)] if e <= tgt), None)
        s = next(((n, e) for n in subs for e in [err(integrator="rk4", substeps=n)] if e <= tgt), None)
        out[tgt] = {"dopri5": r, "rk4": s}
    return out


def timed(fn) -> tuple[float, float]:
    """``(wall, CPU)`` seconds of ``fn()`` (CPU: this process, ``time.process_time``)."""
    t, c = time.perf_counter(), time.process_time()
    fn()
    return time.perf_counter() - t, time.process_time() - c


def ratio_line(label: str, a: list[tuple[float, float]], b: list[tuple[float, float]]) -> str:
    """Wall and CPU times (min / median) of the interleaved rounds ``a`` (ncgen) and ``b``
    (MuJoCo) and the ratios of their rounds."""
    lines = []
    for i, clock in enumerate(("wall", "CPU")):
        x, y = [r[i] for r in a], [r[i] for r in b]
        ratios = [u / w for u, w in zip(x, y)]
        lines.append(f"  {label:<34} {clock:>4}: ncgen {min(x):8.4f} / {statistics.median(x):8.4f} s   MuJoCo "
                     f"{min(y):8.4f} / {statistics.median(y):8.4f} s (min / median)\n"
                     f"  RATIO ncgen / MuJoCo RK4, {label}, {clock}: min {min(ratios):.2f}, median "
                     f"{statistics.median(ratios):.2f}")
    return "\n".join(lines)


def bench(name: str, targets, repeat: int, n_steps: int) -> None:
    print(f"\n=== {name}: 1 s fall, zero torque")
    t0 = time.perf_counter()
    robot = Robot(name)
    print(f"  reference (DOP853 on pinocchio.aba, 1e-13) in {time.perf_counter() - t0:.1f} s")
    mj = mujoco_best_steps(robot, targets, n_steps)
    with tempfile.TemporaryDirectory() as cache:
        os.environ["NCGEN_CACHE_DIR"] = cache
        first = timed(lambda: robot.ncgen_run({"rtol": 1e-8, "atol": 1e-8}))[0]
        print(f"  ncgen first run with an empty compile cache (from_urdf, build, generate + compile, simulate): "
              f"{first:.2f} s")
        model, _ = robot.ncgen_run({})
        best = ncgen_best(robot, targets, model)
        for tgt in targets:
            print(f"\n  target {tgt:g} rad: MuJoCo RK4 h = {mj[tgt][0] if mj[tgt] else float('nan'):.3g} s "
                  f"(error {mj[tgt][1] if mj[tgt] else float('nan'):.2e}); ncgen DOPRI5 rtol = "
                  f"{best[tgt]['dopri5'][0]:.1e} (error {best[tgt]['dopri5'][1]:.2e}), RK4 substeps = "
                  f"{best[tgt]['rk4'][0] if best[tgt]['rk4'] else 'none'}")
            if mj[tgt] is None:
                print("  MuJoCo does not reach the target at any searched step")
                continue
            h = mj[tgt][0]
            opts = {"rtol": best[tgt]["dopri5"][0], "atol": best[tgt]["dopri5"][0]}
            opts_rk4 = {"integrator": "rk4", "substeps": best[tgt]["rk4"][0]} if best[tgt]["rk4"] else None
            e2e_n, e2e_r, e2e_m, sim_n, sim_m = [], [], [], [], []
            mjm = robot.mujoco_model(h)
            q0, v0 = robot.ncgen_state(model)
            for _ in range(repeat):
                e2e_n.append(timed(lambda: robot.ncgen_run(opts)))
                if opts_rk4:
                    e2e_r.append(timed(lambda: robot.ncgen_run(opts_rk4)))
                e2e_m.append(timed(lambda: robot.mujoco_run(h)))
                sim_n.append(timed(lambda: nc.simulate(model, 1.0, 1.0, q0=q0, v0=v0, method="joint", **opts)))
                sim_m.append(timed(lambda: robot.mujoco_run(h, mjm)))
            print(ratio_line("end to end, DOPRI5 (cache warm)", e2e_n, e2e_m))
            if opts_rk4:
                print(ratio_line("end to end, RK4 (cache warm)", e2e_r, e2e_m))
            print(f"  {'first run (empty cache) / MuJoCo median':<34} "
                  f"{first / statistics.median(r[0] for r in e2e_m):8.1f}x (wall)")
            print(ratio_line("simulate only, DOPRI5", sim_n, sim_m))
        os.environ.pop("NCGEN_CACHE_DIR")


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--steps", type=int, default=60, help="MuJoCo step sizes searched")
    ap.add_argument("--targets", type=float, nargs="+", default=[1e-6, 1e-3])
    ap.add_argument("--talos", action="store_true", help="also Talos (slow to build)")
    ap.add_argument("--smoke", action="store_true", help="one repeat, few steps (CI)")
    a = ap.parse_args(argv)
    if a.smoke:
        a.repeat, a.steps, a.targets = 1, 8, [1e-3]
    print(machine())
    print(f"load average: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    bench("panda", a.targets, a.repeat, a.steps)
    if a.talos:
        bench("talos", a.targets, a.repeat, a.steps)
    print(f"\nload average: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
