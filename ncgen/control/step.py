"""``step_function(model, h)``: one RATTLE step of a model as compiled C with exact
derivatives, rollouts and their adjoints (equations: :mod:`ncgen.control.discrete`;
derivatives by the implicit function theorem at the converged step).

State ``x = [q; v]`` (natural coordinates, m, and their rates, m/s; ``2 nq`` entries), inputs
``u`` held over the step, parameters ``p`` (default ``model.p0``), time ``t`` at the start of
the step (s, default ``model.t0``).  ``A = ∂x⁺/∂x`` is 2nq × 2nq, ``B = ∂x⁺/∂u`` 2nq × nu,
``C = ∂x⁺/∂p`` 2nq × np.

Minimal parametrisation.  A step maps every state, on the constraint manifold or not, to
one that satisfies ``Φ = 0`` and ``A v + Φ_t = 0``; the states of a motion therefore live
on a manifold of dimension ``2 dof``, and ``A`` maps every perturbation into its tangent
space at ``x⁺``.  :meth:`StepFunction.tangent_basis` gives an orthonormal basis ``T(x)``
(2nq × 2dof, ``null`` of the Jacobian of both constraint levels, from its SVD, columns
signed reproducibly) and :meth:`StepFunction.reduced_jacobians` the step's Jacobians in
those coordinates, ``A_T = T(x⁺)ᵀ A T(x)``, ``B_T = T(x⁺)ᵀ B``, with ``δx = T(x) ξ``: what an
LQR or an observer that needs a minimal state uses.

Kernels (``kernels=``, :attr:`StepFunction.kernels` says which were chosen): ``"tables"``
runs the step and its Jacobians ``A``, ``B`` through the element library's table stepper
(:mod:`ncgen.runtime.table_step`: the implicit function theorem on the stepper's own Newton
systems, compiled once per ncgen version, so a new model needs no C compiler); ``"flat"``
generates and compiles the model's own step package (:mod:`ncgen.control.discrete`; cached
by content, called through :class:`ncgen.codegen.direct.DirectFunction`); ``"auto"`` (the
default) takes the tables when every element of the model is covered
(:func:`~ncgen.codegen.stepper_tables.uncovered_elements`; a covered model has no
parameters, so ``C`` is empty), else flat.  With the tables, rollouts run step by step
through them; what they do not provide — the rollouts' adjoints (and the unknowns ``Z`` of
the steps, which iLQR's second-order terms use) — compiles the flat package at its first
use.  Both solve the same equations from the same start to the rounding floor: their steps
and Jacobians agree to about 1e-12.

A call and :meth:`StepFunction.jacobians` on the tables at the model's parameters are one C
call each (:meth:`~ncgen.runtime.table_step.TableStep.door`: the arguments' lengths and
finiteness, the step's convergence and finite results checked in C, fresh outputs or
``out=`` written); whatever that refuses takes the checked path, whose error names the
argument or says why the step failed.  Both take ``out=``: writable C-contiguous float64
arrays of the outputs' shapes, written and returned.
Not thread-safe: one object per thread.
"""
from __future__ import annotations

import math

import numpy as np

from ncgen.control.discrete import (MAX_ITER, ROLLOUT_CHUNK, default_abstol, residual_scale, rollout_function,
                                    state_constraint_jacobian, step_functions)
from ncgen.control.step_support import (PACKAGE_OPTIONS, StepDidNotConverge, compile_flags,  # noqa: F401
                                        compile_functions, state_vector)
from ncgen.errors import NcgenError
from ncgen.model.rolling import ROLLING_STEP, refuse_rolling
from ncgen.validation import as_numbers, as_scalar, write_out

METHODS = ("rattle",)
#: The choices of ``kernels`` (module docstring).
KERNELS = ("auto", "tables", "flat")
#: The functions of :func:`ncgen.control.discrete.step_functions` a step function compiles
#: (one translation unit each, compiled in parallel).
COMPILED = ("step_solution", "step_G_z", "step_G_y", "step_jacobian", "step_adjoint")
#: A step whose residual ‖G‖∞ exceeds this (relative to the largest mass-matrix entry plus
#: one), or whose state or unknowns are not finite, did not converge and is refused.
RESIDUAL_TOL = 1e-8
_NO_INPUTS = np.zeros(0)


def step_function(model, h: float, method: str = "rattle", *, max_iter: int = MAX_ITER,
                  abstol: float | None = None, kernels: str = "auto") -> "StepFunction":
    """One step of ``h`` seconds of ``model`` (``method="rattle"``: the compiled stepper's
    scheme, in natural coordinates, also for trees) as a :class:`StepFunction`.  ``abstol``:
    the Newton iterations' residual tolerance, default
    :func:`~ncgen.control.discrete.default_abstol` (``1e-12 (1 + max |M_ij|)``).
    ``kernels``: ``"auto"``, ``"tables"`` or ``"flat"`` (module docstring).  A model with
    nonsmooth contacts gets a :class:`~ncgen.control.contact_step.ContactStepFunction`
    (Jacobians from the active set of the contact solve; ``kernels="tables"`` refused)."""
    refuse_rolling(model, "step_function", ROLLING_STEP)
    if method not in METHODS:
        raise NcgenError(f"step_function: method: expected one of {', '.join(METHODS)}, got {method!r}")
    h = _positive(h, "h", "a positive, finite step in seconds")
    abstol = default_abstol(model) if abstol is None else _positive(abstol, "abstol", "a positive, finite tolerance")
    if not isinstance(max_iter, int) or max_iter < 1:
        raise NcgenError(f"step_function: max_iter: expected a positive integer, got {max_iter!r}")
    if not isinstance(kernels, str) or kernels not in KERNELS:
        raise NcgenError(f"step_function: kernels: expected one of {', '.join(map(repr, KERNELS))}, got {kernels!r}")
    if getattr(model, "contact_model", "smooth") == "nonsmooth" and getattr(model, "nk", 0) > 0:
        if kernels == "tables":
            raise NcgenError(f"step_function: kernels: the element tables have no contact step; model "
                             f"{model.name!r} has nonsmooth contacts (use kernels='auto')")
        from ncgen.control.contact_step import ContactStepFunction
        return ContactStepFunction(model, h, max_iter=max_iter, abstol=abstol)
    return StepFunction(model, h, max_iter=max_iter, abstol=abstol, kernels=kernels)


def _jacobian_uncovered(model) -> dict[str, list[str]]:
    """Forces the table stepper may cover but whose derivatives its step Jacobians
    (``templates/c/runtime/ncgen_table_jacobians.h``: gravity, spring-dampers, input forces,
    actuated joints, constant point and generalised forces) do not have yet (cables, torsional
    springs, torques; contacts), by kind."""
    from ncgen.codegen.stepper_tables import input_forces
    from ncgen.model.forces import GeneralizedForce, PointForce, Spring

    inputs = {id(f) for f, _ in input_forces(model)}
    out: dict[str, list[str]] = {}
    for f in model.forces:
        if (type(f) is Spring and not f.cable) or type(f) in (PointForce, GeneralizedForce) or id(f) in inputs:
            continue
        out.setdefault(f"{f.kind} (no step Jacobian from the tables)", []).append(f"force {f.name!r}")
    if model.contacts:              # the contact library has no step Jacobians
        out["contact (no step Jacobian from the tables)"] = [f"contact {n!r}" for n in model.contact_names]
    return out


def _table_step(model, h: float, kernels: str, abstol: float, max_iter: int):
    """The :class:`~ncgen.runtime.table_step.TableStep` of ``model``, or None when ``kernels``
    is ``"flat"`` or (``"auto"``) the tables do not cover it; ``"tables"`` on a model they do
    not cover raises :class:`~ncgen.codegen.model_tables.UnsupportedElements` naming its
    elements."""
    from ncgen.codegen.model_tables import UnsupportedElements
    from ncgen.model.data import model_data
    from ncgen.runtime.table_step import TableStep
    from ncgen.runtime.table_stepper import table_stepper

    if kernels == "flat":
        return None
    missing = _jacobian_uncovered(model)
    if missing:
        if kernels == "tables":
            raise UnsupportedElements(model.name, missing)
        return None
    cache = model_data(model).steppers
    if ("tables", None) not in cache:
        try:
            cache[("tables", None)] = table_stepper(model)
        except UnsupportedElements as e:
            cache[("tables", None)] = e
    hit = cache[("tables", None)]
    if isinstance(hit, UnsupportedElements):
        if kernels == "tables":
            raise UnsupportedElements(model.name, hit.kinds)
        return None
    return TableStep(hit, h, tol=abstol / residual_scale(model), max_iter=max_iter)


class StepFunction:
    """``x1 = st(x, u, p=None, t=None)``; ``x1, A, B = st.jacobians(x, u)``; rollouts and
    their adjoints; the tangent parametrisation (see the module docstring)."""

    def __init__(self, model, h: float, *, max_iter: int, abstol: float, kernels: str = "auto"):
        self.model, self.h = model, h
        self.nx, self.nu, self.np = 2 * model.nq, model.nu, model.np
        self._max_iter, self._abstol = max_iter, abstol
        self.residual_tol = RESIDUAL_TOL * residual_scale(model)
        self.nz = 2 * (model.nq + model.nc)
        self._rollouts: dict = {}
        self._functions = self._flat = self._J = None
        self._table = _table_step(model, h, kernels, abstol, max_iter)
        #: The kernels chosen: ``"tables"`` or ``"flat"`` (module docstring).
        self.kernels = "tables" if self._table is not None else "flat"
        self._doors = None
        if self._table is None:
            self._load_flat()
        else:                                   # the C doors of a call and of its Jacobians
            self._doors = (self._table.door(False, self.residual_tol), self._table.door(True, self.residual_tol))
            if None in self._doors:
                self._doors = None
        self._t0 = float(model.t0)

    @property
    def functions(self) -> dict:
        """The step's CasADi functions (:func:`ncgen.control.discrete.step_functions`), built at first use."""
        if self._functions is None:
            self._functions = step_functions(self.model, self.h, abstol=self._abstol, max_iter=self._max_iter)
        return self._functions

    def _load_flat(self) -> None:
        """The model's own step package, generated and compiled (cached by content)."""
        if self._flat is None:
            lib = compile_functions(f"{self.model.name}_step", [self.functions[k] for k in COMPILED])
            self._solution, self._G_z, self._G_y = lib["step_solution"], lib["step_G_z"], lib["step_G_y"]
            self._jacobian, self._adjoint = lib["step_jacobian"], lib["step_adjoint"]
            self._flat = lib

    def __repr__(self) -> str:
        return (f"<StepFunction of {self.model.name!r}: RATTLE, h={self.h} s, nx={self.nx}, nu={self.nu}, "
                f"kernels={self.kernels!r}>")

    # ----------------------------------------------------------------- arguments
    def _args(self, x, u, p, t) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        if u is None and self.nu == 0:
            u = _NO_INPUTS
        if (p is None and t is None and type(x) is np.ndarray and x.dtype == np.float64 and x.shape == (self.nx,)
                and type(u) is np.ndarray and u.dtype == np.float64 and u.shape == (self.nu,)
                and math.isfinite(x.dot(x) + u.dot(u))):
            return x, u, self.model.p0, self.model.t0   # float64 vectors of the right sizes, finite: as they are
        x = state_vector(x, self.nx, "x", "the state [q; v]")
        u = state_vector(u, self.nu, "u", "the inputs")
        p = self.model.p0 if p is None else state_vector(p, self.np, "p", "the parameters")
        t = self.model.t0 if t is None else as_scalar(t, "t")
        return x, u, p, t

    def _check(self, res: float, x1: np.ndarray, z: np.ndarray, where: str) -> None:
        """Refuse a step whose residual is above the tolerance or whose state ``x1`` or
        unknowns ``z`` are not finite."""
        finite = bool(np.all(np.isfinite(z)) and np.all(np.isfinite(x1)))
        if not (res <= self.residual_tol and finite):
            found = f"residual {res:.3g} > {self.residual_tol:.3g}" if finite else "NaN or inf in the state"
            raise StepDidNotConverge(f"step of {self.model.name!r} (h = {self.h:g} s){where}: the Newton "
                                     f"iterations ended with {found}; take a smaller h, raise max_iter, or start "
                                     "from a state closer to the constraints")

    def _solve(self, x, u, p, t) -> tuple[np.ndarray, np.ndarray]:
        """``(x1, z)``: the converged step (refused if it did not converge)."""
        self._load_flat()
        x1, z, res = self._solution(x, u, p, t)
        self._check(float(res[0]), x1, z, "")
        return x1.copy(), z.copy()

    def _table_solve(self, x, u, t, jacobians: bool, where: str = ""):
        """``(x1, A, B)`` from the table stepper (``A``, ``B`` None unless ``jacobians``)."""
        status, x1, res, iterations, A, B = self._table(x, u, t, jacobians)
        if status:
            from ncgen.runtime.table_step import STATUS
            what = STATUS.get(status, f"status {status}")
            raise StepDidNotConverge(f"step of {self.model.name!r} (h = {self.h:g} s){where}: the Newton iterations "
                                     f"ended without a residual below the tolerance ({what} after {iterations} "
                                     "iterations); take a smaller h, raise max_iter, or start from a state closer "
                                     "to the constraints")
        self._check(res, x1, np.zeros(0), where)
        if jacobians and not (math.isfinite(A.sum() + B.sum()) or (np.all(np.isfinite(A)) and np.all(np.isfinite(B)))):
            raise StepDidNotConverge(f"step of {self.model.name!r} (h = {self.h:g} s): its Jacobians are not "
                                     "finite: the Newton matrix is singular there (redundant constraints or a "
                                     "singular configuration)")
        return x1, A, B

    # ---------------------------------------------------------------------- step
    def _door(self, jacobians: bool, x, u, t, out):
        """The step's C door (module docstring) at ``(x, u, t)``: its result, or None for the
        checked path (a refused argument or ``out``, a step that did not converge)."""
        door = self._doors[jacobians]
        t = self._t0 if t is None else t
        if type(t) is not float or t != door.t:
            door.at(as_scalar(t, "t"))
        if u is None:
            u = _NO_INPUTS
        try:
            if self.nu or not jacobians:
                return door.call(x, u, out)
            if out is None:                     # no inputs: B is (nx, 0), not the door's
                r = door.call(x, u)
                return None if r is None else (*r, np.zeros((self.nx, 0)))
            B = out[2] if type(out) is tuple and len(out) == 3 else None
            if not (type(B) is np.ndarray and B.shape == (self.nx, 0) and B.dtype == np.float64
                    and B.flags.c_contiguous and B.flags.writeable):
                return None
            return None if door.call(x, u, out[:2]) is None else out
        except (TypeError, ValueError, OverflowError, RuntimeError):
            return None

    def __call__(self, x, u=None, p=None, t=None, *, out=None) -> np.ndarray:
        """The state after one step (``out``: an array of ``nx`` values written and returned)."""
        if self._doors is not None and p is None:
            x1 = self._door(False, x, u, t, out)
            if x1 is not None:
                return x1
        args = self._args(x, u, p, t)
        if self._table is not None:
            x1 = self._table_solve(args[0], args[1], args[3], False)[0]
        else:
            x1 = self._solve(*args)[0]
        return x1 if out is None else write_out(out, x1, "StepFunction")

    def jacobians(self, x, u=None, p=None, t=None, *, parameters: bool = False, out=None):
        """``(x1, A, B)``, or ``(x1, A, B, C)`` with ``parameters=True`` (the implicit function
        theorem at the converged step: :mod:`ncgen.control.discrete`, or with the tables
        :mod:`ncgen.runtime.table_step`).  ``out``: a tuple of writable C-contiguous float64
        arrays of those shapes, written and returned."""
        if self._doors is not None and p is None and not parameters:
            result = self._door(True, x, u, t, out)
            if result is not None:
                return result
        result = self._jacobians(x, u, p, t, parameters)
        return result if out is None else write_out(out, result, "StepFunction.jacobians")

    def _jacobians(self, x, u, p, t, parameters: bool):
        """:meth:`jacobians` on the checked path (fresh arrays)."""
        args = self._args(x, u, p, t)
        if self._table is not None:            # a covered model has no parameters: C is empty
            out = self._table_solve(args[0], args[1], args[3], True)
            return out + (np.zeros((self.nx, 0)),) if parameters else out
        x1, z = self._solve(*args)
        J = self._jacobian(*self._sensitivities(z, *args))[0].reshape(self.nx, -1, order="F").copy()
        if not np.all(np.isfinite(J)):
            raise StepDidNotConverge(f"step of {self.model.name!r} (h = {self.h:g} s): its Jacobians are not "
                                     "finite: the Newton matrix G_z is singular there (redundant constraints "
                                     "or a singular configuration)")
        nx, nu = self.nx, self.nu
        out = (x1, J[:, :nx], J[:, nx:nx + nu])
        return out + (J[:, nx + nu:],) if parameters else out

    def _sensitivities(self, z, x, u, p, t) -> tuple[np.ndarray, np.ndarray]:
        """The nonzeros of ``G_z`` and ``G_y`` at the converged ``z`` (:mod:`ncgen.control.discrete`)."""
        self._load_flat()
        return self._G_z(z, x, u, p, t)[0], self._G_y(z, x, u, p, t)[0]

    # ------------------------------------------------------------------ rollouts
    def _rollout_piece(self, n: int):
        """The compiled rollout of ``n`` steps (``n`` is ``ROLLOUT_CHUNK`` or 1: built once per
        step function, whatever the rollouts' lengths)."""
        if n not in self._rollouts:
            self._load_flat()
            f = rollout_function(self.functions["step_solution"], n, self.h)
            self._rollouts[n] = compile_functions(f"{self.model.name}_rollout{n}", [f])["rollout"]
        return self._rollouts[n]

    def _chunks(self, N: int) -> list[tuple[int, int]]:
        """``(first step, steps)`` of the pieces a rollout of ``N`` steps is run in."""
        full = N // ROLLOUT_CHUNK * ROLLOUT_CHUNK
        return [(k, ROLLOUT_CHUNK) for k in range(0, full, ROLLOUT_CHUNK)] + [(k, 1) for k in range(full, N)]

    def _inputs(self, U) -> np.ndarray:
        U = as_numbers(U, "U", f"finite inputs of shape (N, {self.nu}) (one row per step)")
        if U.ndim == 1 and self.nu == 1:
            U = U[:, None]
        if U.ndim != 2 or U.shape[1] != self.nu or U.shape[0] < 1 or not np.all(np.isfinite(U)):
            raise NcgenError(f"U: expected finite inputs of shape (N, {self.nu}) (one row per step), got shape "
                             f"{U.shape}")
        return U

    def rollout(self, x0, U, p=None, t0=None) -> np.ndarray:
        """States after each of the ``N = len(U)`` steps, shape ``(N, nx)`` (``U``: ``(N, nu)``)."""
        U = self._inputs(U)
        x0, _, p, t0 = self._args(x0, U[0], p, t0)
        if self._table is not None:          # step by step through the tables: nothing to compile
            X, x = np.empty((U.shape[0], self.nx)), x0
            for k in range(U.shape[0]):
                x = X[k] = self._table_solve(x, U[k], t0 + k * self.h, False, f" {k} of the rollout")[0]
            return X
        return self._rollout(x0, U, p, t0)[0]

    def _rollout(self, x0, U, p, t0) -> tuple[np.ndarray, np.ndarray]:
        """``(X, Z)``: the states after each step and each step's unknowns (rows)."""
        N, nz = U.shape[0], self.nz
        X, Z = np.empty((N, self.nx)), np.empty((N, nz))
        x = x0
        for k, n in self._chunks(N):
            Xc, Zc, res = self._rollout_piece(n)(x, U[k:k + n].T.ravel(order="F"), p, t0 + k * self.h)
            Xc, Zc = Xc.reshape(self.nx, n, order="F").T, Zc.reshape(nz, n, order="F").T
            for i in range(n):
                self._check(float(res[i]), Xc[i], Zc[i], f" {k + i} of the rollout")
            X[k:k + n], Z[k:k + n] = Xc, Zc
            x = X[k + n - 1]
        return X, Z

    def rollout_gradient(self, x0, U, dX, p=None, t0=None, *, parameters: bool = False):
        """``(dx0, dU)`` (and ``dp`` with ``parameters=True``): the gradient of a cost ``J(X)``
        with respect to ``x0`` and ``U`` given ``dX = ∂J/∂X`` (shape of :meth:`rollout`'s
        result); one transposed IFT solve per step (``step_adjoint``, generated C), from the
        last step to the first (each step's ``x̄`` added to the ``∂J/∂X`` of the state it
        starts from)."""
        U = self._inputs(U)
        x0, _, p, t0 = self._args(x0, U[0], p, t0)
        N = U.shape[0]
        dX = np.asarray(dX, dtype=float)
        if dX.shape != (N, self.nx) or not np.all(np.isfinite(dX)):
            raise NcgenError(f"dX: expected finite ∂J/∂X of shape ({N}, {self.nx}), got shape {dX.shape}")
        X, Z = self._rollout(x0, U, p, t0)            # refuses a rollout that did not converge
        nx, nu = self.nx, self.nu
        dU, dp, carry = np.empty((N, nu)), np.zeros(self.np), np.zeros(nx)
        for k in range(N - 1, -1, -1):
            G_z, G_y = self._sensitivities(Z[k], x0 if k == 0 else X[k - 1], U[k], p, t0 + k * self.h)
            y_bar = self._adjoint(G_z, G_y, dX[k] + carry)[0]
            carry, dU[k] = y_bar[:nx].copy(), y_bar[nx:nx + nu]
            dp += y_bar[nx + nu:]
        if not (np.all(np.isfinite(carry)) and np.all(np.isfinite(dU)) and np.all(np.isfinite(dp))):
            raise StepDidNotConverge(f"rollout of {self.model.name!r}: its gradient is not finite: the Newton "
                                     "matrix G_z of a step is singular (redundant constraints or a singular "
                                     "configuration)")
        out = (carry, dU)
        return out + (dp,) if parameters else out

    # ------------------------------------------------------- tangent coordinates
    def tangent_basis(self, x, p=None, t=None) -> np.ndarray:
        """``T(x)``: orthonormal basis (nx × 2 dof) of the tangent space of the state
        manifold ``{Φ = 0, A v + Φ_t = 0}`` at ``x``."""
        from ncgen.assembly.manifold import null_basis
        x, _, p, t = self._args(x, np.zeros(self.nu), p, t)
        if self._J is None:
            self._J = state_constraint_jacobian(self.model)
        return null_basis(np.array(self._J(x, p, t)), self.nx)

    def reduced_jacobians(self, x, u=None, p=None, t=None):
        """``(x1, A_T, B_T)`` with ``A_T = T(x1)ᵀ A T(x)``, ``B_T = T(x1)ᵀ B`` (tangent coordinates)."""
        x1, A, B = self.jacobians(x, u, p, t)
        t1 = (self.model.t0 if t is None else float(t)) + self.h
        T0, T1 = self.tangent_basis(x, p, t), self.tangent_basis(x1, p, t1)
        return x1, T1.T @ A @ T0, T1.T @ B


def _positive(value, name: str, what: str) -> float:
    """``value`` as a float if it is a finite number above zero, else a clear error."""
    try:
        out = float(value)
    except (TypeError, ValueError):
        out = None
    if isinstance(value, bool) or out is None or not np.isfinite(out) or out <= 0:
        raise NcgenError(f"step_function: {name}: expected {what}, got {value!r}")
    return out
