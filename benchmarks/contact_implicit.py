"""Optimal control through contact: ncgen's contact-implicit transcription against the same
problem with its contact sequence fixed by hand, and against nosnoc (if installed: ``pip
install nosnoc``, a test-only dependency).

Case: examples/block_push.py with T = 0.6 s (the block slides throughout): a 2 kg block on
a floor with μ = 0.5 pushed 0.5 m from rest to rest, least ∫ push² dt, push piecewise
constant over N = 20 equal steps.

* ncgen: ``OptimalControl`` on the model built with ``contacts="nonsmooth"`` from the block
  at rest (the Scholtes homotopy, its penalty and the polish; every IPOPT call timed);
* fixed sequence: the same block with the floor's force and the sliding friction written as
  forces (``push − μ m g`` along x, the weight cancelled), ncgen's Radau collocation from rest;
* nosnoc: the block as a Filippov system ``v̇ = push/m − μ g sign(v)`` (Stewart's
  reformulation, FESD, 2 finite elements per stage, Radau IIA with 2 stages), its own
  homotopy to ``comp_tol = 1e-9``.

All three are exact for piecewise-constant accelerations, so their optimal costs agree with
the closed form of the discrete problem (``block_push.closed_form``).

"IPOPT" times: ncgen's ``solve_time`` is the wall time of its solver calls (IPOPT built in
three of them: the first solve, the warm-started ones, the polish); nosnoc's ``cpu_time_nlp``
is IPOPT's CPU time (``t_proc_total``) of its calls.  "call" is the whole solve with its process
CPU time (ncgen's includes building the NLP; nosnoc's NLP is built before, untimed).  On a
shared machine compare CPU times and iteration counts: the ratios to nosnoc are of CPU times.

Then examples/hopper_gait.py from standing (its fixed-sequence row:
``contact_implicit_pusher_box.py --scene hopper``), and nosnoc on the same hopper: nosnoc 0.2.0
(Python) has no impact model of its own (no CLS, no automatic time freezing), so the hopper is
written as a time-freezing Filippov system by hand (Nurkanović et al. 2021, arXiv:2111.06759):
state (y_body, y_foot, v_body, v_foot, t), a speed of time ``s`` as a second control; regions
foot above the floor, or below it and rising: ``s·(v, a(leg), 1)``; below it and sinking: an
auxiliary upward acceleration ``a_n/m_foot`` with the clock frozen (inelastic contact, as the
example's e = 0); the physical time of each stage end equal to the stage grid (tolerance 1e-9).
Its cost is ``∫ (1000 (|y_b − ref|² + |y_f − ref|²) + 1e-2 leg²) dt`` over physical time (a state
that runs with the clock), the continuous integral, where ncgen's is the trapezoidal sum at the nodes: the costs are of two
discretisations of one problem, not one NLP (compare with that in mind).  Run from the same
naive guess (standing still) and from ncgen's optimum, homotopy from σ₀ = 1 as the example.
Measured (AMD EPYC, 2 CPUs, load 15–20): from either guess nosnoc ends standing, at the
standing local optimum (16.039755, the least-squares closed form of
tests/test_optim_contact_implicit.py's ``_standing_cost`` to 9e-7), where ncgen hops at 8.18 from
standing; ncgen reaches the standing optimum from σ₀ = 0.3 (equal to nosnoc's to ~1e-6), so the
costs are compared there, and the hop has no nosnoc counterpart.

Run:  python benchmarks/contact_implicit.py [--smoke]   (one case; --smoke is the same run.  The
fixed-sequence collocation fails from rest with N = 6 or 10, Restoration_Failed: not investigated.)
"""
from __future__ import annotations

import argparse
import importlib.util
import time
from pathlib import Path

import casadi as ca
import numpy as np

import ncgen as nc
from common import machine

ROOT = Path(__file__).resolve().parent.parent


def _block_push():
    spec = importlib.util.spec_from_file_location("block_push", ROOT / "examples" / "block_push.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def contact_implicit(ex, T):
    model = ex.build()
    start, cpu = time.perf_counter(), time.process_time()
    sol = ex.problem(model, T).solve("rest")
    wall, cpu = time.perf_counter() - start, time.process_time() - cpu
    print("  homotopy (σ: IPOPT iterations):", ", ".join(f"{h['sigma']:g}: {h['iterations']}" if h["sigma"] != "polish"
                                                      else f"polish: {h['iterations']}" for h in sol.homotopy))
    calls = sum(h['cpu_time'] for h in sol.homotopy)
    print(f"  CPU time of the solver calls (IPOPT built in three of them): {calls:.2f} s")
    contact_implicit.solver_cpu = calls
    return T / ex.N * float(np.sum(sol.u[:ex.N, 0] ** 2)), sol.stats.solve_time, wall, cpu, sol.stats.iterations


def fixed_sequence(ex, T):
    s = nc.System("block_sliding", gravity=(0, -ex.G))
    block = s.add_point("block", mass=ex.MASS, position=(0, 0))
    block.add_marker("centre", (0, 0))
    push = s.add_input("push")
    s.add_force(nc.PointForce(block, (0, 0), force=ca.vertcat(push - ex.MU * ex.MASS * ex.G, ex.MASS * ex.G)))
    model = s.build()
    ocp = nc.OptimalControl(model, N=ex.N, t_final=T)
    ocp.final(marker=("block.centre", (ex.DISTANCE, 0.0)), v=0)
    ocp.minimize_effort()
    start, cpu = time.perf_counter(), time.process_time()
    sol = ocp.solve("rest")
    wall, cpu = time.perf_counter() - start, time.process_time() - cpu
    return sol.stats.objective, sol.stats.solve_time, wall, cpu, sol.stats.iterations


def nosnoc_push(ex, T):
    import nosnoc
    x, u = ca.SX.sym("x", 2), ca.SX.sym("u", 1)
    F = ca.horzcat(ca.vertcat(x[1], u / ex.MASS - ex.MU * ex.G), ca.vertcat(x[1], u / ex.MASS + ex.MU * ex.G))
    model = nosnoc.NosnocModel(x=x, F=[F], c=[x[1]], S=[np.array([[1], [-1]])], x0=np.zeros(2), u=u)
    ocp = nosnoc.NosnocOcp(f_q=u[0] ** 2, g_terminal=ca.vertcat(x[0] - ex.DISTANCE, x[1]))
    opts = nosnoc.NosnocOpts()
    opts.terminal_time, opts.N_stages, opts.N_finite_elements, opts.n_s = T, ex.N, 2, 2
    opts.print_level, opts.comp_tol, opts.initial_theta = 0, 1e-9, 0.5
    solver = nosnoc.NosnocSolver(opts, model, ocp)
    start, cpu = time.perf_counter(), time.process_time()
    res = solver.solve()
    wall, cpu = time.perf_counter() - start, time.process_time() - cpu
    return float(res["cost_val"]), float(np.sum(res["cpu_time_nlp"])), wall, cpu, int(np.sum(res["nlp_iter"]))  # CPU


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--smoke", action="store_true", help="the same single case (it takes seconds)")
    parser.parse_args()
    print(machine())
    ex = _block_push()
    T = 0.6
    reference = ex.closed_form(T)[1]
    print(f"=== block push, T = {T} s, N = {ex.N}: closed form of the discrete problem {reference:.9f} N²·s")
    rows = [("ncgen contact-implicit", contact_implicit), ("ncgen, contact sequence fixed", fixed_sequence)]
    if importlib.util.find_spec("nosnoc") is not None:
        rows.append(("nosnoc (FESD, Stewart)", nosnoc_push))
    else:
        print("nosnoc is not installed (pip install nosnoc): its row is skipped")
    out = {}
    for name, run in rows:
        cost, solve, wall, cpu, iterations = run(ex, T)
        out[name] = (cost, solve, wall, cpu)
        print(f"{name:32s} cost {cost:.9f} (Δ {cost - reference:+.2e}), IPOPT {solve:.2f} s, "
              f"call {wall:.2f} s (CPU {cpu:.2f} s), {iterations} iterations")
    ci = out["ncgen contact-implicit"]
    fx = out['ncgen, contact sequence fixed']
    print(f"RATIO contact-implicit / fixed sequence: IPOPT wall time {ci[1] / fx[1]:.1f}; CPU of the calls {ci[3] / fx[3]:.1f}")
    if "nosnoc (FESD, Stewart)" in out:
        ns = out["nosnoc (FESD, Stewart)"]
        print(f"RATIO ncgen / nosnoc, CPU time of the solver calls (ncgen's homotopy and polish, nosnoc's "
              f"IPOPT calls) {contact_implicit.solver_cpu / ns[1]:.2f}; of the calls {ci[3] / ns[3]:.2f}; "
              f"cost difference {ci[0] - ns[0]:+.2e}")
    hopper()


#: the hopper's homotopy start that keeps it standing (the standing local optimum, nosnoc's from
#: standing); from 0.1 ncgen ends at a worse standing point (16.15, the foot at the floor with no
#: force over some steps)
STANDING_SIGMA0 = 0.3


def hopper():
    """examples/hopper_gait.py from the standing guess: time, iterations, and the phases found."""
    spec = importlib.util.spec_from_file_location("hopper_gait", ROOT / "examples" / "hopper_gait.py")
    hg = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(hg)
    model = hg.build()
    start, cpu = time.perf_counter(), time.process_time()
    sol = hg.problem(model).solve("rest")
    wall, cpu = time.perf_counter() - start, time.process_time() - cpu
    stance, flight = hg.phases(sol)
    print(f"=== hopper (examples/hopper_gait.py, N = {hg.N}) from standing: cost {sol.stats.objective:.6f}, "
          f"IPOPT {sol.stats.solve_time:.2f} s, call {wall:.2f} s (CPU {cpu:.2f} s), {sol.stats.iterations} iterations "
          f"({', '.join(str(h['iterations']) for h in sol.homotopy)}); flight in {int(flight.sum())} of {hg.N} "
          f"intervals; complementarity residual {sol.complementarity_residual:.1e}")
    if importlib.util.find_spec("nosnoc") is None:
        print("nosnoc is not installed: its hopper row is skipped")
        return
    # the standing local optimum, where both solvers end from standing (module docstring)
    standing = hg.problem(model, contacts={"sigma0": STANDING_SIGMA0}).solve("rest")
    print(f"ncgen from standing, σ₀ = {STANDING_SIGMA0}: cost {standing.stats.objective:.9f}, highest foot "
          f"{standing.marker('foot.centre')[:, 1].max() - hg.RADIUS:.1e} m, {standing.stats.iterations} iterations, "
          f"CPU of the solver calls {sum(h['cpu_time'] for h in standing.homotopy):.2f} s")
    rows = {}
    for origin, guess in (("standing", None), ("ncgen's hop", sol)):
        cost, solver_cpu, call_cpu, iterations, lift = rows[origin] = nosnoc_hopper(hg, guess)
        print(f"nosnoc hopper (time freezing, FESD, Stewart) from {origin}: cost {cost:.9f}, IPOPT CPU {solver_cpu:.2f} s, "
              f"call CPU {call_cpu:.2f} s, {iterations} iterations; highest foot {lift:.1e} m above the floor "
              f"({'hops' if lift > 1e-3 else 'stays standing'})")
    for name, ours in (("hop", sol), ("standing", standing)):
        theirs = rows["standing"]
        print(f"RATIO ncgen {name} / nosnoc from standing, CPU time of the solver calls "
              f"{sum(h['cpu_time'] for h in ours.homotopy) / theirs[1]:.2f}; cost ncgen − nosnoc "
              f"{ours.stats.objective - theirs[0]:+.2e}")


def nosnoc_hopper(hg, guess=None, a_n=100.0):
    """``(cost, IPOPT CPU, call CPU, iterations, highest foot gap)`` of the hopper in nosnoc
    (time-freezing reformulation; module docstring) from standing, or from ``guess``: ncgen's
    solution (its states at the stage ends and its leg forces, the clock running at speed 1)."""
    import nosnoc
    yb, yf, vb, vf, t, cost = (ca.SX.sym(n) for n in ("y_body", "y_foot", "v_body", "v_foot", "t", "cost"))
    leg, speed = ca.SX.sym("leg"), ca.SX.sym("speed_of_time")
    lift = hg.LIFT * ca.sin(np.pi * t / hg.T) ** 2
    x0 = np.array([hg.RADIUS + hg.LEG, hg.RADIUS, 0, 0, 0, 0])
    weight = 1000.0                                    # hopper_gait.problem's default tracking weight
    running = weight * ((yb - x0[0] - lift) ** 2 + (yf - x0[1] - lift) ** 2) + hg.EFFORT * leg ** 2
    # the cost as a state that runs with the clock (frozen with it): ∫ running dt in physical time
    ode = speed * ca.vertcat(vb, vf, leg / hg.BODY - hg.G, -leg / hg.FOOT - hg.G, 1, running)
    frozen = ca.vertcat(0, 0, 0, a_n / hg.FOOT, 0, 0)
    model = nosnoc.NosnocModel(x=ca.vertcat(yb, yf, vb, vf, t, cost), F=[ca.horzcat(ode, ode, frozen)],
                               S=[np.array([[1, 0], [-1, 1], [-1, -1]])], c=[ca.vertcat(yf - hg.RADIUS, vf)],
                               x0=x0, u=ca.vertcat(leg, speed), t_var=t)
    ocp = nosnoc.NosnocOcp(lbu=np.array([-hg.FORCE, 0.5]), ubu=np.array([hg.FORCE, 20.0]), u_guess=np.array([0.0, 1.0]),
                           f_terminal=cost, g_terminal=ca.vertcat(yb - x0[0], yf - x0[1], vb, vf))
    opts = nosnoc.NosnocOpts()
    opts.terminal_time, opts.N_stages, opts.N_finite_elements, opts.n_s = hg.T, hg.N, 2, 2
    opts.time_freezing, opts.equidistant_control_grid, opts.time_freezing_tolerance = True, True, 1e-9
    opts.print_level, opts.comp_tol, opts.sigma_0, opts.max_iter_homotopy = 0, 1e-9, hg.CONTACTS["sigma0"], 12
    opts.mpcc_mode = nosnoc.MpccMode.SCHOLTES_INEQ
    if guess is not None:
        opts.initialization_strategy = nosnoc.InitializationStrategy.EXTERNAL
    solver = nosnoc.NosnocSolver(opts, model, ocp)
    if guess is not None:
        y, v = guess.q[:, [1, 3]], guess.v[:, [1, 3]]       # the points' heights and vertical speeds
        clock = np.linspace(0.0, hg.T, hg.N + 1)
        solver.set("x", np.column_stack([y[1:], v[1:], clock[1:], np.zeros(hg.N)]))
        solver.set("u", np.column_stack([guess.u[:hg.N, 0], np.ones(hg.N)]))
    cpu = time.process_time()
    res = solver.solve()
    cpu = time.process_time() - cpu
    if res["status"] != nosnoc.Status.SUCCESS:
        raise RuntimeError(f"nosnoc hopper: {res['status']}")
    done = [i for i, c in enumerate(res["cpu_time_nlp"]) if c is not None]  # the homotopy's unused slots are None
    foot = np.array(res["x_traj"])[:, 1] - hg.RADIUS
    return (float(res["cost_val"]), float(sum(res["cpu_time_nlp"][i] for i in done)), cpu,
            int(sum(res["nlp_iter"][i] for i in done)), float(foot.max()))


if __name__ == "__main__":
    main()
