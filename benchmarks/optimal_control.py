"""Optimal control: ncgen (natural coordinates) against a minimal-coordinate formulation of the
same problems, written here directly in CasADi.

Cases (SI units; inputs piecewise constant over N equal intervals; cost ∫ uᵀ R u dt):

* ``cartpole`` — examples/cartpole_swingup.py: cart 1 kg on a rail, uniform pole 0.2 kg,
  0.5 m on a hinge at the cart; from hanging to upright at rest in 2 s, |push| ≤ 20 N,
  |cart x| ≤ 1.5 m, R = 1.
* ``acrobot`` — two uniform 1 m, 1 kg links (planar bars on Revolute joints "shoulder" and
  "elbow"), motor at the elbow only, |τ| ≤ 15 N·m; from hanging to upright at rest in 4 s,
  R = 0.1.
* ``arm3d`` — 3D: two rods (``ruvw`` bodies, 0.5 kg, 0.4 m, radius 2 cm) on hinges about
  y (shoulder at the origin, elbow at the first rod's end), both motorised,
  |τ| ≤ 5 N·m, gravity −z; from hanging at rest to shoulder +90° and elbow +90° at rest in
  T = 1 s, R = 1; in ncgen the target is the forearm's pose (``final(pose=...)``), the
  model built with coordinate sharing (the default).

ncgen's collocation form is its default, ``"auto"``: all three models are trees of joints,
so the joint-space form (:mod:`ncgen.optim.joint_radau`; joint coordinates as states,
natural coordinates ``q(q_j)`` in the costs and targets); ``--form ggl`` measures the
natural-coordinate GGL form instead.

The minimal formulation has the joint angles as coordinates (cart x and pole angle; the
links' angles), its equations of motion from the Lagrangian ``L = T − V`` (mass matrix
and bias by CasADi's algorithmic differentiation of the kinetic and potential energy, no
use of ncgen), an explicit ODE ``θ̈ = M(θ)⁻¹ (B u − b(θ, θ̇))``, the same Radau IIA
collocation of degree 3 with the same quadrature of the cost and bounds at the same points,
IPOPT with its default options, and a naive guess: the joint angles interpolated linearly
from start to end, inputs 0.  ncgen solves from its default guess (``ocp.solve()``).

Printed per case and N: IPOPT iterations, solve time (s, IPOPT call only), cost, and the
ratios ncgen / minimal; "at ncgen opt" is the minimal formulation solved again from ncgen's
optimum (joint angles and inputs at the nodes, the same winding), the check that both
reach the same optimum, and "rel diff" compares ncgen's cost with it; ``RATIO`` lines
summarise.  Targets (issue 18): iterations ≤ 2×,
time ≤ 10×, costs within 1e-3 (relative) at equal N.  The joint-space form and the minimal
formulation are the same discrete problem (Radau IIA(3) on the joint angles, rates
eliminated or not), so at the same optimum their costs agree to round-off; the natural
forms collocate other coordinates and agree only as N grows.

    python benchmarks/optimal_control.py                 N = 30, 40, 80, every case
    python benchmarks/optimal_control.py --cases arm3d --sizes 30
    python benchmarks/optimal_control.py --form ggl      natural-coordinate GGL form
    python benchmarks/optimal_control.py --coarse-start  ncgen solves on N/2 first (totals reported)
    python benchmarks/optimal_control.py --quick         N = 8 (seconds; CI)
    python benchmarks/optimal_control.py --cases arm3d --sizes 8 --panda 20   the Panda line

A separate ``PANDA setup`` line (not a ratio; skipped with ``--quick`` or ``--panda 0``)
times a point-to-point motion of the Panda arm (URDF from example-robot-data) at N = 20:
model build, NLP build (guess included), the solve call (CasADi's expansion and exact
Hessian, then IPOPT) and the share of IPOPT's function evaluations.
"""
from __future__ import annotations

import argparse
import sys
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import casadi as ca
import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
from common import machine  # noqa: E402

G = 9.81


# ------------------------------------------------------------------ minimal formulation
@dataclass
class MinimalProblem:
    """An OCP in joint coordinates: ``energies(θ, θ̇) -> (T, V)``, input map ``B`` (n × nu,
    constant), start and end states, input bounds, optional box on θ, horizon, weight."""

    n: int
    nu: int
    energies: Callable
    B: np.ndarray
    x_start: np.ndarray
    x_end: np.ndarray
    u_max: float
    T: float
    R: float
    theta_bounds: list | None = None      # [(index, lower, upper)]


def lagrange_ode(prob: MinimalProblem) -> ca.Function:
    """``(x, u) -> ẋ`` from the Lagrangian: ``M θ̈ + (∂(M θ̇)/∂θ) θ̇ − ∂T/∂θ + ∂V/∂θ = B u``."""
    th, dth, u = ca.SX.sym("th", prob.n), ca.SX.sym("dth", prob.n), ca.SX.sym("u", prob.nu)
    T, V = prob.energies(th, dth)
    M = ca.hessian(T, dth)[0]
    p = ca.gradient(T, dth)
    bias = ca.mtimes(ca.jacobian(p, th), dth) - ca.gradient(T, th) + ca.gradient(V, th)
    acc = ca.solve(M, ca.mtimes(ca.DM(prob.B), u) - bias)
    return ca.Function("ode", [ca.vertcat(th, dth), u], [ca.vertcat(dth, acc)])


def radau(d: int = 3):
    """Radau IIA points ``[0, τ_1..τ_d]``, derivative matrix ``C[r, j] = ℓ_r'(τ_j)``, weights."""
    tau = np.array([0.0] + list(ca.collocation_points(d, "radau")))
    C = np.zeros((d + 1, d))
    b = np.zeros(d)
    for r in range(d + 1):
        others = np.delete(tau, r)
        ell = np.poly1d(np.poly(others)) / np.prod(tau[r] - others)
        C[r] = np.polyder(ell)(tau[1:])
    for j in range(d):
        others = np.delete(tau[1:], j)
        ell = np.poly1d(np.poly(others)) / np.prod(tau[1 + j] - others)
        P = np.polyint(ell)
        b[j] = P(1.0) - P(0.0)
    return tau, C, b


def solve_minimal(prob: MinimalProblem, N: int, d: int = 3, guess=None) -> dict:
    """Solve at ``N`` intervals from the linear guess, or from ``guess = (t, θ, θ̇, u)``: joint
    angles and rates at times ``t`` on [0, T] and ``N`` inputs."""
    ode = lagrange_ode(prob)
    tau, C, _ = radau(d)
    nx = 2 * prob.n
    h = prob.T / N
    opti = ca.Opti()
    X = opti.variable(nx, N * d)
    U = opti.variable(prob.nu, N)
    F = ode.map(N * d)(X, ca.reshape(ca.repmat(U, d, 1), prob.nu, N * d))
    x_prev = ca.DM(prob.x_start)
    for k in range(N):
        cols = slice(k * d, (k + 1) * d)
        opti.subject_to(ca.mtimes(ca.horzcat(x_prev, X[:, cols]), ca.DM(C)) - h * F[:, cols] == 0)
        x_prev = X[:, k * d + d - 1]
    opti.subject_to(x_prev == ca.DM(prob.x_end))
    opti.subject_to(opti.bounded(-prob.u_max, U, prob.u_max))
    for i, lo, hi in prob.theta_bounds or []:
        opti.subject_to(opti.bounded(lo, X[i, :], hi))
    opti.minimize(h * prob.R * ca.sumsqr(U))
    s = ((np.arange(N)[:, None] + tau[None, 1:]) / N).reshape(-1)
    if guess is None:
        opti.set_initial(X, (np.outer(1 - s, prob.x_start) + np.outer(s, prob.x_end)).T)
        opti.set_initial(U, 0)
    else:
        tg, th, dth, ug = guess
        turns = np.round((th[-1] - prob.x_end[:prob.n]) / (2 * np.pi))     # the winding ncgen took
        prob.x_end = np.concatenate([prob.x_end[:prob.n] + 2 * np.pi * turns, prob.x_end[prob.n:]])
        x = np.hstack([th, dth])
        opti.set_initial(X, np.array([np.interp(s * prob.T, tg, x[:, i]) for i in range(nx)]))
        opti.set_initial(U, np.asarray(ug).T)
    opti.solver("ipopt", {"expand": True, "print_time": False},
                {"print_level": 0, "sb": "yes", "tol": 1e-8, "constr_viol_tol": 1e-8})
    start = time.perf_counter()
    try:
        sol = opti.solve()
        ok = True
    except RuntimeError:
        sol, ok = opti.debug, False
    elapsed = time.perf_counter() - start
    st = opti.stats()
    return {"iterations": int(st["iter_count"]), "time": elapsed, "cost": float(sol.value(opti.f)),
            "success": ok and st["success"]}


def planar_energies(links):
    """Energies of a planar chain given per link: mass, COM position p(θ) (SX 2-vector,
    height in component 1), absolute angle φ(θ), inertia about the COM."""
    def energies(th, dth):
        T, V = 0, 0
        for m, com, phi, inertia in links(th):
            v = ca.mtimes(ca.jacobian(com, th), dth)
            w = ca.mtimes(ca.jacobian(phi, th), dth)
            T += 0.5 * m * ca.sumsqr(v) + 0.5 * inertia * w ** 2
            V += m * G * com[1]
        return T, V
    return energies


# ------------------------------------------------------------------ the cases
def cartpole_minimal() -> MinimalProblem:
    mc, mp, L = 1.0, 0.2, 0.5

    def links(th):              # th = [cart x, pole angle from hanging, counter-clockwise]
        x, a = th[0], th[1]
        return [(mc, ca.vertcat(x, 0), 0 * x, 0.0),
                (mp, ca.vertcat(x + L / 2 * ca.sin(a), -L / 2 * ca.cos(a)), a, mp * L ** 2 / 12)]
    return MinimalProblem(2, 1, planar_energies(links), np.array([[1.0], [0.0]]),
                          np.zeros(4), np.array([0, np.pi, 0, 0]), 20.0, 2.0, 1.0, [(0, -1.5, 1.5)])


def cartpole_ncgen(N: int, form: str = "auto"):
    import ncgen as nc
    model = nc.System.from_toml(ROOT / "examples" / "cartpole.toml").build()
    ocp = nc.OptimalControl(model, N=N, t_final=2.0, form=form)
    ocp.bound_input("push", -20, 20)
    ocp.bound_coordinate("cart.r_i.x", -1.5, 1.5)
    ocp.initial(q={"cart.r_i.x": 0.0, "pole.r_j.x": 0.0, "pole.r_j.y": -0.5}, v=0)
    ocp.final(q={"cart.r_i.x": 0.0, "pole.r_j.x": 0.0, "pole.r_j.y": 0.5}, v=0)
    ocp.minimize_effort()
    return ocp


def acrobot_minimal() -> MinimalProblem:
    m, L = 1.0, 1.0

    def links(th):              # absolute angle of the upper link, elbow angle (relative)
        a1, a2 = th[0], th[0] + th[1]
        e = ca.vertcat(L * ca.sin(a1), -L * ca.cos(a1))
        return [(m, e / 2, a1, m * L ** 2 / 12),
                (m, e + ca.vertcat(L / 2 * ca.sin(a2), -L / 2 * ca.cos(a2)), a2, m * L ** 2 / 12)]
    return MinimalProblem(2, 1, planar_energies(links), np.array([[0.0], [1.0]]),
                          np.zeros(4), np.array([np.pi, 0, 0, 0]), 15.0, 4.0, 0.1)


def acrobot_ncgen(N: int, form: str = "auto"):
    import ncgen as nc
    s = nc.System("acrobot", gravity=(0, -G))
    upper = s.add_bar("upper", mass=1.0, ends=[(0, 0), (0, -1)])
    fore = s.add_bar("fore", mass=1.0, ends=[(0, -1), (0, -2)])
    s.add_joint(nc.Revolute(s.ground, upper, at=(0, 0), name="shoulder"))
    s.add_joint(nc.Revolute(upper, fore, at=(0, -1), name="elbow"))
    tau = s.add_input("tau")                       # elbow motor, N·m
    s.add_force(nc.Torque(upper, -tau))
    s.add_force(nc.Torque(fore, tau))
    model = s.build()
    ocp = nc.OptimalControl(model, N=N, t_final=4.0, form=form)
    ocp.bound_input("tau", -15, 15)
    ocp.final(q=[0, 1, 0, 2], v=0)
    ocp.minimize_effort(0.1)
    return ocp


ARM_M, ARM_L, ARM_RADIUS = 0.5, 0.4, 0.02


def arm_minimal() -> MinimalProblem:
    m, L = ARM_M, ARM_L
    inertia = m * L ** 2 / 12 + m * ARM_RADIUS ** 2 / 4

    def links(th):              # rotation about +y: a rod hanging along −z turns to (−sin, −cos) in (x, z)
        a1, a2 = th[0], th[0] + th[1]
        e = ca.vertcat(-L * ca.sin(a1), -L * ca.cos(a1))
        return [(m, e / 2, a1, inertia),
                (m, e + ca.vertcat(-L / 2 * ca.sin(a2), -L / 2 * ca.cos(a2)), a2, inertia)]
    return MinimalProblem(2, 2, planar_energies(links), np.eye(2), np.zeros(4),
                          np.array([np.pi / 2, np.pi / 2, 0, 0]), 5.0, 1.0, 1.0)


def roty(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def arm_frames(a1: float, a2: float):
    """``(R1, p1), (R2, p2)``: rotations and centres of the two rods at shoulder angle
    ``a1`` and elbow angle ``a2`` (rad, about +y), and the elbow position."""
    down = np.array([0, 0, -ARM_L])
    R1, R2 = roty(a1), roty(a1 + a2)
    elbow = R1 @ down
    return (R1, R1 @ down / 2), (R2, elbow + R2 @ down / 2), elbow


def arm_system(a1: float = 0.0, a2: float = 0.0):
    """The 3D arm with shoulder angle ``a1`` and elbow angle ``a2`` (rad, about +y)."""
    import ncgen as nc
    m, L, r = ARM_M, ARM_L, ARM_RADIUS
    inertia = np.diag([m * L ** 2 / 12 + m * r ** 2 / 4, m * L ** 2 / 12 + m * r ** 2 / 4, m * r ** 2 / 2])
    (R1, p1), (R2, p2), elbow = arm_frames(a1, a2)
    s = nc.System("arm3d", gravity=(0, 0, -G))
    b1 = s.add_body("upper", mass=m, inertia=inertia, position=p1, rotation=R1)
    b2 = s.add_body("fore", mass=m, inertia=inertia, position=p2, rotation=R2)
    b2.add_marker("hand", (0, 0, -L / 2))
    s.add_joint(nc.Revolute(s.ground, b1, at=(0, 0, 0), axis=(0, 1, 0), name="shoulder"))
    s.add_joint(nc.Revolute(b1, b2, at=tuple(elbow), axis=(0, 1, 0), name="elbow"))
    tau = s.add_input("tau", 2)                  # [shoulder, elbow] about +y, N·m
    s.add_force(nc.Torque(b1, ca.vertcat(0, tau[0] - tau[1], 0)))
    s.add_force(nc.Torque(b2, ca.vertcat(0, tau[1], 0)))
    return s


def arm_ncgen(N: int, form: str = "auto"):
    import ncgen as nc
    model = arm_system().build()
    ocp = nc.OptimalControl(model, N=N, t_final=1.0, form=form)
    ocp.bound_input("tau", -5, 5)
    _, fore, _ = arm_frames(np.pi / 2, np.pi / 2)
    ocp.final(pose={"fore": fore}, v=0)           # the forearm's pose; the joints place the upper rod
    ocp.minimize_effort()
    return ocp


def _planar_angle(R):
    """Angle of a planar bar or body from hanging (x̄ along −y), counter-clockwise."""
    return np.arctan2(R[0, 0], -R[1, 0])


def _about_y(R):
    """Angle about +y of a body whose local −z̄ hangs along world −z at zero."""
    return np.arctan2(R[0, 2], R[0, 0])


def cartpole_angles(model, q):
    R = model.poses(q)[0]
    return [q[model.coordinate_names.index("cart.r_i.x")], _planar_angle(R[model.member_names.index("pole")])]


def acrobot_angles(model, q):
    R = model.poses(q)[0]
    a1, a2 = _planar_angle(R[0]), _planar_angle(R[1])
    return [a1, a2 - a1]


def arm_angles(model, q):
    R = model.poses(q)[0]
    a1, a2 = _about_y(R[0]), _about_y(R[1])
    return [a1, a2 - a1]


CASES = {"cartpole": (cartpole_ncgen, cartpole_minimal, cartpole_angles),
         "acrobot": (acrobot_ncgen, acrobot_minimal, acrobot_angles),
         "arm3d": (arm_ncgen, arm_minimal, arm_angles)}


def solve_ncgen(make, angles, N: int, max_iter: int, form: str, coarse_start: bool = False) -> dict:
    """ncgen from its default guess (with ``coarse_start``: first on N // 2 intervals, then on
    N from that solution, iterations and times summed); ``path``: ``(t, joint angles, u)``."""
    import ncgen as nc
    iterations, elapsed, warm = 0, 0.0, None
    for n in ([N // 2, N] if coarse_start else [N]):
        ocp = make(n, form)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                sol = ocp.solve(warm_start=warm, max_iter=max_iter, diagnose=False)
                st, ok = sol.stats, True
            except nc.errors.OptimizationError as exc:
                sol, ok = exc.result, False
                st = sol.stats
        iterations, elapsed, warm = iterations + st.iterations, elapsed + st.solve_time, sol
    th = np.unwrap(np.array([angles(ocp.model, q) for q in sol.q]), axis=0)
    dth = np.array([ocp.model.to_joint_space(q, v)[1] for q, v in zip(sol.q, sol.v)])
    return {"iterations": iterations, "time": elapsed, "cost": st.objective, "success": ok and st.success,
            "size": f"{st.n_variables}x{st.n_constraints}", "path": (sol.t - sol.t[0], th, dth, sol.u[:-1])}


def panda_setup(N: int) -> str:
    """The Panda (example-robot-data URDF, 9 joints, mimic coupling of the fingers removed)
    from rest at the model's q0 to 0.3 rad on its seven arm joints at rest in 1 s, |τ| ≤
    80 N·m, minimum effort, N intervals (joint-space form): model build, NLP build (guess
    included), the solve call (CasADi's expansion and exact derivatives, then IPOPT) and
    IPOPT's function evaluations, in seconds."""
    import importlib.metadata as md
    import re

    import ncgen as nc
    try:
        urdf = next(Path(f.locate()) for f in md.files("example-robot-data") or []
                    if str(f).endswith("panda_description/urdf/panda.urdf"))
    except (md.PackageNotFoundError, StopIteration):
        return "PANDA setup: skipped (pip install example-robot-data)"
    start = time.perf_counter()
    model = nc.System.from_urdf(re.sub(r"<mimic[^>]*/>", "", urdf.read_text())).build()
    t_model = time.perf_counter() - start
    ocp = nc.OptimalControl(model, N=N, t_final=1.0).minimize_effort().bound_input("tau", -80.0, 80.0)
    ocp.final(joints={n: 0.3 for n in model.joint_space.joint_names[:7]}, v=0)
    start = time.perf_counter()
    try:
        sol, ok = ocp.solve(diagnose=False), True
    except nc.errors.OptimizationError as exc:
        sol, ok = exc.result, False
    total = time.perf_counter() - start
    st = sol.stats
    evals = sum(v for k, v in sol.nlp.opti.stats().items() if k.startswith("t_wall_nlp_"))
    return (f"PANDA setup (N = {N}, {st.n_variables} unknowns, {'converged' if ok else 'FAILED'}, {st.iterations} "
            f"iterations): model {t_model:.1f} s, NLP build {st.build_time:.1f} s, solve call {st.solve_time:.1f} s "
            f"(of which function evaluations {evals:.1f} s), total {total:.1f} s")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    ap.add_argument("--sizes", nargs="+", type=int, default=[30, 40, 80], help="numbers of intervals N")
    ap.add_argument("--max-iter", type=int, default=1000)
    ap.add_argument("--form", default="auto", choices=["auto", "joint", "ggl", "index3", "index1"],
                    help="ncgen's collocation form (auto: joint space for trees; ncgen.optim.joint_radau, .radau)")
    ap.add_argument("--coarse-start", action="store_true",
                    help="ncgen solves on N // 2 first (solve(coarse_start=True)); iterations and times summed")
    ap.add_argument("--quick", "--smoke", action="store_true", help="N = 8 only (seconds), no Panda line")
    ap.add_argument("--panda", type=int, default=20, help="N of the Panda setup-time line (0: skip it)")
    args = ap.parse_args(argv)
    sizes = [8] if args.quick else args.sizes
    print(machine())
    print(f"{'case':9} {'N':>3} | {'iterations':>17} {'ratio':>6} | {'time (s)':>17} {'ratio':>7} | "
          f"{'cost ncgen':>12} {'cost minimal':>12} {'at ncgen opt':>12} {'rel diff':>9} | ncgen NLP")
    rows = []
    for case in args.cases:
        make, minimal, angles = CASES[case]
        for N in sizes:
            a = solve_ncgen(make, angles, N, args.max_iter, args.form, args.coarse_start)
            b = solve_minimal(minimal(), N)
            c = solve_minimal(minimal(), N, guess=a["path"])     # the same local optimum as ncgen's
            rel = abs(a["cost"] - c["cost"]) / max(abs(c["cost"]), 1e-12)
            flag = "" if a["success"] and b["success"] else "  (failed: " + ", ".join(
                n for n, r in (("ncgen", a), ("minimal", b)) if not r["success"]) + ")"
            rows.append((case, N, a, b, rel))
            print(f"{case:9} {N:3d} | {a['iterations']:8d} {b['iterations']:8d} {a['iterations'] / max(b['iterations'], 1):6.2f} | "
                  f"{a['time']:8.3f} {b['time']:8.3f} {a['time'] / b['time']:7.2f} | "
                  f"{a['cost']:12.6g} {b['cost']:12.6g} {c['cost']:12.6g} {rel:9.1e} | {a['size']}{flag}", flush=True)
    it = max(r[2]["iterations"] / max(r[3]["iterations"], 1) for r in rows)
    tm = max(r[2]["time"] / r[3]["time"] for r in rows)
    cost = max(r[4] for r in rows)
    print(f"RATIO ncgen / minimal, iterations (worst case): {it:.2f}   (target ≤ 2)")
    print(f"RATIO ncgen / minimal, solve time (worst case): {tm:.2f}   (target ≤ 10)")
    print(f"relative cost difference at ncgen's optimum (worst case): {cost:.1e}   (target ≤ 1e-3)")
    print(f"converged: ncgen {sum(r[2]['success'] for r in rows)}/{len(rows)}, "
          f"minimal {sum(r[3]['success'] for r in rows)}/{len(rows)}")
    if args.panda and not args.quick:
        print(panda_setup(args.panda))
    return 0


if __name__ == "__main__":
    sys.exit(main())
