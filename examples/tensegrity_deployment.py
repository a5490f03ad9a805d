"""Deployment of a two-stage tensegrity tower by its cables' rest lengths.  Run:
python examples/tensegrity_deployment.py

The tower (two 3-prisms on a floor ring of 0.3 m, struts 0.7654 m) is designed in two shapes
of the same struts: compact (rings of 0.35 m, top at 0.796 m) and deployed (rings of 0.3 m,
top at 1 m), each with its least prestress (cables ≥ 10 N).  Realised with every cable's rest
length an input (k = 2000 N/m, damping 10 N·s/m, 0.2 kg per node), both are stable equilibria
of one model.  The deployment is posed as optimal control (rest lengths the controls, within
2 cm of both designs; from the compact equilibrium at rest to the deployed one at rest in
1.5 s; warm-started by a simulated cosine ramp of the rest lengths) and tracked in
simulation from a disturbed start by cable-space feedback: each cable's rest length set so
that its tension is the plan's plus ``k_f (l − l*) + c_f (l̇ − l̇*)`` about the planned length
``l*`` (the prestressed structure is stiff in its cables' lengths; ``nc.MPC`` does not track
it: its step is stable only for h ≤ 0.01 s, so its horizon of a few steps is too short, see
docs/tensegrity.md).
"""
import time

import numpy as np

import ncgen as nc
from ncgen.analysis.tensegrity_model import rest_length_inputs
from ncgen.analysis.tensegrity_shapes import stacked_prisms, tower_of_radii

K, DAMPING, SUPPORTS = 2000.0, 10.0, [0, 1, 2]


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
    ocp.bound_input("l0", np.minimum(uA, uB) - 0.02, np.maximum(uA, uB) + 0.02)
    ocp.initial(q=qA, v=0)
    ocp.final(q=qB, v=0)
    start = time.perf_counter()
    plan = ocp.solve(warm_start=ramp)
    print(f"optimal control: {plan.stats.iterations} IPOPT iterations, {time.perf_counter() - start:.1f} s wall, "
          f"largest dynamics defect {plan.stats.max_defect:.1e}")
    opened = nc.simulate(model, t_final, plan.t[1], u=plan.u, q0=qA, backend="vm")
    print(f"its inputs replayed (IDAS, open loop): top at {opened.q[-1, z]:.4f} m, "
          f"|q - qB| {np.abs(opened.q[-1] - qB).max():.2e} m")
    v0 = np.zeros(model.nq)
    v0[z] = 0.3                                     # a push on a top node
    held = lambda t: plan.u[min(np.searchsorted(plan.t, t, side="right") - 1, len(plan.u) - 1)]  # noqa: E731
    runs = {"open loop": held, "tracked": cable_feedback(model, plan)}
    for name, u in runs.items():
        traj = nc.simulate(model, t_final + 0.5, 0.002, u=u, q0=qA, v0=v0, backend="vm", ic_tolerance=None)
        print(f"{name} from a disturbed start: top at {traj.q[-1, z]:.4f} m, "
              f"|q - qB| {np.abs(traj.q[-1] - qB).max():.2e} m, speed {np.abs(traj.v[-1]).max():.2e} m/s")
