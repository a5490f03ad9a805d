"""``nc.MPC(ocp)``: a receding-horizon controller for an ``OptimalControl`` problem, in
generated C.

Each control step runs a fixed number of sequential-quadratic-programming iterations
(``iterations=1``: the real-time iteration of Diehl et al., 2005) on the problem of
:mod:`ncgen.control.mpc_problem`, from the previous step's solution shifted by one interval
(warm start).  One iteration, with the guess ``(X̄, Ū)`` (states at the ``N + 1`` nodes,
inputs on the ``N`` intervals; multiple shooting):

1. the step and its exact Jacobians at every node, ``x̄⁺_k, A_k, B_k``
   (:mod:`ncgen.control.discrete`, implicit function theorem);
2. the QP in ``(δX, δU)``: minimise ``½ δᵀ H δ + gᵀ δ`` (``g``, ``H``: gradient and Hessian of
   the cost at the guess — a Gauss–Newton Hessian: the dynamics' curvature is left out),
   subject to ``δx_0 = x − x̄_0``, ``δx_{k+1} = A_k δx_k + B_k δu_k + x̄⁺_k − x̄_{k+1}``, the
   OCP's bounds moved by the guess (and, with ``min_tension``, the cables' pull linearised,
   :func:`cable_pull_blocks`) — condensed onto the inputs (``vec δX = S δU + s``,
   ``ncgen_condense.h``: ``N·nu`` variables, the bounded state components as general rows) and
   solved by CasADi's active-set ``qrqp``;
3. a backtracking line search with a filter on (cost ``J``, infeasibility ``c``: the ℓ1 norm
   of the shooting gaps and of the state-bound violations, :func:`merit_function`) along
   ``X̄ + α (X⁺ − X̄)``, ``clip(Ū + α δU)`` into the input bounds (``X⁺``: the QP's full step),
   ``α`` = 1, ½, … (:data:`ALPHAS`), accepted by :func:`acceptable`.  A trial whose steps do
   not converge, or that has NaN or inf anywhere, is rejected; a QP answer that is not finite,
   or no acceptable ``α``, keeps the guess (``mpc.step_lengths``: 0).  So every input
   returned is inside its bounds (and checked), and nothing NaN or diverging is ever answered
   or kept as the next guess; a guess along which the steps do not converge is an error.

An iteration is four generated functions (:func:`mpc_functions`): the QP's blocks (with the
guess's cost and infeasibility, from the same steps), ``qrqp``, the full step and the merit
of a trial.  The blocks call one interval's kernel (:func:`stage_function`) at every
interval through a serial ``map``, so their C is one interval's, whatever the horizon.  The
controller's C (:func:`ncgen.control.export.export_mpc`'s, compiled into the MPC's own package
too, :mod:`ncgen.control.mpc_c_loop`) condenses them in plain C
(``templates/c/runtime/ncgen_condense.h``: the one implementation of the condensing), and
``mpc(x, t)`` takes its QP data from that C in every loop and with every option (a reference,
``min_tension``, an in-process QP solver), so Python and C compute the same numbers.  The other
functions are called through :class:`ncgen.codegen.direct.DirectFunction`.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ncgen.blas_threads import one_blas_thread
from ncgen.control.discrete import step_jacobian_function
from ncgen.control.mpc_problem import mpc_problem, qp_rows
from ncgen.control.mpc_qp import GENERATED, InProcessQP, check_qp_solver, qp_function
from ncgen.errors import NcgenError, OptimizationError
from ncgen.validation import as_scalar

#: ``"sqp"``: this module's SQP (generated C); ``"fatrop"``: CasADi's Fatrop on the stage-wise
#: problem (:mod:`ncgen.control.mpc_fatrop`).
SOLVERS = ("sqp", "fatrop")
#: Added to the diagonal of the QP Hessian (keeps it positive definite on the inputs).
REGULARIZATION = 1e-8
#: Step lengths tried by the line search, longest first; its Armijo fraction, the filter's
#: margin γ and the infeasibility (m, m/s: ℓ1 over the horizon) below which an iterate counts
#: as feasible.
ALPHAS = tuple(0.5 ** i for i in range(11))
ARMIJO, GAMMA, C_MIN = 1e-4, 1e-5, 1e-10
#: A converged QP predicting a decrease of at most this fraction of the cost at a nearly
#: feasible guess: the guess is optimal to round-off and kept without trials (:func:`stationary`).
STATIONARY = 1e-12


def mpc_functions(model, problem, *, regularization: float = REGULARIZATION,
                  qp_max_iter: int = 100, sx_qr_max_nnz: int | None = None,
                  qp_solver: str = "qrqp") -> list[ca.Function]:
    """The CasADi functions of one SQP iteration (see the module docstring):

    * ``mpc_qp_blocks: (x, t, X̄, Ū) -> (A, B, d, Q, M, R, g_x, g_u, J, c, res[, P, P_a, P_b, P_u])``:
      the QP before condensing, the intervals' blocks side by side (dense; ``d``: ``x − x̄_0`` and
      the shooting gaps ``x̄⁺_k − x̄_{k+1}``, ``Q``, ``g_x`` with the terminal node's last), the
      guess's merit (:func:`merit_function`'s outputs, from the steps the blocks are built on) and,
      with ``min_tension``, the cables' pulls and their Jacobians (:func:`cable_pull_blocks`).  The
      controller's C condenses them (``templates/c/runtime/ncgen_condense.h``) into the QP in
      ``δU``: ``H, g``, the rows ``lba ≤ A δU ≤ uba`` (the bounded state components at nodes
      ``1..N``, then the cables' rows), ``lbx ≤ δU ≤ ubx`` and ``vec δX = S δU + (Xs − vec X̄)``;
    * ``mpc_qp``: CasADi's ``qrqp`` on it (returns its last iterate also when it reports a
      failure: the caller checks it), or the ``qp_solver`` of :mod:`ncgen.control.mpc_qp`;
    * ``mpc_update: (Xs, S, Ū, δU) -> (X⁺, U⁺)``: the full step;
    * ``mpc_merit`` (:func:`merit_function`): cost and infeasibility of a trial.

    ``sx_qr_max_nnz``: the step Jacobians' QR is unrolled into straight-line C up to this size
    (:func:`ncgen.control.discrete.qr_solve_columns`), else generated as loops.
    """
    h, N = problem.h, problem.N
    nx, nu = 2 * model.nq, model.nu
    qp = qp_function(qp_solver, nu * N, qp_rows(problem, nx), qp_max_iter)
    x, t = ca.MX.sym("x", nx), ca.MX.sym("t")
    X, U = ca.MX.sym("X", nx, N + 1), ca.MX.sym("U", nu, N)
    times = t + h * ca.DM(np.arange(N)).T
    stages = stage_function(model, problem, regularization, sx_qr_max_nnz).map("mpc_stages", "serial", int(N), [], [])
    x1, A, B, res, Q, M, R, g_x, g_u = stages(X[:, :N], U, times)
    Q_N, g_N = terminal_function(problem, nx, regularization)(X[:, N], t + N * h)
    merit = (total_cost_function(problem, nx, nu)(X, U, t), infeasibility(problem, x, X, U, x1, times), ca.mmax(res))
    outputs = [A, B, ca.horzcat(x - X[:, 0], x1 - X[:, 1:]), ca.horzcat(Q, Q_N), M, R, ca.horzcat(g_x, g_N), g_u,
               *merit]
    names = ["A", "B", "d", "Q", "M", "R", "g_x", "g_u", "J", "c", "res"]
    if problem.min_tension is not None:
        pulls = cable_pull_blocks(problem).map("mpc_cable_blocks", "serial", int(N), [], [])
        outputs += pulls(X[:, :N], X[:, 1:], U, times)
        names += ["P", "P_a", "P_b", "P_u"]
    blocks = ca.Function("mpc_qp_blocks", [x, t, X, U], [ca.densify(e) for e in outputs],
                         ["x", "t", "X_guess", "U_guess"], names)
    return [blocks, qp, update_function(nx, nu, N), merit_function(model, problem)]


def update_function(nx: int, nu: int, N: int) -> ca.Function:
    """``mpc_update: (Xs, S, Ū, δU) -> (X⁺, U⁺)``: the full step, ``vec X⁺ = Xs + S δU =
    Xs + Σ_k S_k δu_k`` (``S_k``: the columns of interval ``k``'s inputs, one call of the SX kernel
    ``mpc_stage_input`` each, through a serial ``map`` summing them) and ``U⁺ = Ū + δU``."""
    nX = nx * (N + 1)
    S_k, du = ca.SX.sym("S", nX, nu), ca.SX.sym("du", nu)
    column = ca.Function("mpc_stage_input", [S_k, du], [ca.mtimes(S_k, du)], ["S", "du"], ["dX"])
    Xs, S, U, dU = ca.MX.sym("Xs", nX), ca.MX.sym("S", nX, nu * N), ca.MX.sym("U", nu, N), ca.MX.sym("dU", nu * N)
    dX = column.map("mpc_stage_inputs", "serial", int(N), [], [0])(S, ca.reshape(dU, nu, N))
    return ca.Function("mpc_update", [Xs, S, U, dU],
                       [ca.densify(ca.reshape(Xs + dX, nx, N + 1)), ca.densify(U + ca.reshape(dU, nu, N))],
                       ["Xs", "S", "U_guess", "dU"], ["X_sol", "U_sol"])


def stage_function(model, problem, regularization: float, sx_qr_max_nnz: int | None) -> ca.Function:
    """``mpc_stage: (x, u, t) -> (x1, A, B, res, Q, M, R, g_x, g_u)``: one interval of the QP
    data, the step from node ``x`` with ``u`` at ``t`` and its Jacobians
    (:func:`~ncgen.control.discrete.step_jacobian_function`, the parameters closed over), and
    the stage cost's Gauss–Newton Hessian blocks ``[Q M; Mᵀ R]`` (``regularization`` on the
    diagonal) and gradient ``(g_x, g_u)`` in ``(x, u)``.  Expanded to SX where the step allows
    it; called by :func:`mpc_functions` at every interval through a serial ``map``, so the
    generated C holds one interval, not the horizon (a C function of its own,
    :data:`ncgen.codegen.kernels.CALLED_PREFIXES`)."""
    from ncgen.codegen.kernels import c_function
    nx, nu = 2 * model.nq, model.nu
    jac = step_jacobian_function(model, problem.h, sx_qr_max_nnz=sx_qr_max_nnz)
    x, u, t = ca.MX.sym("x", nx), ca.MX.sym("u", nu), ca.MX.sym("t")
    x1, A, B, _, res = jac(x, u, ca.DM(problem.p), t)
    xs, us, ts = ca.SX.sym("x", nx), ca.SX.sym("u", nu), ca.SX.sym("t")
    H, g = ca.hessian(problem.stage(xs, us, ts), ca.vertcat(xs, us))
    H = H + regularization * ca.SX.eye(nx + nu)
    cost = ca.Function("stage_cost_blocks", [xs, us, ts], [H[:nx, :nx], H[:nx, nx:], H[nx:, nx:], g[:nx], g[nx:]])
    f = ca.Function("mpc_stage", [x, u, t], [x1, A, B, res, *cost(x, u, t)],
                    ["x", "u", "t"], ["x1", "A", "B", "res", "Q", "M", "R", "g_x", "g_u"])
    return c_function(f, "mpc_stage")


def terminal_function(problem, nx: int, regularization: float) -> ca.Function:
    """``mpc_stage_terminal: (x, t) -> (Q, g)``: the terminal cost's Hessian
    (``regularization`` on the diagonal) and gradient at the last node ``x`` at its time ``t`` (SX)."""
    xs, ts = ca.SX.sym("x", nx), ca.SX.sym("t")
    H, g = ca.hessian(problem.terminal(xs, ts), xs)
    return ca.Function("mpc_stage_terminal", [xs, ts], [H + regularization * ca.SX.eye(nx), g], ["x", "t"], ["Q", "g"])


def cable_pull_blocks(problem) -> ca.Function:
    """``mpc_cable_block: (x_k, x_{k+1}, u_k, t_k) -> (P, P_a, P_b, P_u)``: the cables' pulls at
    interval ``k``'s two ends (:mod:`ncgen.control.mpc_problem`) and their Jacobians in ``x_k``,
    ``x_{k+1}``, ``u_k`` (SX).  The controller's C linearises the path constraint with them
    (``ncgen_condense_taut``): ``P_a δx_k + P_b δx_{k+1} + P_u δu_k ≥ T_min − P`` with
    ``δx_j = S_j δU + s_j``."""
    pull = problem.cable_pull
    nx, nu = pull.numel_in(0), pull.numel_in(2)
    xa, xb, us, ts = ca.SX.sym("x", nx), ca.SX.sym("x_next", nx), ca.SX.sym("u", nu), ca.SX.sym("t")
    P = pull(xa, xb, us, ts)
    return ca.Function("mpc_cable_block", [xa, xb, us, ts],
                       [P, ca.jacobian(P, xa), ca.jacobian(P, xb), ca.jacobian(P, us)],
                       ["x", "x_next", "u", "t"], ["P", "P_a", "P_b", "P_u"])


def merit_function(model, problem) -> ca.Function:
    """``mpc_merit: (x, t, X, U) -> (J, c, res)``: the cost ``J`` of the iterate ``(X, U)``
    (``X``: nx × (N + 1), ``U``: nu × N), its infeasibility
    ``c = ‖x − X_0‖₁ + Σ_k ‖step(X_k, U_k) − X_{k+1}‖₁ + Σ_{k≥1} (state-bound violation)₁``
    and the largest residual ``res`` of the ``N`` steps' Newton iterations."""
    from ncgen.control.discrete import step_functions
    h, N, p = problem.h, problem.N, problem.p
    nx, nu = 2 * model.nq, model.nu
    step = step_functions(model, h)["step"]
    x, t, X, U = ca.MX.sym("x", nx), ca.MX.sym("t"), ca.MX.sym("X", nx, N + 1), ca.MX.sym("U", nu, N)
    times = t + h * ca.DM(np.arange(N)).T
    xs, us, ts = ca.MX.sym("x", nx), ca.MX.sym("u", nu), ca.MX.sym("t")
    # the parameters closed over, not passed to the map: a map of a zero-size input made CasADi 3.8
    # generate ``casadi_copy(0, 0, 0+ i*0)``, which gcc refuses
    step_p = ca.Function("mpc_step", [xs, us, ts], list(step(xs, us, ca.DM(p), ts)))
    X1, res = step_p.map("mpc_steps", "serial", int(N), [], [])(X[:, :N], U, times)
    return ca.Function("mpc_merit", [x, t, X, U],
                       [total_cost_function(problem, nx, nu)(X, U, t), infeasibility(problem, x, X, U, X1, times),
                        ca.mmax(res)],
                       ["x", "t", "X_trial", "U_trial"], ["J", "c", "res"])


def infeasibility(problem, x, X, U, X1, times):
    """``c`` of :func:`merit_function` (MX) from the steps ``X1`` (nx × N) of the nodes
    ``X[:, :N]`` with ``U`` at ``times``."""
    N = problem.N
    c = ca.norm_1(x - X[:, 0]) + ca.sum2(ca.sum1(ca.fabs(X1 - X[:, 1:])))
    lo_x, hi_x = problem.x_bounds
    for i in np.flatnonzero(np.isfinite(lo_x) | np.isfinite(hi_x)):
        row = X[int(i), 1:]
        if np.isfinite(lo_x[i]):
            c += ca.sum2(ca.fmax(0, float(lo_x[i]) - row))
        if np.isfinite(hi_x[i]):
            c += ca.sum2(ca.fmax(0, row - float(hi_x[i])))
    if problem.min_tension is not None:           # the cables' pull below T_min, at both ends of each interval
        pull = problem.cable_pull.map("mpc_cable_pulls", "serial", int(N), [], [])
        c += ca.sum2(ca.sum1(ca.fmax(0, problem.min_tension - pull(X[:, :N], X[:, 1:], U, times))))
    return c


def total_cost_function(problem, nx: int, nu: int) -> ca.Function:
    """``mpc_total_cost: (X, U, t) -> J`` (SX, :func:`total_cost`)."""
    Xs, Us, ts = ca.SX.sym("X", nx, problem.N + 1), ca.SX.sym("U", nu, problem.N), ca.SX.sym("t")
    return ca.Function("mpc_total_cost", [Xs, Us, ts], [total_cost(problem, Xs, Us, ts)])


def total_cost(problem, X, U, t):
    """``Σ_{k<N} ℓ(X_k, U_k, t + k h) + ℓ_N(X_N, t + N h)`` (SX)."""
    h, N = problem.h, problem.N
    return sum(problem.stage(X[:, k], U[:, k], t + k * h) for k in range(N)) + problem.terminal(X[:, N], t + N * h)


class MPC:
    """A receding-horizon controller for ``ocp`` (an :class:`~ncgen.optim.problem.OptimalControl`):
    ``u = mpc(x, t)``.

    ``solver``: ``"sqp"`` (Gauss–Newton SQP with CasADi's ``qrqp`` and a filter line search,
    generated C; see the module docstring) or ``"fatrop"`` (CasADi's Fatrop, an interior-point
    method, solving the stage-wise problem of :mod:`ncgen.control.mpc_fatrop` to its tolerance
    from the previous solution shifted; ``nc.export_mpc(..., solver="fatrop")`` writes the
    joint form's as C, :mod:`ncgen.control.export_fatrop`);
    ``fatrop_form``: that problem's form, ``"joint"`` (a tree's joint space with an
    explicit midpoint step, :mod:`ncgen.control.mpc_fatrop_joint`: 2 n_j states and nu
    controls a stage, not the SQP's RATTLE step), ``"natural"`` (the SQP's own discrete
    problem, the step's unknowns as controls) or ``None`` (the joint form where the model
    allows it; ``mpc.fatrop.form`` says which);
    ``iterations``: SQP iterations (Fatrop: solves) per control step (1: real-time iteration);
    ``fatrop_options``: Fatrop's own options by name (``{"tolerance": 1e-8, "max_iter": 50}``,
    over :data:`ncgen.control.mpc_fatrop.FATROP_OPTIONS`), checked by a first solve;
    ``terminal_weight``: weight ``W`` of the OCP's final conditions, soft in MPC
    (:mod:`ncgen.control.mpc_problem`);
    ``sx_qr_max_nnz``: the largest QR of the step's Jacobian (``nnz(V) + nnz(R)``) unrolled into
    straight-line C (default :data:`ncgen.control.discrete.SX_QR_MAX_NNZ`); ``0`` generates it
    as loops, slower per solve but quick to compile (the two-stage tensegrity tower's unrolled QR,
    26k instructions in one C function, had gcc -O1 still compiling after 5 min at 2.3 GB);
    ``reference``: a plan to track, ``(t, X, U)`` or an OCP's solution
    (:mod:`ncgen.control.mpc_reference`), with the weights ``state_weight`` (``Q``: nx numbers or
    one, default 1) and ``input_weight`` (``r``: nu or one, default 0) of the stage cost on ``x − x_ref``, ``u − u_ref``
    (:mod:`ncgen.control.mpc_problem`; the final conditions' target becomes ``x_ref`` at the
    horizon's end); ``min_tension``: ``T_min`` (N), the cables kept at a pull ``≥ T_min`` at both
    ends of every interval (a path constraint of the QP, linearised like the state bounds, and in
    the infeasibility ``c``; :mod:`ncgen.control.mpc_problem`), refused on a model without
    cables and with ``"fatrop"``.  The horizon is the OCP's: ``N`` intervals of
    ``h = t_final / N`` seconds, and ``mpc`` is meant to be called every ``h`` seconds.
    ``qp_solver``: ``"qrqp"`` (generated C) or ``"qpoases"`` (in this process; not exported), see
    :mod:`ncgen.control.mpc_qp`.
    ``loop``: ``"python"`` (the iterations driven from Python, every iteration reported) or
    ``"c"`` (the whole control step one call of the exported package's C controller compiled
    into the same package, :mod:`ncgen.control.mpc_c_loop`: the same numbers; ``qrqp``, no
    reference; only the last iteration of a step reported).
    ``mpc.reset(x, t, iterations=...)`` (also done by the first call) sets the guess to ``x``
    held with zero inputs (clipped into their bounds), or to the reference along the horizon
    from ``t``, and iterates on it.
    ``mpc.qp_status``, ``mpc.step_lengths`` and ``mpc.infeasibility`` report each iteration of
    the last call (SQP), ``mpc.fatrop.status`` and ``mpc.fatrop.iteration_counts`` each solve of
    the last call (Fatrop: ``"0"`` is success; a failed solve keeps the guess)."""

    def __init__(self, ocp, solver: str = "sqp", *, iterations: int = 1, terminal_weight: float = 1e3,
                 regularization: float = REGULARIZATION, qp_max_iter: int = 100,
                 sx_qr_max_nnz: int | None = None, fatrop_options: dict | None = None,
                 reference=None, state_weight=None, input_weight=None, min_tension=None,
                 qp_solver: str = "qrqp", loop: str = "python", fatrop_form: str | None = None):
        if not isinstance(solver, str) or solver not in SOLVERS:
            raise OptimizationError(f"MPC: solver: expected one of {', '.join(SOLVERS)}, got {solver!r}")
        if not isinstance(iterations, int) or iterations < 1:
            raise OptimizationError(f"MPC: iterations: expected a positive integer, got {iterations!r}")
        self.ocp, self.model = ocp, ocp.model
        self.problem = mpc_problem(ocp, terminal_weight, reference, state_weight, input_weight, min_tension)
        if self.problem.min_tension is not None and solver == "fatrop":
            raise OptimizationError("MPC: min_tension: supported by solver='sqp' only, got solver='fatrop'")
        if fatrop_form is not None and solver != "fatrop":
            raise OptimizationError(f"MPC: fatrop_form: the stage-wise form of solver='fatrop', got fatrop_form="
                                    f"{fatrop_form!r} with solver={solver!r}")
        self.qp_solver = check_qp_solver(qp_solver)
        from ncgen.control.mpc_c_loop import check_loop, loop_refusal
        self.loop, refusal = check_loop(loop), loop_refusal(solver, qp_solver, self.problem)
        if self.loop == "c" and refusal is not None:
            raise OptimizationError(f"MPC: loop='c': the compiled control step is the exported package's "
                                    f"(solver='sqp', qp_solver='qrqp', no reference), got {refusal}")
        self.h, self.N = self.problem.h, self.problem.N
        self.nx, self.nu = 2 * self.model.nq, self.model.nu
        self.iterations = iterations
        if sx_qr_max_nnz is not None and (isinstance(sx_qr_max_nnz, bool) or not isinstance(sx_qr_max_nnz, int)
                                          or sx_qr_max_nnz < 0):
            raise OptimizationError(f"MPC: sx_qr_max_nnz: expected an integer >= 0 or None, got {sx_qr_max_nnz!r}")
        self.solver = solver
        #: Fatrop's stage-wise problem (``solver="fatrop"``), else ``None``; ``mpc.Z``: Fatrop's own
        #: part of the guess (the steps' unknowns, or the joint states: ``mpc.fatrop.form``).
        self.fatrop = self.Z = None
        #: the controller's C (:class:`~ncgen.control.mpc_c_loop.CompiledLoop`): the SQP's condensing,
        #: and its whole control step where it applies
        self._c = None
        if solver == "fatrop":
            from ncgen.control.mpc_fatrop import FatropSolver
            self.fatrop = FatropSolver(self.model, self.problem, fatrop_options, fatrop_form)
        else:
            self._sqp_package(regularization, qp_max_iter, sx_qr_max_nnz)
        self._residual_tol = residual_tolerance(self.model)
        #: the QP solver's status of each QP of the last control step (0: converged).
        self.qp_status: list[int] = []
        #: the step length α taken by each SQP iteration of the last control step (0: no trial
        #: was acceptable, the iterate was kept).
        self.step_lengths: list[float] = []
        #: the infeasibility ``c`` (ℓ1 of the shooting gaps and state-bound violations, m and m/s
        #: summed over the horizon) of the iterate each SQP iteration of the last control step ended with.
        self.infeasibility: list[float] = []
        self.u_bounds = self.problem.u_bounds
        self.u_rest = np.clip(np.zeros(self.nu), *self.u_bounds)
        self._u_lo, self._u_hi = (np.tile(b, self.N) for b in self.u_bounds)   # the inputs' bounds along the horizon
        self.X = self.U = self.solution = None

    def _sqp_package(self, regularization: float, qp_max_iter: int, sx_qr_max_nnz: int | None) -> None:
        """The SQP's functions (:func:`mpc_functions`) compiled into one package with the
        controller's C (:mod:`ncgen.control.mpc_c_loop`), which condenses the QP for every loop;
        the QP solver in this process where ``qp_solver`` is not generated (the controller's C
        then only condenses)."""
        self.functions = mpc_functions(self.model, self.problem, regularization=regularization,
                                       qp_max_iter=qp_max_iter, sx_qr_max_nnz=sx_qr_max_nnz, qp_solver=self.qp_solver)
        from ncgen.control.mpc_c_loop import CompiledLoop
        from ncgen.control.step_support import compile_functions
        qp_in_c = self.qp_solver in GENERATED
        compiled = [f for f in self.functions if f.name() != "mpc_qp" or qp_in_c]
        name = f"{self.model.name}_mpc"
        lib = compile_functions(name, compiled,
                                extra_sources=controller_sources(self.model, self.problem, compiled, name))
        lib.setdefault("mpc_qp", InProcessQP(self.functions[1]))
        self._qp, self._update, self._merit_fn = (lib[f.name()] for f in self.functions[1:4])
        self._c = CompiledLoop(self._update.library, name, self.nx, self.nu, self.N, qp_rows(self.problem, self.nx),
                               controller=qp_in_c)
        self._data = self._c.condensed_qp          # the QP condensed by the controller's C, in every loop

    def __repr__(self) -> str:
        if self.fatrop is not None:
            return (f"<MPC of {self.model.name!r}: N={self.N}, h={self.h} s, {self.iterations} Fatrop "
                    f"solve(s) per step, {self.fatrop.form} form>")
        return (f"<MPC of {self.model.name!r}: N={self.N}, h={self.h} s, {self.iterations} SQP "
                f"iteration(s) per step, {self.qp_solver}>")

    def _merit(self, x, t: float, X: np.ndarray, U: np.ndarray):
        """``(J, c)`` of the iterate, or ``None`` when a step along it did not converge or
        anything is not finite."""
        if not (np.isfinite(X).all() and np.isfinite(U).all()):
            return None
        try:
            # t as a 1-array: the compiled function's fast copy (a float took its checked path, 0.1 ms)
            J, c, res = (float(o[0]) for o in self._merit_fn(x, np.array([t]), X.ravel(), U.ravel()))
        except (NcgenError, RuntimeError):         # a kernel (a step's Newton iterations) reported failure
            return None
        return (J, c) if res <= self._residual_tol and np.isfinite(J) and np.isfinite(c) else None

    def _solve(self, x, t: float, X: np.ndarray, U: np.ndarray):
        """``iterations`` globalised SQP iterations (or Fatrop solves) from the guess ``(X, U)``:
        ``(X, U)``."""
        self.qp_status, self.step_lengths, self.infeasibility = [], [], []
        if self.fatrop is not None:
            self.fatrop.clear()
            for _ in range(self.iterations):
                X, U, self.Z = self.fatrop.solve(x, t, X, U, self.Z)
            return X, U
        for _ in range(self.iterations):
            X, U = self._iteration(x, t, X, U)
        return X, U

    def _iteration(self, x, t, X, U):
        """One SQP iteration (see the module docstring): the QP at the guess (with the guess's
        merit, from the same steps), then the filter line search along ``X + α (X⁺ − X)``,
        ``clip(U + α δU)``; the guess itself must be valid (its steps converge), else
        :class:`OptimizationError`.  The QP data are the compiled function's buffers, used
        before its next call."""
        t1 = np.array([t])                 # a 1-array: the compiled function's fast copy
        data = None
        if np.isfinite(X).all() and np.isfinite(U).all():
            try:
                data = self._data(x, t1, X.ravel(), U.ravel())
            except (NcgenError, RuntimeError):         # a kernel (a step's Newton iterations) reported failure
                pass
        if data is None or not (data[11][0] <= self._residual_tol and np.isfinite(data[9][0])
                                and np.isfinite(data[10][0])):
            raise OptimizationError(f"MPC of {self.model.name!r}: a step of the model does not converge along "
                                    f"the guess at t = {t:g} s (state {np.asarray(x).tolist()}); reset() the guess")
        H, g, A, lba, uba, lbx, ubx, Xs, S, J0, c0, _ = data
        J0, c0 = float(J0[0]), float(c0[0])
        self.qp_status.append(self._qp.status_call(H, g, A, lba, uba, lbx, ubx, 0.0, 0.0, 0.0))
        dU, model_decrease = self._qp.outputs[0].copy(), float(self._qp.outputs[1][0])
        if (np.isfinite(dU).all() and np.isfinite(model_decrease)
                and not stationary(J0, c0, model_decrease, self.qp_status[-1])):
            Xf = self._update(Xs, S, U.ravel(), dU)[0].reshape(self.N + 1, self.nx)
            lo, hi = self._u_lo, self._u_hi
            for alpha in ALPHAS:
                Xa = X + alpha * (Xf - X)
                Ua = np.minimum(np.maximum(U.ravel() + alpha * dU, lo), hi).reshape(self.N, self.nu)
                trial = self._merit(x, t, Xa, Ua)
                if trial is not None and acceptable(J0, c0, *trial, alpha, model_decrease):
                    self.step_lengths.append(alpha)
                    self.infeasibility.append(trial[1])
                    return Xa, Ua
        self.step_lengths.append(0.0)
        self.infeasibility.append(c0)
        return X, U

    def initial_guess(self, x, t: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """``(X, U)``: ``x`` at every node, inputs zero clipped into their bounds; with a
        reference, the reference at the nodes' times from ``t`` (inputs clipped)."""
        if self.problem.reference is None:
            return np.tile(x, (self.N + 1, 1)), np.tile(self.u_rest, (self.N, 1))
        t = self.model.t0 if t is None else t
        X, U = zip(*(self._reference(t + k * self.h) for k in range(self.N + 1)))
        return np.array(X), np.array(U[:self.N])

    def _reference(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """``(x_ref(t), u_ref(t))``, the input clipped into its bounds."""
        x, u = (np.asarray(o, float).reshape(-1) for o in self.problem.reference(t))
        return x, np.clip(u, *self.u_bounds)

    @one_blas_thread
    def reset(self, x, t: float | None = None, iterations: int = 0) -> None:
        """Start again from the guess of :meth:`initial_guess`, then run ``iterations``
        solves at ``x`` without shifting (to converge the first solution)."""
        from ncgen.control.step_support import state_vector
        x = state_vector(x, self.nx, "x", "the state [q; v]")
        t = self.model.t0 if t is None else as_scalar(t, "MPC.reset: t")
        if isinstance(iterations, bool) or not isinstance(iterations, (int, np.integer)) or iterations < 0:
            raise OptimizationError(f"MPC.reset: iterations: expected an integer >= 0, got {iterations!r}")
        if self.loop == "c":
            self._check_c(self._c.start(x, t, int(iterations), self.iterations), t, x)
            self.X, self.U = self._c.X, self._c.U
            return
        X, U = self.initial_guess(x, t)
        if self.fatrop is not None:
            self.Z = self.fatrop.guess(X)
        for _ in range(iterations):
            X, U = self._solve(x, t, X, U)
        self.X, self.U = X, U

    @one_blas_thread
    def __call__(self, x, t: float | None = None) -> np.ndarray:
        """The input to apply now, from the measured state ``x`` at time ``t``; the solution
        (``mpc.solution``: states and inputs along the horizon), shifted by one interval,
        is the next call's guess.  The input is inside its bounds (checked)."""
        from ncgen.control.step_support import state_vector
        x = state_vector(x, self.nx, "x", "the state [q; v]")
        t = self.model.t0 if t is None else as_scalar(t, "MPC: t")
        if self.X is None:
            self.reset(x, t)
        if self.loop == "c":
            return self._c_step(x, t)
        X, U = self._solve(x, t, self.X, self.U)
        u = self._checked_input(U[0].copy())
        self.solution = (X, U)
        if self.problem.reference is None:
            self.X, self.U = np.vstack([X[1:], X[-1:]]), np.vstack([U[1:], U[-1:]])
        else:                                   # the horizon's new last node and input from the reference
            self.X = np.vstack([X[1:], self._reference(t + (self.N + 1) * self.h)[0]])
            self.U = np.vstack([U[1:], self._reference(t + self.N * self.h)[1]])
        if self.Z is not None:
            self.Z = np.vstack([self.Z[1:], self.Z[-1:]])
        return u


    def _checked_input(self, u: np.ndarray) -> np.ndarray:
        """``u``, refused unless finite and inside the input bounds."""
        lo, hi = self.u_bounds
        if not (np.all(np.isfinite(u)) and np.all(lo <= u) and np.all(u <= hi)):
            raise OptimizationError(f"MPC of {self.model.name!r}: the control step returned {u.tolist()}, "
                                    f"outside the bounds [{lo.tolist()}, {hi.tolist()}]")
        return u

    def _c_step(self, x: np.ndarray, t: float) -> np.ndarray:
        """``loop="c"``: the control step in one C call (:mod:`ncgen.control.mpc_c_loop`), from
        the guess ``mpc.X``, ``mpc.U`` (the struct's own arrays unless replaced)."""
        c = self._c
        if self.X is not c.X or self.U is not c.U:
            c.X[:], c.U[:] = self.X, self.U
            self.X, self.U = c.X, c.U
        status, u = c.step(x, t)
        self._check_c(status, t, x)
        qp_status, alpha = c.report()
        self.qp_status, self.step_lengths, self.infeasibility = [qp_status], [alpha], []
        self.solution = (c.X_sol.copy(), c.U_sol.copy())
        return self._checked_input(u.copy())

    def _check_c(self, status: int, t: float, x: np.ndarray) -> None:
        """A status of the compiled controller other than 0 as an :class:`OptimizationError`."""
        if status:
            raise OptimizationError(f"MPC of {self.model.name!r}: the compiled control step failed at t = {t:g} s "
                                    f"(state {np.asarray(x).tolist()}): a step of the model does not converge "
                                    "along the guess, or an iterate is not finite; the guess is kept")


def controller_sources(model, problem, functions, name: str) -> list:
    """The exported package's controller (``templates/c/mpc``, rendered ``in_process``) as
    extra sources of the MPC's package ``name`` (:mod:`ncgen.control.mpc_c_loop`)."""
    from ncgen.codegen.package import ExtraSource
    from ncgen.control.mpc_context import controller_context
    context = controller_context(model, problem, functions, None, line_search_rules(model))
    return [ExtraSource("runtime/ncgen_mpc.h", "ncgen_mpc.h", included=True),
            ExtraSource("runtime/ncgen_condense.h", "ncgen_condense.h", included=True),
            ExtraSource("mpc/mpc.h.j2", f"{name}_mpc.h", context),
            ExtraSource("mpc/mpc.c.j2", f"{name}_mpc.c", context)]


def acceptable(J0: float, c0: float, J: float, c: float, alpha: float, model_decrease: float) -> bool:
    """The filter's test of a trial ``(J, c)`` against the iterate ``(J0, c0)`` (cost,
    infeasibility) at step length ``α``; ``model_decrease``: the QP's optimal value (its
    model of the cost's change at ``α = 1``).  Nearly feasible (``c0 ≤`` :data:`C_MIN`) with a
    predicted decrease: Armijo on the cost, ``J ≤ J0 + c α model_decrease``, the trial staying
    nearly feasible; otherwise a sufficient decrease of the infeasibility or of the cost,
    ``c ≤ (1 − γ) c0`` or ``J ≤ J0 − γ c0`` with ``c ≤ c0``.  The same expression, in the same
    order, as the exported package's C."""
    if c0 <= C_MIN and model_decrease < 0:
        return c <= C_MIN and J <= J0 + ARMIJO * alpha * model_decrease
    return c <= (1.0 - GAMMA) * c0 or (J <= J0 - GAMMA * c0 and c <= c0)


def stationary(J0: float, c0: float, model_decrease: float, qp_status: int) -> bool:
    """Whether the guess is optimal to round-off: nearly feasible (``c0 ≤`` :data:`C_MIN`) and
    the converged QP (status 0) predicts a decrease of at most :data:`STATIONARY` ``|J0|``,
    below what an evaluation of the cost resolves, so that the line search could pass its
    Armijo test only by round-off (at a converged guess it used to try all 11 step lengths:
    twelve merit calls, 2–3 ms on the cart-pole).  The guess is then kept without trials
    (``mpc.step_lengths``: 0).  The same test as the exported package's C."""
    return qp_status == 0 and c0 <= C_MIN and -model_decrease <= STATIONARY * abs(J0)


def line_search_rules(model) -> dict:
    """The SQP line search's rules as the exported controller's C takes them: the number of
    step lengths (:data:`ALPHAS`), :data:`ARMIJO`, :data:`GAMMA`, :data:`C_MIN`,
    :data:`STATIONARY` and the step's residual tolerance (:func:`residual_tolerance`)."""
    return {"alphas": len(ALPHAS), "armijo": ARMIJO, "gamma": GAMMA, "c_min": C_MIN, "stationary": STATIONARY,
            "step_tol": residual_tolerance(model)}


def residual_tolerance(model) -> float:
    """The Newton residual above which a step is refused (as :class:`ncgen.control.step.StepFunction`)."""
    from ncgen.control.discrete import residual_scale
    from ncgen.control.step import RESIDUAL_TOL
    return RESIDUAL_TOL * residual_scale(model)
