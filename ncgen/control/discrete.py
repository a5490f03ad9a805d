"""One RATTLE step as an implicit function, its exact derivatives, rollouts and their adjoints
(CasADi; compiled by :mod:`ncgen.control.step`).

The step of the compiled stepper (:mod:`ncgen.assembly.stepper_equations`, whose kernels
``step_newton`` and ``step_velocity`` are reused here) from ``x = [q; v]`` with step ``h``
(s) and inputs ``u`` held over the step, written as one residual in the unknowns
``z = [w; ν; v⁺; μ']`` (``w = v_{n+½}``, ``ν = h/2 λ``, ``μ' = h/2 μ``)::

    G(z; x, u, p, t) = [ M (w − v) − h/2 F(t, q, w) + A(t, q)ᵀ ν                  ]
                       [ Φ(t + h, q⁺) / h                                          ]   q⁺ = q + h w
                       [ M v⁺ + A(t + h, q⁺)ᵀ μ' − M w − h/2 F(t + h, q⁺, w)       ]
                       [ A(t + h, q⁺) v⁺ + Φ_t(t + h, q⁺)                          ]
    x⁺ = [q + h w; v⁺]

``z`` is found as the compiled stepper finds it: CasADi's ``fast_newton`` rootfinder on the
first half-step's residual ``r(w, ν)`` (the first two rows; its Jacobian is the stepper's
``K``; sparse QR, at most ``max_iter`` iterations, stopping when ``‖r‖∞ ≤ abstol`` or the
Newton step is below ``abstol_step``) from ``[v; 0]``, then the second half-step, linear in
``(v⁺, μ')``, by one sparse QR solve; it generates self-contained C.

Derivatives come from the implicit function theorem at the converged ``z``, never from
differentiating the iterations: with ``y = [x; u; p]``,

    ∂z/∂y = −G_z⁻¹ G_y,      ∂x⁺/∂y = [I_q 0] + E ∂z/∂y,   E z = [h w; v⁺]

so that ``A = ∂x⁺/∂x``, ``B = ∂x⁺/∂u``, ``C = ∂x⁺/∂p``; the adjoint of a step is one
transposed solve, ``ȳ = (∂x⁺/∂y)ᵀ x̄⁺ = [x̄⁺_q; 0] − G_yᵀ G_z⁻ᵀ Eᵀ x̄⁺``.  (``G_y`` at fixed
``q⁺ = q + h w`` is cheaper, but then the whole ``∂q⁺/∂q ≈ I`` comes out of the solve, with
the solve's relative error ``cond(G_z) ε``: Talos's ``A`` agreed with central differences
to 1.5e-5 only.)  :func:`step_functions`
generates the step (returning ``z``), the sparse ``G_z`` and ``G_y`` at a given ``z`` (SX,
one function each) and the two solves given them (``step_jacobian``, ``step_adjoint``:
CasADi's sparse QR linear solver ``"qr"``, generated as loops over the factor's pattern), so
that each is a translation unit of its own, compiled in parallel, and the C grows with the
model's functions, not with a factorisation unrolled into code (unrolled, the z1 arm's was
55 MB of C that gcc could not compile).  Every step function also returns the residual
``‖G(z)‖∞`` of the solution it used, so that callers can refuse a step that did not
converge.  :func:`step_jacobian_function` writes the whole step with its Jacobians as one
function for the MPC (its QR unrolled into SX when the factors are small,
:data:`SX_QR_MAX_NNZ`).

Rollouts ``X = [x₁ … x_N]`` run in pieces of :data:`ROLLOUT_CHUNK` steps (and single
steps for the rest), each a ``mapaccum`` of the step returning the states and the steps'
unknowns ``Z``: CasADi writes a ``mapaccum`` as one call per step, so a piece's C grows with
its length (a 1000-step ``mapaccum`` was 10 MB of C and minutes of compiling); the pieces
are compiled once per step function.  Their adjoint chains the steps' transposed IFT solves
from the last step to the first.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ncgen.assembly.stepper_equations import mass_scale, stepper_functions
from ncgen.model.rolling import ROLLING_STEP, refuse_rolling

#: Rootfinder defaults: residual tolerance (relative: :func:`default_abstol`), absolute step
#: tolerance, iteration limit.
ABSTOL, ABSTOL_STEP, MAX_ITER = 1e-12, 1e-14, 20
#: Steps per compiled piece of a rollout.
ROLLOUT_CHUNK = 25


def residual_scale(model) -> float:
    """``1 + max |M_ij|``: the scale of the step residual's rows (the momentum rows grow with the
    mass matrix)."""
    return 1.0 + mass_scale(model) if model.nq else 1.0


def default_abstol(model) -> float:
    """The Newton tolerance of a model's step, ``ABSTOL (1 + max |M_ij|)``: an absolute 1e-12
    is below the rounding floor of a heavy robot's residual (the Panda's stalls near 1e-11),
    whose iterations then all ran to ``max_iter``."""
    return ABSTOL * residual_scale(model)


def step_residual(model, h: float) -> ca.Function:
    """``G: (z, x, u, p, t) -> G`` (SX; see the module docstring)."""
    newton, velocity = stepper_functions(model)[:2]
    nq, nc = model.nq, model.nc
    z = ca.SX.sym("z", 2 * (nq + nc))
    x, u, p, t = ca.SX.sym("x", 2 * nq), ca.SX.sym("u", model.nu), ca.SX.sym("p", model.np), ca.SX.sym("t")
    q, v = x[:nq], x[nq:]
    w, nu_h, vmu = z[:nq], z[nq:nq + nc], z[nq + nc:]
    r, _ = newton(t, q, v, u, p, h, w, nu_h)
    b, K2 = velocity(t + h, q + h * w, w, u, p, h)
    G = ca.vertcat(r, ca.mtimes(K2, vmu) - b)
    return ca.Function("step_residual", [z, x, u, p, t], [ca.densify(G)], ["z", "x", "u", "p", "t"], ["G"])


def _step_state(x, z, nq: int, nc: int, h: float):
    """``x⁺ = [q + h w; v⁺]`` from the state ``x = [q; v]`` and the step's unknowns ``z``."""
    return ca.vertcat(x[:nq] + h * z[:nq], z[nq + nc:2 * nq + nc])


def _solved_step(model, h: float, abstol: float, abstol_step: float, max_iter: int):
    """``((x, u, p, t), z, x1, res)``: MX arguments, the step's unknowns ``z``, the state after
    the step and ``‖G(z)‖∞``, solved as the compiled stepper solves it: the rootfinder on the
    first half-step's ``r(w, ν) = 0`` (its Jacobian is the stepper's ``K``, a quarter of
    ``G_z``) from ``[v; 0]`` and one more Newton step from where it stopped (its test,
    relative to the mass matrix, stops a few digits above the rounding floor; the quadratic
    step reaches the floor, which finite differences of the step need on a large model), then
    the second half-step, linear in ``(v⁺, μ')``, by one sparse QR solve.  ``res`` is the larger of ``‖r‖∞`` (from the rootfinder's Jacobian function, so
    that the C holds ``r`` once) and the second solve's ``‖K₂ [v⁺; μ'] − b‖∞``: the rows of
    ``G``."""
    newton, velocity = stepper_functions(model)[:2]
    nq, nc = model.nq, model.nc
    wn, xs = ca.SX.sym("w_nu", nq + nc), ca.SX.sym("x", 2 * nq)
    us, ps, ts = ca.SX.sym("u", model.nu), ca.SX.sym("p", model.np), ca.SX.sym("t")
    r = newton(ts, xs[:nq], xs[nq:], us, ps, h, wn[:nq], wn[nq:])[0]
    first = ca.Function("r", [wn, ca.vertcat(xs, us, ps, ts)], [r])
    solve = ca.rootfinder("rattle_step", "fast_newton", first,
                          {"abstol": abstol, "abstolStep": abstol_step, "max_iter": max_iter})
    x, u = ca.MX.sym("x", 2 * nq), ca.MX.sym("u", model.nu)
    p, t = ca.MX.sym("p", model.np), ca.MX.sym("t")
    q, v = x[:nq], x[nq:]
    y = ca.vertcat(x, u, p, t)
    newton_system = solve.get_function("jac_g_x")                     # (K, r)
    w_nu_stop = solve(ca.vertcat(v, ca.MX(nc, 1)), y)
    K, r_stop = newton_system(w_nu_stop, y)
    w_nu = w_nu_stop - ca.solve(K, r_stop, "qr")
    r_end = newton_system(w_nu, y)[1]
    w = w_nu[:nq]
    b, K2 = velocity(t + h, q + h * w, w, u, p, h)
    v_mu = ca.solve(K2, b, "qr")
    z = ca.vertcat(w_nu, v_mu)
    res = ca.fmax(ca.norm_inf(r_end), ca.norm_inf(ca.mtimes(K2, v_mu) - b))
    return (x, u, p, t), z, _step_state(x, z, nq, nc, h), res


def step_functions(model, h: float, *, abstol: float = ABSTOL, abstol_step: float = ABSTOL_STEP,
                   max_iter: int = MAX_ITER) -> dict[str, ca.Function]:
    """``{"step": (x, u, p, t) -> (x1, res), "step_solution": (x, u, p, t) -> (x1, z, res),
    "step_G_z": (z, x, u, p, t) -> G_z, "step_G_y": (z, x, u, p, t) -> G_y,
    "step_jacobian": (G_z, G_y) -> J, "step_adjoint": (G_z, G_y, x1_bar) -> y_bar}`` with
    ``J = ∂x⁺/∂[x; u; p]`` (nx × (nx + nu + np), dense) and ``y_bar = Jᵀ x1_bar`` from the
    sparse ``G_z``, ``G_y`` at a converged ``z`` (see the module docstring): separate
    functions, so that the C of the solve and of each sensitivity is a translation unit of its
    own."""
    refuse_rolling(model, "the RATTLE step (step_function, MPC, export_mpc)", ROLLING_STEP)
    nq, nc = model.nq, model.nc
    args, z, x1, res = _solved_step(model, h, abstol, abstol_step, max_iter)
    names = ["x", "u", "p", "t"]
    step = ca.Function("step", list(args), [x1, res], names, ["x1", "res"])
    solution = ca.Function("step_solution", list(args), [x1, z, res], names, ["x1", "z", "res"])
    G_z, G_y = _sensitivities(step_residual(model, h))
    Gz, Gy = ca.MX.sym("G_z", G_z.sparsity_out(0)), ca.MX.sym("G_y", G_y.sparsity_out(0))
    jacobian = _state_jacobian(-ca.solve(Gz, ca.densify(Gy), "qr"), nq, nc, h)
    x1_bar = ca.MX.sym("x1_bar", 2 * nq)
    z_bar = ca.vertcat(h * x1_bar[:nq], ca.MX(nc, 1), x1_bar[nq:], ca.MX(nc, 1))       # Eᵀ x̄⁺
    y_bar = ca.vertcat(x1_bar[:nq], ca.MX(Gy.size2() - nq, 1)) - ca.mtimes(Gy.T, ca.solve(Gz.T, z_bar, "qr"))
    return {"step": step, "step_solution": solution, "step_G_z": G_z, "step_G_y": G_y,
            "step_jacobian": ca.Function("step_jacobian", [Gz, Gy], [ca.densify(jacobian)], ["G_z", "G_y"], ["J"]),
            "step_adjoint": ca.Function("step_adjoint", [Gz, Gy, x1_bar], [ca.densify(y_bar)],
                                        ["G_z", "G_y", "x1_bar"], ["y_bar"])}


def _sensitivities(G: ca.Function) -> tuple[ca.Function, ca.Function]:
    """``step_G_z: (z, x, u, p, t) -> G_z`` and ``step_G_y: (z, x, u, p, t) -> G_y`` (sparse, SX)."""
    zs, xs, us, ps, ts = (G.sx_in(i) for i in range(5))
    Gs = G(zs, xs, us, ps, ts)
    names = ["z", "x", "u", "p", "t"]
    return (ca.Function("step_G_z", [zs, xs, us, ps, ts], [ca.jacobian(Gs, zs)], names, ["G_z"]),
            ca.Function("step_G_y", [zs, xs, us, ps, ts], [ca.jacobian(Gs, ca.vertcat(xs, us, ps))], names,
                        ["G_y"]))


def _state_jacobian(Z_y, nq: int, nc: int, h: float):
    """``∂x⁺/∂y = [I_q 0] + E Z_y`` (``E z = [h w; v⁺]``) from ``Z_y = −G_z⁻¹ G_y``."""
    ny = Z_y.size2()
    return ca.vertcat(ca.horzcat(ca.DM.eye(nq), ca.DM(nq, ny - nq)) + h * Z_y[:nq, :], Z_y[nq + nc:2 * nq + nc, :])


def step_jacobian_function(model, h: float, *, abstol: float = ABSTOL, abstol_step: float = ABSTOL_STEP,
                           max_iter: int = MAX_ITER, sx_qr_max_nnz: int | None = None) -> ca.Function:
    """``step_jac: (x, u, p, t) -> (x1, A, B, C, res)`` (``A``, ``B``, ``C`` dense): the IFT
    solve with one QR of ``G_z`` for all columns (:func:`qr_solve_columns`, unrolled up to
    ``sx_qr_max_nnz``, default :data:`SX_QR_MAX_NNZ`), in one function with the step: what the
    MPC's generated C calls at every node of its horizon."""
    nq, nc = model.nq, model.nc
    (x, u, p, t), z, x1, res = _whole_newton_step(model, h, abstol, abstol_step, max_iter)
    G_z_f, G_y_f = _sensitivities(step_residual(model, h))
    G_z, G_y = G_z_f(z, x, u, p, t), G_y_f(z, x, u, p, t)
    ny = G_y.size2()
    X1_y = _state_jacobian(-qr_solve_columns(G_z, ca.densify(G_y), G_z_f.sparsity_out(0), ny, sx_qr_max_nnz),
                           nq, nc, h)
    nu_ = model.nu
    return ca.Function("step_jac", [x, u, p, t],
                       [x1] + [ca.densify(X1_y[:, c]) for c in (slice(0, 2 * nq), slice(2 * nq, 2 * nq + nu_),
                                                                slice(2 * nq + nu_, ny))] + [res],
                       ["x", "u", "p", "t"], ["x1", "A", "B", "C", "res"])


def _whole_newton_step(model, h: float, abstol: float, abstol_step: float, max_iter: int):
    """``((x, u, p, t), z, x1, ‖G(z)‖∞)``: the rootfinder on the whole residual ``G`` from
    ``z₀ = [v; 0; v; 0]``, for the MPC's step (with the staged solve of :func:`_solved_step`
    the exported MPC's C held a zero-size ``casadi_copy(0, 0, 0+ i*0)`` that gcc refuses)."""
    nq, nc = model.nq, model.nc
    G = step_residual(model, h)
    zs, xs, us, ps, ts = (G.sx_in(i) for i in range(5))
    residual = ca.Function("G", [zs, ca.vertcat(xs, us, ps, ts)], [G(zs, xs, us, ps, ts)])
    solve = ca.rootfinder("rattle_step", "fast_newton", residual,
                          {"abstol": abstol, "abstolStep": abstol_step, "max_iter": max_iter})
    x, u = ca.MX.sym("x", 2 * nq), ca.MX.sym("u", model.nu)
    p, t = ca.MX.sym("p", model.np), ca.MX.sym("t")
    v = x[nq:]
    z = solve(ca.vertcat(v, ca.MX(nc, 1), v, ca.MX(nc, 1)), ca.vertcat(x, u, p, t))
    return (x, u, p, t), z, _step_state(x, z, nq, nc, h), ca.norm_inf(G(z, x, u, p, t))


#: Largest nnz(V) + nnz(R) of the QR factors of ``G_z`` unrolled into SX (beyond: CasADi's
#: ``qr`` linear solver, generated as loops, several times slower per solve).
SX_QR_MAX_NNZ = 20_000


def qr_solve_columns(K: ca.MX, B: ca.MX, pattern: ca.Sparsity, ncol: int, max_nnz: int | None = None) -> ca.MX:
    """``K⁻¹ B`` for the ``ncol`` columns of ``B`` with one factorisation: the sparse
    Householder QR of ``K`` (pattern ``pattern``) unrolled into an SX function, then an SX
    back-substitution mapped over the columns (a loop in C); CasADi's ``qr`` solver (loops)
    when ``nnz(V) + nnz(R)`` exceeds ``max_nnz`` (default :data:`SX_QR_MAX_NNZ`)."""
    V, R, *_ = ca.qr_sparse(ca.DM(pattern, 1.0), True)
    if V.nnz() + R.nnz() > (SX_QR_MAX_NNZ if max_nnz is None else max_nnz):
        return ca.solve(K, B, "qr")
    Ks = ca.SX.sym("K", pattern)
    V, R, beta, prinv, pc = ca.qr_sparse(Ks, True)
    factor = ca.Function("qr_factor", [Ks], [V, R, beta])
    Vs, Rs, bs = ca.SX.sym("V", V.sparsity()), ca.SX.sym("R", R.sparsity()), ca.SX.sym("beta", beta.shape[0])
    b = ca.SX.sym("b", pattern.size1())
    back = ca.Function("qr_backsolve", [Vs, Rs, bs, b], [ca.qr_solve(b, Vs, Rs, bs, prinv, pc)])
    Vn, Rn, bn = factor(K)
    return back.map("qr_backsolve_columns", "serial", ncol, [0, 1, 2], [])(Vn, Rn, bn, B)


def rollout_function(solution: ca.Function, N: int, h: float) -> ca.Function:
    """``rollout: (x0, U, p, t0) -> (X, Z, res)`` over ``N`` steps of ``solution`` (the
    ``step_solution`` of :func:`step_functions`): ``U`` is nu × N, ``X`` nx × N (the states
    after each step), ``Z`` the steps' unknowns (nz × N), ``res`` 1 × N (each step's residual)."""
    nx, nu, npar = solution.size1_in(0), solution.size1_in(1), solution.size1_in(2)
    x0, U, p, t0 = ca.MX.sym("x0", nx), ca.MX.sym("U", nu, N), ca.MX.sym("p", npar), ca.MX.sym("t0")
    times = t0 + h * ca.DM(np.arange(N)).T
    X, Z, res = solution.mapaccum("step_acc", N, [0], [0])(x0, U, ca.repmat(p, 1, N), times)
    return ca.Function("rollout", [x0, U, p, t0], [X, Z, res], ["x0", "U", "p", "t0"], ["X", "Z", "res"])


def state_constraint_jacobian(model) -> ca.Function:
    """``J: (x, p, t) -> ∂[Φ(t, q); A(t, q) v + Φ_t(t, q)]/∂x`` (2nc × 2nq, dense): the states
    the step maps to satisfy both constraint levels, so their tangent space is ``null J``."""
    f = model.functions
    nq = model.nq
    x, p, t = ca.SX.sym("x", 2 * nq), ca.SX.sym("p", model.np), ca.SX.sym("t")
    q, v = x[:nq], x[nq:]
    c = ca.vertcat(f["phi"](t, q, p), ca.mtimes(f["A"](t, q, p), v) + f["phi_t"](t, q, p))
    return ca.Function("state_constraint_jacobian", [x, p, t], [ca.densify(ca.jacobian(c, x))],
                       ["x", "p", "t"], ["J"])
