"""The MPC's horizon problem (:mod:`ncgen.control.mpc_problem`) posed stage-wise for Fatrop
(Vanroye et al., 2023: an interior-point method exploiting the optimal-control structure),
CasADi's ``nlpsol("fatrop")`` with ``structure_detection="auto"``, in one of two forms
(:data:`FORMS`, :func:`choose_form`): ``"joint"`` for a tree of hinges and slides
(:mod:`ncgen.control.mpc_fatrop_joint`: joint states, an explicit step; its whole solver
compiled, :mod:`ncgen.control.compiled_nlp`), or ``"natural"``, this module's, described here.

In the natural form stage ``k < N`` has the state ``x_k`` (nx) and the controls
``[u_k; z_k]`` (nu inputs, then the RATTLE step's unknowns ``z = [w; ν; v⁺; μ']`` of
:mod:`ncgen.control.discrete`), stage ``N`` the state only.  Decision variables in stage
order ``x_0, u_0, z_0, x_1, …, x_N``; constraints in stage order, all equalities:

* the gap ``x_{k+1} − [q_k + h w_k; v⁺_k] = 0`` (Fatrop's dynamics: explicit in the stage's
  state and controls),
* at stage 0 ``x_0 − x = 0`` (``x``: the measured state, a parameter with the time ``t``),
* the step residual ``G(z_k; x_k, u_k, p, t + k h) = 0`` (a path constraint of stage ``k``);

the bounds on inputs (``u_k``) and states (``x_k``, ``k ≥ 1``) are bounds on the variables.
Cost ``Σ ℓ(x_k, u_k) + ℓ_N(x_N)`` as the SQP's.  Exact Hessians (SX, expanded), no
condensing: Fatrop's Riccati recursion sees the stage structure.  The solution satisfies the
same discrete problem as the SQP's converged iterate, so both answer the same input.
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ncgen.control.discrete import _step_state, step_residual
from ncgen.errors import OptimizationError

#: Fatrop's options for an MPC solve: quiet, a small initial barrier parameter (the guess is
#: the previous solution shifted, near the optimum: on the cart-pole's swing-up 1e-6 took 25 %
#: fewer iterations than 1e-3, the same closed loop to 2e-9), its convergence tolerance.
FATROP_OPTIONS = {"print_level": 0, "mu_init": 1e-6, "tolerance": 1e-8}


#: The stage-wise forms: ``"joint"`` (:mod:`ncgen.control.mpc_fatrop_joint`: a tree's joint
#: space, the default where the model allows it) and ``"natural"`` (this module's: the
#: natural coordinates with the RATTLE step's unknowns as controls, the SQP's own problem).
FORMS = ("joint", "natural")


@dataclass
class FatropProblem:
    """The solver and the layout of its variables: ``solver(x0, p, lbx, ubx, lbg, ubg)``;
    ``form``: one of :data:`FORMS`; ``state[k]``, ``input[k]``, ``unknowns[k]``: index arrays
    of ``x_k``, ``u_k``, ``z_k`` (natural form only; empty otherwise) in the variable vector;
    ``lbx``, ``ubx``, ``lbg``, ``ubg``: the variables' and constraints' bounds; ``nlp``: the
    NLP (``{"x", "f", "g", "p"}``), for another solver of the same problem; ``options``: the
    solver's (``nlpsol``'s)."""

    solver: ca.Function
    form: str
    state: list
    input: list
    unknowns: list
    lbx: np.ndarray
    ubx: np.ndarray
    lbg: np.ndarray
    ubg: np.ndarray
    nlp: dict
    options: dict


def natural_nlp(model, problem) -> dict:
    """``{"nlp", "state", "input", "unknowns", "lbx", "ubx", "lbg", "ubg", "equality"}``: the
    stage-wise NLP of ``problem`` in natural coordinates (see the module docstring) and its
    layout, as :func:`ncgen.control.mpc_fatrop_joint.joint_nlp`'s."""
    h, N, p = problem.h, problem.N, ca.DM(problem.p)
    nq, nc, nu = model.nq, model.nc, model.nu
    nx, nz = 2 * nq, 2 * (nq + nc)
    G = step_residual(model, h)
    x_meas, t = ca.SX.sym("x", nx), ca.SX.sym("t")
    X = [ca.SX.sym(f"x_{k}", nx) for k in range(N + 1)]
    U = [ca.SX.sym(f"u_{k}", nu) for k in range(N)]
    Z = [ca.SX.sym(f"z_{k}", nz) for k in range(N)]
    w, g = [], []
    state, inputs, unknowns = [], [], []
    lo_u, hi_u = problem.u_bounds
    lo_x, hi_x = problem.x_bounds
    lbx, ubx = [], []
    J = problem.terminal(X[N], t + N * h)
    for k in range(N + 1):
        state.append(np.arange(len(lbx), len(lbx) + nx))
        w.append(X[k])
        lbx += [-np.inf] * nx if k == 0 else list(lo_x)
        ubx += [np.inf] * nx if k == 0 else list(hi_x)
        if k == N:
            break
        inputs.append(np.arange(len(lbx), len(lbx) + nu))
        unknowns.append(np.arange(len(lbx) + nu, len(lbx) + nu + nz))
        w += [U[k], Z[k]]
        lbx += list(lo_u) + [-np.inf] * nz
        ubx += list(hi_u) + [np.inf] * nz
        g.append(X[k + 1] - _step_state(X[k], Z[k], nq, nc, h))
        if k == 0:
            g.append(X[0] - x_meas)
        g.append(G(Z[k], X[k], U[k], p, t + k * h))
        J += problem.stage(X[k], U[k], t + k * h)
    g = ca.vertcat(*g)
    return {"nlp": {"x": ca.vertcat(*w), "f": J, "g": g, "p": ca.vertcat(x_meas, t)}, "state": state,
            "input": inputs, "unknowns": unknowns, "lbx": np.array(lbx, dtype=float),
            "ubx": np.array(ubx, dtype=float), "lbg": np.zeros(g.numel()), "ubg": np.zeros(g.numel()),
            "equality": [True] * g.numel()}


def fatrop_problem(model, problem, form: str = "natural", *, options: dict | None = None) -> FatropProblem:
    """The stage-wise NLP of ``problem`` (an :class:`~ncgen.control.mpc_problem.MPCProblem`)
    in ``form`` (:data:`FORMS`) and CasADi's Fatrop plugin on it (its functions in CasADi's
    virtual machine: the natural form's solver; the joint form solves with its generated C,
    :class:`FatropSolver`); ``options``: Fatrop's own, over :data:`FATROP_OPTIONS`."""
    opts = {"structure_detection": "auto", "print_time": False, "fatrop": {**FATROP_OPTIONS, **(options or {})}}
    if form == "joint":
        from ncgen.control.mpc_fatrop_joint import joint_nlp
        parts = joint_nlp(model, problem)
    else:
        parts = natural_nlp(model, problem)
    opts["equality"] = parts["equality"]
    solver = ca.nlpsol(f"mpc_fatrop_{form}", "fatrop", parts["nlp"], opts)
    return FatropProblem(solver, form, parts["state"], parts["input"], parts.get("unknowns", []), parts["lbx"],
                         parts["ubx"], parts["lbg"], parts["ubg"], parts["nlp"], opts)


def pack(fp: FatropProblem, X: np.ndarray, U: np.ndarray, Z: np.ndarray | None = None) -> np.ndarray:
    """The variable vector of states ``X`` ((N + 1) × nx), inputs ``U`` (N × nu) and, in the
    natural form, step unknowns ``Z`` (N × nz)."""
    out = np.empty(fp.lbx.size)
    out[np.concatenate(fp.state)] = X.ravel()
    out[np.concatenate(fp.input)] = U.ravel()
    if fp.unknowns:
        out[np.concatenate(fp.unknowns)] = Z.ravel()
    return out


def unpack(fp: FatropProblem, w: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """``(X, U, Z)`` of the variable vector ``w`` (the inverse of :func:`pack`; ``Z`` None in
    the joint form)."""
    return (w[np.array(fp.state)], w[np.array(fp.input)],
            w[np.array(fp.unknowns)] if fp.unknowns else None)


def unknowns_guess(model, h: float, X: np.ndarray) -> np.ndarray:
    """Step unknowns consistent with the state guess ``X``: ``w_k = (q_{k+1} − q_k)/h``,
    ``v⁺_k = v_{k+1}``, multipliers zero."""
    nq, nc = model.nq, model.nc
    w = (X[1:, :nq] - X[:-1, :nq]) / h
    zeros = np.zeros((X.shape[0] - 1, nc))
    return np.hstack([w, zeros, X[1:, nq:], zeros])


def choose_form(model, form) -> str:
    """The stage-wise form of ``model`` (:data:`FORMS`): ``form`` checked, or for ``None``
    ``"joint"`` where the model allows it (a tree of hinges and slides:
    :func:`~ncgen.control.mpc_fatrop_joint.joint_form_refusal`), else ``"natural"``."""
    from ncgen.control.mpc_fatrop_joint import joint_form_refusal
    if form is not None and (not isinstance(form, str) or form not in FORMS):
        raise OptimizationError(f"MPC: fatrop_form: expected one of {', '.join(FORMS)} or None (the joint form "
                                f"where the model allows it), got {form!r}")
    why = joint_form_refusal(model) if form != "natural" else None
    if form == "joint" and why is not None:
        raise OptimizationError(f"MPC: fatrop_form='joint': model {model.name!r}: {why}; use fatrop_form='natural'")
    return form or ("natural" if why else "joint")


class FatropSolver:
    """Fatrop on the stage-wise problem in ``form`` (:func:`choose_form`), one solve per call
    of :meth:`solve` from the guess given (the MPC's previous solution shifted: a primal warm
    start).  ``status`` and ``iteration_counts``: Fatrop's return status and interior-point
    iterations of each solve since :meth:`clear`.  ``compiled=False``: the joint form solves
    with CasADi's plugin too (its solver not compiled: the problem and its options checked
    for :func:`ncgen.control.export.export_mpc`, which writes the solver's C itself)."""

    def __init__(self, model, problem, options: dict | None = None, form: str | None = None, *,
                 compiled: bool = True):
        if options is not None and not (isinstance(options, dict) and all(isinstance(k, str) for k in options)):
            raise OptimizationError(f"MPC: fatrop_options: expected a dict of Fatrop's options by name, got {options!r}")
        self.model, self.problem = model, problem
        self.form = choose_form(model, form)
        try:
            self.nlp = fatrop_problem(model, problem, self.form, options=options)
        except RuntimeError as exc:
            raise OptimizationError(f"MPC: Fatrop refused the problem or fatrop_options {options!r}: {exc}") from None
        # the solver's arguments after x0 and p: the bounds, no initial multipliers (as CasADi matrices once)
        self._fixed = [ca.DM(b) for b in (self.nlp.lbx, self.nlp.ubx, self.nlp.lbg, self.nlp.ubg)] + [ca.DM()] * 2
        if self.form == "joint":
            from ncgen.control.mpc_fatrop_joint import joint_maps
            from ncgen.control.step_support import compile_functions
            self._joint_state, self._natural = compile_functions(f"{model.name}_fatrop_maps",
                                                                 joint_maps(model, problem.N)).values()
        self.status: list[str] = []
        self.iteration_counts: list[int] = []
        #: the joint form's whole solver as compiled C (:func:`~ncgen.control.compiled_nlp.compiled_fatrop`)
        self._compiled = None
        if options:                                # Fatrop reads its options at the first solve only
            self.check_options(options)
        if self.form == "joint" and compiled:
            from ncgen.control.compiled_nlp import compiled_fatrop
            self._compiled = compiled_fatrop(f"{model.name}_fatrop_solver", self.nlp.nlp, self.nlp.options)
            self._zeros = (np.zeros(self.nlp.lbx.size), np.zeros(self.nlp.lbg.size))

    def guess(self, X: np.ndarray) -> np.ndarray:
        """The solver's own part of the guess from the natural states ``X`` ((N + 1) × nx): the
        step unknowns (:func:`unknowns_guess`; natural form) or the joint states ((N + 1) × 2 n_j;
        joint form)."""
        if self.form == "natural":
            return unknowns_guess(self.model, self.problem.h, X)
        near = np.zeros(2 * self.model.joint_space.nv)
        first = self._joint_state(X[0], near)[0].copy()
        return np.array([first] + [self._joint_state(x, first)[0].copy() for x in X[1:]])

    def check_options(self, options: dict) -> None:
        """One solve from the problem's start held, so that an option Fatrop does not know, or
        a value of the wrong type, is refused now and by name."""
        x = self.problem.x_start
        X = np.tile(x, (self.problem.N + 1, 1))
        U = np.tile(np.clip(np.zeros(self.model.nu), *self.problem.u_bounds), (self.problem.N, 1))
        self.solve(x, self.model.t0, X, U, self.guess(X))
        status = self.status[-1]
        self.clear()
        if status.startswith("error"):
            raise OptimizationError(f"MPC: fatrop_options {options!r}: Fatrop refused them: "
                                    f"{status.splitlines()[-1]}")

    def clear(self) -> None:
        self.status.clear()
        self.iteration_counts.clear()

    def solve(self, x, t: float, X: np.ndarray, U: np.ndarray, Z: np.ndarray):
        """``(X, U, Z)``: Fatrop's solution from the guess ``(X, U, Z)`` at the measured state
        ``x`` and time ``t`` (``Z``: :meth:`guess`'s part; in the joint form the guess is
        ``(Z, U)`` and ``X`` the natural states of the solution's ``Z``), its inputs clipped
        into their bounds (Fatrop, as IPOPT, relaxes bounds by about 1e-8 relative: a saturated
        push came back as 20.00000016 N against 20 N); the guess itself when Fatrop fails or
        answers anything not finite (its status says so)."""
        nlp = self.nlp
        if nlp.form == "joint":
            w0, x = pack(nlp, Z, U), self._joint_state(x, Z[0])[0]
        else:
            w0 = pack(nlp, X, U, Z)
        if self._compiled is not None:
            code = self._compiled.status_call(w0, np.append(x, t), nlp.lbx, nlp.ubx, nlp.lbg, nlp.ubg, *self._zeros)
            success, count = code <= 0, -code if code <= 0 else -1
            status, w = ("0", self._compiled.outputs[0].copy()) if success else ("failed (the compiled solver)", None)
        else:
            status, success, count, w = self._plugin_solve(w0, x, t)
        self.iteration_counts.append(count)
        self.status.append(status if w is None or np.all(np.isfinite(w)) else f"{status}, not finite")
        if not success or not np.all(np.isfinite(w)):
            return X, U, Z
        Xs, U, Zs = unpack(nlp, w)
        if nlp.form == "joint":
            Xs, Zs = self._natural(Xs.ravel())[0].reshape(Xs.shape[0], -1).copy(), Xs
        return Xs, np.clip(U, *self.problem.u_bounds), Zs

    def _plugin_solve(self, w0: np.ndarray, x: np.ndarray, t: float):
        """``(status, success, iterations, w)`` of CasADi's Fatrop plugin from ``w0`` at the
        parameters ``(x, t)``; ``w`` None after an evaluation error inside Fatrop."""
        solver = self.nlp.solver
        try:
            r = solver.call([ca.DM(w0), ca.DM(np.append(x, t)), *self._fixed])
        except RuntimeError as exc:
            return f"error: {exc}", False, -1, None
        stats = solver.stats()
        return (str(stats.get("return_status")), bool(stats.get("success")), int(stats.get("iter_count", -1)),
                np.array(r[0].nonzeros()))
