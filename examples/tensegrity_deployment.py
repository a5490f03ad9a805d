"""Deployment of a two-stage tensegrity tower by its cables' rest lengths.  Run:
python examples/tensegrity_deployment.py

The tower (two 3-prisms on a floor ring of 0.3 m, struts 0.7654 m) is designed in two shapes
of the same struts: compact (rings of 0.35 m, top at 0.796 m) and deployed (rings of 0.3 m,
top at 1 m), each with its least prestress (cables ≥ 10 N).  Realised with every cable's rest
length an input (k = 2000 N/m, damping 10 N·s/m, 0.2 kg per node), both are stable equilibria
of one model.  The deployment is posed as optimal control (rest lengths the controls, within
2 cm of both designs; from the compact equilibrium at rest to the deployed one at rest in
1.5 s; every cable's pull at least 2 N, so no cable goes slack; warm-started by a simulated
cosine ramp of the rest lengths) and tracked in
simulation from a disturbed start, two ways: by cable-space feedback (each cable's rest length
set so that its tension is the plan's plus ``k_f (l − l*) + c_f (l̇ − l̇*)`` about the planned
length ``l*``) and by ``nc.MPC`` with the plan as its time-varying reference (a horizon of
5 steps of 10 ms — its RATTLE step is stable only for h ≤ 0.01 s here — the stage cost on
``x − x_ref`` and ``u − u_ref``, the deployed design's rest lengths after the plan, every
cable's pull at least 1 N along the horizon, its QPs solved by qpOASES; see docs/tensegrity.md).
The MPC's run is written to tensegrity_deployment.html (cables coloured by their tension).
"""
import time

import numpy as np

import ncgen as nc
from ncgen.analysis.tensegrity_model import rest_length_inputs
from ncgen.analysis.tensegrity_shapes import stacked_prisms, tower_of_radii

K, DAMPING, SUPPORTS = 2000.0, 10.0, [0, 1, 2]
PLAN_MIN_TENSION = 2.0      # N: the plan keeps every cable's pull at least this (OptimalControl.min_tension)
INPUT_WEIGHT = 1.0          # MPC: weight of (u − u_ref)² per m² (see mpc_tracking)
MIN_TENSION = 1.0           # MPC: every cable's pull >= 1 N along the horizon (N)
QP_SOLVER = "qpoases"       # MPC: the QP solver (ncgen.control.mpc_qp; qrqp fails on these QPs)
ITERATIONS = 6              # MPC: SQP iterations per call


def designs():
    """``(model, (uA, uB), (qA, qB))``: the actuated model, the inputs and equilibria of the
    compact and the deployed design."""
    regular, struts, _ = stacked_prisms(3, stages=2, radius=0.3, height=0.5)
    s = np.linalg.norm(regular[struts[0][1]] - regular[struts[0][0]])
    (A, struts, cables), B = tower_of_radii([0.3, 0.35, 0.35], s), tower_of_radii([0.3, 0.3, 0.3], s)[0]
    l0 = [nc.inverse_statics(X, struts, cables, supports=SUPPORTS, cable_min=10.0).rest_lengths(K)[:len(cables)]
          for X in (A, B)]
    model = nc.tensegrity_system(A, struts, cables, l0[0], K, supports=SUPPORTS, actuated=True, damping=DAMPING,
                                 node_mass=0.2).build()
    u = tuple(rest_length_inputs(model, x) for x in l0)
    return model, u, tuple(nc.equilibrium(model, u=ui).q for ui in u)


def plan_pulls(model, plan) -> np.ndarray:
    """The cables' pulls ``k (l − l₀) + c l̇`` (N) at both ends of each of the plan's intervals,
    with the interval's rest lengths (intervals × 2 × cables)."""
    f = model.springs.function
    n = len(plan.t) - 1
    return np.array([[np.asarray(f(plan.t[j], plan.q[j], plan.v[j], plan.u[k], model.p0)[2]).reshape(-1)
                      for j in (k, k + 1)] for k in range(n)])


def cable_feedback(model, plan, gain: float = 4 * K, damping: float = 20.0):
    """``u(t, q, v)``: rest lengths giving each cable the plan's tension plus
    ``gain (l − l*) + damping (l̇ − l̇*)`` (N/m, N·s/m) about the plan's length ``l*``: a
    virtual cable stiffer and more damped than the real one about the plan (``gain = k``,
    ``damping = 0`` would be the plan's rest lengths, open loop)."""
    f = model.springs.function
    eps = 1e-7

    def state(t, q, v, u):
        T, length, _ = (np.asarray(x).reshape(-1) for x in f(t, q, v, u, []))
        rate = (np.asarray(f(t, q + eps * v, v, u, [])[1]).reshape(-1) - length) / eps
        return T, length, rate

    def at(t):                                        # the plan interpolated linearly in time
        k = int(np.clip(np.searchsorted(plan.t, t, side="right") - 1, 0, len(plan.t) - 2))
        w = float(np.clip((t - plan.t[k]) / (plan.t[k + 1] - plan.t[k]), 0.0, 1.0))
        u = plan.u[min(k, len(plan.u) - 1)]
        return (1 - w) * plan.q[k] + w * plan.q[k + 1], (1 - w) * plan.v[k] + w * plan.v[k + 1], u

    def control(t, q, v):
        q_ref, v_ref, u_ref = at(t)
        T_ref, l_ref, rate_ref = state(t, q_ref, v_ref, u_ref)
        _, length, rate = state(t, q, v, u_ref)
        T = np.maximum(T_ref + gain * (length - l_ref) + damping * (rate - rate_ref), 0.0)
        return length - (T - DAMPING * rate) / K          # k (l − l₀) + c l̇ = T
    return control


def mpc_tracking(model, plan, u_final, bounds, *, N: int = 5, h: float = 0.01, state_weight=(1e3, 1.0),
                 input_weight: float = INPUT_WEIGHT, terminal_weight: float = 1e3, min_tension=MIN_TENSION,
                 qp_solver: str = QP_SOLVER, iterations: int = ITERATIONS):
    """``nc.MPC`` tracking ``plan`` (its states and inputs; after the plan the inputs
    ``u_final`` hold its final state): a horizon of ``N`` steps of ``h`` s, the rest lengths
    within ``bounds`` (lower, upper), stage weights ``Q`` (on q, on v) and ``r`` (on u − u_ref, per
    m²), ``W`` on the horizon's end, every cable's pull ``≥ min_tension`` (N) along the horizon
    (None: no such constraint), the QPs solved by ``qp_solver``, ``iterations`` SQP iterations a
    call (the step Jacobians' QR as loops: quick to compile)."""
    ocp = nc.OptimalControl(model, N=N, t_final=N * h)
    ocp.bound_input("l0", *bounds)
    reference = (plan.t, np.hstack([plan.q, plan.v]), np.vstack([plan.u[:len(plan.t) - 1], u_final]))
    Q = np.repeat(state_weight, model.nq)
    return nc.MPC(ocp, sx_qr_max_nnz=0, reference=reference, state_weight=Q, input_weight=input_weight,
                  terminal_weight=terminal_weight, min_tension=min_tension, qp_solver=qp_solver,
                  iterations=iterations)


def timed(mpc):
    """``(u(t, q, v), log)``: the MPC as a feedback, ``log`` collecting each call's wall and
    CPU time (s) and the infeasibility of its solution."""
    log = []

    def control(t, q, v):
        wall, cpu = time.perf_counter(), time.process_time()
        u = mpc(np.concatenate([q, v]), t)
        log.append((time.perf_counter() - wall, time.process_time() - cpu, mpc.infeasibility[-1]))
        return u
    return control, log


if __name__ == "__main__":
    model, (uA, uB), (qA, qB) = designs()
    z = model.coordinate_names.index("n6.r_i.z")
    print(f"compact top {qA[z]:.4f} m, deployed top {qB[z]:.4f} m; rest-length changes "
          f"{np.round(uB - uA, 4)} m")
    t_final = 1.5
    ramp = nc.simulate(model, t_final, 0.05, q0=qA, backend="vm",
                       u=lambda t: uA + 0.5 * (1 - np.cos(np.pi * min(t / (t_final - 0.3), 1.0))) * (uB - uA))
    print(f"the cosine ramp alone: top at {ramp.q[-1, z]:.4f} m, speed {np.abs(ramp.v[-1]).max():.3f} m/s at the end")
    ocp = nc.OptimalControl(model, N=20, t_final=t_final)
    bounds = (np.minimum(uA, uB) - 0.02, np.maximum(uA, uB) + 0.02)
    ocp.bound_input("l0", *bounds)
    ocp.initial(q=qA, v=0)
    ocp.final(q=qB, v=0)
    ocp.min_tension(PLAN_MIN_TENSION)
    start = time.perf_counter()
    plan = ocp.solve(warm_start=ramp)
    print(f"optimal control: {plan.stats.iterations} IPOPT iterations, {time.perf_counter() - start:.1f} s wall, "
          f"largest dynamics defect {plan.stats.max_defect:.1e}; smallest cable pull at the nodes "
          f"{plan_pulls(model, plan).min():.2f} N (floor {PLAN_MIN_TENSION:g} N)")
    grid = np.linspace(0.0, t_final, 10 * (len(plan.t) - 1) + 1)       # ten samples an interval, inputs held
    held_u = plan.u[np.minimum(np.searchsorted(plan.t, grid, side="right") - 1, len(plan.t) - 2)]
    opened = nc.simulate(model, t_final, grid[1], u=held_u, q0=qA, backend="vm")
    pulls = [np.asarray(model.springs.function(t, q, v, u, model.p0)[2]).min()
             for t, q, v, u in zip(opened.t, opened.q, opened.v, held_u)]
    print(f"its inputs replayed (IDAS, open loop): top at {opened.q[-1, z]:.4f} m, "
          f"|q - qB| {np.abs(opened.q[-1] - qB).max():.2e} m, smallest cable pull {min(pulls):.2f} N")
    v0 = np.zeros(model.nq)
    v0[z] = 0.3                                     # a push on a top node
    held = lambda t: plan.u[min(np.searchsorted(plan.t, t, side="right") - 1, len(plan.u) - 1)]  # noqa: E731
    runs = {"open loop": held, "tracked": cable_feedback(model, plan)}
    for name, u in runs.items():
        traj = nc.simulate(model, t_final + 0.5, 0.002, u=u, q0=qA, v0=v0, backend="vm", ic_tolerance=None)
        print(f"{name} from a disturbed start: top at {traj.q[-1, z]:.4f} m, "
              f"|q - qB| {np.abs(traj.q[-1] - qB).max():.2e} m, speed {np.abs(traj.v[-1]).max():.2e} m/s")
    start = time.perf_counter()
    mpc = mpc_tracking(model, plan, uB, bounds)
    print(f"MPC: N = {mpc.N}, h = {mpc.h} s, built in {time.perf_counter() - start:.0f} s")
    control, log = timed(mpc)
    traj = nc.simulate(model, t_final + 0.5, mpc.h, u=control, q0=qA, v0=v0, backend="vm", ic_tolerance=None)
    wall, cpu, gap = np.array(log).T
    phi = max(np.abs(np.asarray(model.functions["phi"](t, q, model.p0))).max() for t, q in zip(traj.t, traj.q))
    print(f"MPC: constraints within {phi:.1e} m along the run (strut lengths)")
    print(f"MPC from a disturbed start: top at {traj.q[-1, z]:.4f} m, |q - qB| {np.abs(traj.q[-1] - qB).max():.2e} m, "
          f"speed {np.abs(traj.v[-1]).max():.2e} m/s; inputs within their bounds; l1 gap of its last solution "
          f"{gap[-1]:.1e} (largest over the last 0.1 s {gap[-10:].max():.1e}); per step median {1e3 * np.median(wall):.1f} "
          f"ms wall, {1e3 * np.median(cpu):.1f} ms CPU (period {1e3 * mpc.h:.0f} ms)")
    traj.to_html("tensegrity_deployment.html", title="tensegrity tower deployed by MPC")
    print("wrote tensegrity_deployment.html (the MPC's run: cables coloured by tension, a tension panel)")
