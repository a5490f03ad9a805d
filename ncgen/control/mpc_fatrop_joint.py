"""The MPC's horizon problem posed for Fatrop in joint space (``form="joint"`` of
:mod:`ncgen.control.mpc_fatrop`), for a tree of hinges and slides.

The state is ``x = [q_j; v_j]`` (joint positions and rates, ``model.joint_space`` order; rad or
m, rad/s or m/s), the control the OCP's input ``u``; the natural coordinates are functions of
them, ``[q; v] = T(x)`` (the tree map, :meth:`~ncgen.assembly.joint_space.JointSpace.tree_function`),
so the model's constraints hold identically.  One step of length ``h`` is the explicit
midpoint rule (second order, as the SQP's RATTLE step) on the tree's joint-space ODE
``ẋ = φ(t, x, u) = [v_j; a(t, q_j, v_j, u, p)]`` (:func:`ncgen.runtime.joint_simulation.dynamics_function`:
the projected equations ``Jᵀ M J a = Jᵀ (F − M J̇ v_j)``, recursive in 3D)::

    x_{k+1} = f(x_k, u_k, t_k) = x_k + h φ(t_k + h/2, x_k + h/2 φ(t_k, x_k, u_k), u_k)

Measured on the cart-pole (``h`` = 0.05 s, closed loops on the natural-coordinate plant):
semi-implicit Euler (the scheme of :class:`~ncgen.control.joint_step.JointStep`) predicts so
poorly that the loop from the documented start did not swing the pole up (cost 2.7 times the
SQP's); the midpoint rule's closed-loop costs are 0.2 % (tilt and push) and 0.8 % (swing-up)
below the SQP's, RK4's 0.2 % and 0.2 % at twice the Hessian's size (82 k instructions against 36 k).

Stage ``k < N`` has the state ``x_k`` and the controls ``u_k``, stage ``N`` the state only;
the constraints in stage order: the gap ``x_{k+1} − f(x_k, u_k, t_k) = 0``, at stage 0
``x_0 − x_j = 0`` (the measured state in joint space, a parameter with ``t``), at stages
``k ≥ 1`` the OCP's state bounds on ``T(x_k)`` (inequalities; only the finite ones).  Cost
``Σ ℓ(T(x_k), u_k, t_k) + ℓ_N(T(x_N), t_N)``: the SQP's stage and terminal costs
(:mod:`ncgen.control.mpc_problem`) on the natural coordinates.  This is not the SQP's
discrete problem (its step is RATTLE in natural coordinates): the two agree to the steps'
discretisation error.  On the cart-pole a stage has 4 states and 1 control, against 16
states and 29 controls (the step's unknowns) in the natural form.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ncgen.errors import ModelError, OptimizationError


def joint_form_refusal(model) -> str | None:
    """Why ``model`` has no joint form (None if it has): it must be a tree of joints whose
    coordinates add (no quaternion), whose constraints are all the joints' and with as many
    joint rates as degrees of freedom (:func:`ncgen.optim.joint_radau.joint_space_reason`)."""
    from ncgen.optim.joint_radau import joint_space_reason
    return joint_space_reason(model)


def joint_step_function(model, h: float) -> ca.Function:
    """``joint_step: (x, u, p, t) -> x⁺``: one explicit midpoint step of length ``h`` (SX;
    module docstring)."""
    from ncgen.runtime.joint_simulation import dynamics_function
    js = model.joint_space
    n = js.nv
    try:
        accelerations = dynamics_function(model)
    except ModelError as exc:
        raise OptimizationError(f"MPC: fatrop_form='joint': model {model.name!r}: {exc}") from None
    x, u = ca.SX.sym("x", 2 * n), ca.SX.sym("u", model.nu)
    p, t = ca.SX.sym("p", model.np), ca.SX.sym("t")

    def rate(tk, y):
        return ca.vertcat(y[n:], accelerations(tk, y[:n], y[n:], u, p)[0])

    x1 = x + h * rate(t + h / 2, x + h / 2 * rate(t, x))
    return ca.Function("joint_step", [x, u, p, t], [x1], ["x", "u", "p", "t"], ["x1"])


def natural_state_function(model) -> ca.Function:
    """``T: x = [q_j; v_j] -> [q; v]`` (SX): the natural coordinates and rates of a joint state."""
    n = model.joint_space.nv
    tree = model.joint_space.tree_function(model.layout)
    x = ca.SX.sym("x", 2 * n)
    return ca.Function("natural_state", [x], [ca.vertcat(*tree(x[:n], x[n:]))], ["x"], ["xn"])


def joint_nlp(model, problem) -> dict:
    """``{"nlp", "state", "input", "lbx", "ubx", "lbg", "ubg", "equality"}``: the stage-wise
    NLP of ``problem`` in joint space (module docstring; ``model`` a tree,
    :func:`joint_form_refusal`) and its layout (index arrays of each
    ``x_k``, ``u_k`` in the variable vector; bounds; which constraints are equalities)."""
    h, N, p = problem.h, problem.N, ca.DM(problem.p)
    nx, nu = 2 * model.joint_space.nv, model.nu
    f, T = joint_step_function(model, h), natural_state_function(model)
    lo_x, hi_x = problem.x_bounds
    bounded = np.flatnonzero(np.isfinite(lo_x) | np.isfinite(hi_x))
    x_meas, t = ca.SX.sym("x", nx), ca.SX.sym("t")
    X = [ca.SX.sym(f"x_{k}", nx) for k in range(N + 1)]
    U = [ca.SX.sym(f"u_{k}", nu) for k in range(N)]
    w, g, lbg, ubg, state, inputs = [], [], [], [], [], []
    size = 0

    def add(rows, lo, hi):
        g.append(rows)
        lbg.extend(lo)
        ubg.extend(hi)

    J = problem.terminal(T(X[N]), t + N * h)
    for k in range(N + 1):
        state.append(np.arange(size, size + nx))
        w.append(X[k])
        size += nx
        if k < N:
            inputs.append(np.arange(size, size + nu))
            w.append(U[k])
            size += nu
            add(X[k + 1] - f(X[k], U[k], p, t + k * h), [0.0] * nx, [0.0] * nx)
            J += problem.stage(T(X[k]), U[k], t + k * h)
        if k == 0:
            add(X[0] - x_meas, [0.0] * nx, [0.0] * nx)
        elif bounded.size:
            add(T(X[k])[bounded.tolist()], lo_x[bounded], hi_x[bounded])
    lbg, ubg = np.array(lbg, dtype=float), np.array(ubg, dtype=float)
    lo_u, hi_u = problem.u_bounds
    lbx, ubx = np.full(size, -np.inf), np.full(size, np.inf)
    for idx in inputs:
        lbx[idx], ubx[idx] = lo_u, hi_u
    return {"nlp": {"x": ca.vertcat(*w), "f": J, "g": ca.vertcat(*g), "p": ca.vertcat(x_meas, t)},
            "state": state, "input": inputs, "lbx": lbx, "ubx": ubx, "lbg": lbg, "ubg": ubg,
            "equality": [bool(e) for e in lbg == ubg]}


def joint_maps(model, N: int) -> list[ca.Function]:
    """``joint_state: (x, near) -> x_j``: ``[q_j; v_j]`` of the natural state ``x = [q; v]``,
    each angle turned by whole turns to lie within π of the same angle in ``near`` (a joint
    state: the guess's first node, so that a pole that swung over keeps its winding); and
    ``natural_states: X_j -> X``: :func:`natural_state_function` at the ``N + 1`` nodes
    (columns)."""
    js, nq, n = model.joint_space, model.nq, model.joint_space.nv
    x, near = ca.SX.sym("x", 2 * nq), ca.SX.sym("near", 2 * n)
    qj = js.positions(x[:nq])
    turns = ca.DM(js.angles.astype(float)) * ca.floor((near[:n] - qj) / (2 * np.pi) + 0.5)
    xj = ca.vertcat(qj + 2 * np.pi * turns, js.rates(x[:nq], x[nq:]))
    return [ca.Function("joint_state", [x, near], [xj], ["x", "near"], ["xj"]),
            natural_state_function(model).map("natural_states", "serial", N + 1, [], [])]
