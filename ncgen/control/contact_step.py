"""Step functions of models with nonsmooth contacts: the compiled stepper's step and its exact
derivatives from the active set of its converged contact solve (``nc.step_function`` on a
model built with ``contacts="nonsmooth"``).

Each call runs one step of the model's compiled contact stepper (from a cold start: no
repeat of earlier impulses), classifies every contact from the impulses it converged to —
separated (``P_N = 0``), sticking (``|P_T| < μ P_N``), sliding (on the cone's boundary) — and
whether the step is an impact, then solves the step's equations with that active set
(:mod:`ncgen.control.contact_equations`, the stepper's own formulas; by default written over
the active contacts only, :mod:`ncgen.control.contact_active`, and over all contacts — one
function, :class:`AllContactEquations` — for a step with a push-out or with
``equations="all"``) by Newton's method from the stepper's solution to the rounding floor,
and differentiates them by the implicit function theorem: one sparse LU of ``R_Z``, all
columns of ``R_y = ∂R/∂[x; u; p]`` at once::

    ∂Z/∂y = −R_Z⁻¹ R_y,      ∂x⁺/∂y = E ∂Z/∂y  (+ [I_q 0] where x⁺'s q is q + h w).

The state returned is that solution (it equals the stepper's to its Newton and contact
tolerances; :attr:`ContactStep.stepper_difference` says by how much), so that ``x⁺`` and its
Jacobians are one smooth function inside a mode, and central differences of ``x⁺`` agree
with them there.

Switching points.  Where a contact sits on the boundary between two modes the step is not
differentiable; the Jacobians returned are then one-sided, those of the mode the solve
converged to, with these choices: ``P_N = 0`` is separated; a contact on the cone's boundary
with no slip (``|V_T| ≤`` the solver's tolerance) is sticking (the derivative for
perturbations that keep it stuck).  A step is flagged (:attr:`ContactStep.at_switch`, the
reasons in :attr:`ContactStep.switches`) when, relative to :data:`SWITCH_TOL`, a closed
contact's ``P_N`` or a separated contact's normal velocity margin vanishes, the free step
ends with a gap at 0, a sticking contact's friction reaches the cone, a sliding contact's
slip vanishes, a restitution's ``min(U⁻_N, 0)`` is at its kink, or the impact test is at its
threshold, or a contact ends the step at the push-out's threshold depth or is pushed out
by nothing.  The push-out is itself a switch: a contact resting on its surface (gap 0) is
pushed back only below ``−PENETRATION_TOL`` (1e-8 m), so the Jacobians of a resting contact
are those of the side that is not pushed out (central differences of such a step must stay
within 1e-8 m).  The stepper repeats a push-out while its linearisation leaves a gap below
that threshold (curved gaps: sphere pairs, after a deep penetration); the equations hold one
pass, and a step whose result then differs from the stepper's by more than
:data:`MATCH_TOL` is refused (:class:`~ncgen.control.step.StepDidNotConverge`), as is a step
whose modes do not settle or whose equations do not converge.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import ctypes

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ncgen.control.contact_active import ActiveContactEquations
from ncgen.control.contact_equations import IMPACT_STEPS, NGLOBAL, NSEL, contact_residual, contact_system, layout
from ncgen.assembly.stepper_equations import contact_function
from ncgen.blas_threads import one_blas_thread
from ncgen.codegen.stepper_package import PENETRATION_TOL
from ncgen.control.discrete import residual_scale
from ncgen.errors import NcgenError
from ncgen.validation import as_scalar, write_out

#: Relative tolerance of the switching tests (module docstring).
SWITCH_TOL = 1e-7
#: A free step's gap within this (relative to ``h (1 + max |U|)``) of 0 counts as closed.
ROUNDOFF = 1e-12
#: Newton iterations of the polishing solve, and its residual tolerance relative to
#: :func:`~ncgen.control.discrete.residual_scale`.
POLISH_MAX_ITER, POLISH_TOL = 20, 1e-13
#: Largest ``|x⁺ − x⁺_stepper|∞ / (1 + |x⁺|∞)`` accepted: the stepper converges its contact
#: solve to ``CONTACT_REFINE_TOL`` = 1e-8 after an impact.
MATCH_TOL = 1e-6
MODES = ("separated", "sticking", "sliding", "closed")
_MODE_NAMES = np.array(MODES)
#: The step's equations: over the active contacts (compiled pieces, the default) or over all
#: contacts (one function; :class:`AllContactEquations`).
EQUATIONS = ("active", "all")
#: Largest system function (CasADi instructions) compiled to C; larger ones run on CasADi's
#: virtual machine (the 20-sphere heap's 1.1 million instructions kept gcc -O1 busy for more
#: than 15 minutes on a loaded 2-core machine; its VM evaluation takes 70 ms).
COMPILE_MAX_INSTRUCTIONS = 200_000
#: Relative singular-value cut of the least-norm solves of a singular ``R_Z`` (:class:`_Factor`).
LSTSQ_RCOND = 1e-10
#: Newton iterations of the compiled stepper's step (its default, ``MAX_ITER`` of the package).
STEPPER_MAX_ITER = 12
#: Passes of classifying the modes and solving with them, at most.
MODE_PASSES = 5
#: SuperLU's options for the active-contact equations' ``R_Z`` (:class:`_Factor` without
#: ``split``): their unknowns' order as laid out (free step, response, final step, generalised
#: impulses, impulses: nearly block triangular) and threshold pivoting (a diagonal entry within
#: 0.1 of its column's largest is kept).  The heap's 480 unknowns: 3 760 nonzeros in the
#: factors instead of COLAMD's 5 716, its factorisation 0.3 ms instead of 0.9 ms, its 120
#: columns' solve 1.2 ms instead of 2.4 ms.  A factorisation whose solve fails the residual
#: test is done again with SuperLU's defaults (COLAMD, partial pivoting) before a least-norm solve.
FAST_LU = {"permc_spec": "NATURAL", "diag_pivot_thresh": 0.1}


@dataclass
class ContactStep:
    """One step: ``x1`` (2nq), ``A = ∂x⁺/∂x``, ``B = ∂x⁺/∂u``, ``C = ∂x⁺/∂p``; ``modes`` per
    contact (``"separated"``, ``"sticking"``, ``"sliding"``, or ``"closed"`` for a closed
    contact without friction); ``impact``: whether the step is an impact (its contact laws
    hold on the velocities the step ends with); ``at_switch`` and ``switches`` (contact name
    and reason); ``impulses`` (nk × dim, N·s: normal, then tangents); ``stepper_difference``:
    ``|x⁺ − x⁺_stepper|∞``; ``push_out``: the push-out's ``π`` per contact (kg·m, 0 where none)."""

    x1: np.ndarray
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    modes: list
    impact: bool
    impulses: np.ndarray
    stepper_difference: float
    switches: list = field(default_factory=list)
    push_out: np.ndarray | None = None

    @property
    def at_switch(self) -> bool:
        return bool(self.switches)


class ContactStepFunction:
    """``x1 = st(x, u, p=None, t=None)``; ``x1, A, B = st.jacobians(x, u)``; ``st.step(x, u)``
    → :class:`ContactStep` with the modes and the switch flag; ``st.last``: the
    :class:`ContactStep` of the last call.  Rollouts run step by step.  No second derivatives
    (iLQR runs Gauss–Newton on it)."""

    kernels = "contact"
    second_derivatives = False

    def __init__(self, model, h: float, *, max_iter: int, abstol: float, equations: str = "active"):
        from ncgen.runtime.stepper_library import load_stepper

        if equations not in EQUATIONS:
            raise NcgenError(f"equations: expected one of {', '.join(map(repr, EQUATIONS))}, got {equations!r}")
        self.model, self.h = model, h
        self.nx, self.nu, self.np = 2 * model.nq, model.nu, model.np
        self._max_iter, self._abstol = max_iter, abstol
        self._stepper = load_stepper(model)
        #: Which equations the Jacobians come from (:data:`EQUATIONS`); a step with a push-out
        #: always uses ``"all"``'s (made on first need).
        self.equations = equations
        self._active = ActiveContactEquations(model, h) if equations == "active" else None
        self._all = AllContactEquations(model, h) if equations == "all" else None
        self._scale = residual_scale(model)
        self._g = float(np.linalg.norm(model.gravity))
        self.names = [c["name"] for c in model.contacts]
        self._mu = np.array([c["mu"] for c in model.contacts], float)
        self._e = np.array([c["restitution"] for c in model.contacts], float)
        self.last: ContactStep | None = None

    @property
    def evaluation(self) -> str:
        """How the step's equations are evaluated: ``"active"`` (compiled pieces over the active
        contacts, :mod:`ncgen.control.contact_active`), or the all-contacts function
        ``"compiled"`` (generated C, cached by content) or, above
        :data:`COMPILE_MAX_INSTRUCTIONS`, ``"casadi-vm"``."""
        return "active" if self._active is not None else self._all.evaluation

    def __repr__(self) -> str:
        return (f"<ContactStepFunction of {self.model.name!r}: RATTLE with {self.model.nk} nonsmooth contacts, "
                f"h={self.h} s, nx={self.nx}, nu={self.nu}>")

    # ------------------------------------------------------------------ arguments
    def _args(self, x, u, p, t):
        from ncgen.control.step_support import state_vector
        x = state_vector(x, self.nx, "x", "the state [q; v]")
        u = np.zeros(0) if u is None and self.nu == 0 else state_vector(u, self.nu, "u", "the inputs")
        p = np.asarray(self.model.p0, float) if p is None else state_vector(p, self.np, "p", "the parameters")
        t = self.model.t0 if t is None else as_scalar(t, "t")
        return x, u, p, t

    def _inputs(self, U) -> np.ndarray:
        U = np.atleast_2d(np.asarray(U, float))
        if self.nu == 0 and U.size == 0:
            return U.reshape(U.shape[0] if U.ndim == 2 else 0, 0)
        if U.ndim != 2 or U.shape[1] != self.nu:
            raise NcgenError(f"inputs U: expected an array of shape (N, {self.nu}), got shape {np.shape(U)}")
        return U

    # ----------------------------------------------------------------------- step
    def __call__(self, x, u=None, p=None, t=None, *, out=None) -> np.ndarray:
        """The state after one step (``out``: a writable C-contiguous float64 array of ``nx``
        values, written and returned)."""
        x1 = self.step(x, u, p, t).x1
        return x1 if out is None else write_out(out, x1, "ContactStepFunction")

    def jacobians(self, x, u=None, p=None, t=None, *, parameters: bool = False, out=None):
        """``(x1, A, B)`` (and ``C`` if ``parameters``) of one step (:meth:`step`); ``out``: a
        tuple of writable C-contiguous float64 arrays of those shapes, written and returned."""
        s = self.step(x, u, p, t)
        result = (s.x1, s.A, s.B, s.C) if parameters else (s.x1, s.A, s.B)
        return result if out is None else write_out(out, result, "ContactStepFunction.jacobians")

    def rollout(self, x0, U, p=None, t0=None) -> np.ndarray:
        """States ``x₁ … x_N`` (N × nx) under the inputs ``U`` (N × nu)."""
        U = self._inputs(U)
        x, _, p, t0 = self._args(x0, U[0] if len(U) else None, p, t0)
        X = np.empty((len(U), self.nx))
        for k in range(len(U)):
            x = X[k] = self.step(x, U[k], p, t0 + k * self.h).x1
        return X

    @one_blas_thread
    def step(self, x, u=None, p=None, t=None) -> ContactStep:
        """The step from ``x`` with its Jacobians, modes and switch flag (module docstring); its
        factorisations and solves on one BLAS thread (:mod:`ncgen.blas_threads`), as are
        :meth:`jacobians` and :meth:`rollout`, which call it."""
        from ncgen.control.step_support import StepDidNotConverge

        x, u, p, t = self._args(x, u, p, t)
        nk, dim = self.model.nk, self.model.dim
        status, x1_c, P = self._stepper_step(x, u, p, t)
        where = f"step of {self.model.name!r} (h = {self.h:g} s)"
        if status != 0:
            from ncgen.codegen.stepper_package import STATUS
            raise StepDidNotConverge(f"{where}: the contact stepper failed ({STATUS.get(status, status)})")
        # the first modes from the stepper's impulses and, for the slips, its end velocities
        eq = self._active if self._active is not None else self._equations_all()
        sel = self._modes(P, None, None, lambda: eq.velocities(x, x1_c, p))
        solved = self._solve(eq, x, x1_c, P, u, p, t, sel, where)
        if solved is None:        # a push-out: the all-contacts equations
            eq = self._equations_all()
            solved = self._solve(eq, x, x1_c, P, u, p, t, sel, where)
        Z, info, lu, Ry, sel = solved
        x1 = eq.x1(Z, x)
        difference = float(np.max(np.abs(x1 - x1_c)))
        if difference > MATCH_TOL * (1 + np.max(np.abs(x1))):
            raise StepDidNotConverge(f"{where}: the step's equations with the active set of its contact solve "
                                     f"end {difference:.3g} from the stepper's state (a push-out of a penetrating "
                                     "contact, or a contact solve that did not converge): no derivatives there")
        J = eq.jacobian(lu.solve_rows(Ry, eq.state_rows), -1.0)
        nx, nu = self.nx, self.nu
        P_end = eq.impulses(Z, sel)
        self.last = ContactStep(x1, J[:, :nx], J[:, nx:nx + nu], J[:, nx + nu:], self._mode_names(sel),
                                bool(sel[-2]), P_end.reshape(nk, dim), difference, self._switches(P_end, info, sel),
                                eq.push(Z))
        return self.last

    def _equations_all(self) -> "AllContactEquations":
        if self._all is None:
            self._all = AllContactEquations(self.model, self.h)
        return self._all

    def _solve(self, eq, x, x1_c, P, u, p, t, sel, where):
        """``(Z, info, lu, R_y, sel)``: the step's equations ``eq`` solved with the modes
        classified again after each solve until they settle; None when the active-contact
        equations meet a push-out (they have none)."""
        from ncgen.control.step_support import StepDidNotConverge
        Z = eq.start(x, x1_c, P, sel, u, p, t)
        for _ in range(MODE_PASSES):   # the modes depend on the free step, the slips, the push-out
            Z, lu, Ry = self._polish(eq, Z, x, u, p, t, sel, where)
            info = eq.info(Z, x, p, sel)
            new = self._modes(P, info, sel)
            if new[-1] and not eq.push_out:
                return None
            if np.array_equal(new, sel):
                return Z, info, lu, Ry, sel
            sel = new
        raise StepDidNotConverge(f"{where}: the modes of its contacts did not settle in {MODE_PASSES} passes")

    # ------------------------------------------------------------------- internals
    def _stepper_step(self, x, u, p, t):
        """``(status, x⁺, P)``: one step of the compiled contact stepper from a cold start (no
        halving), called directly (a single step needs no interruptible worker thread)."""
        from ncgen.codegen.stepper_package import TOL
        from ncgen.runtime.stepper_library import _ptr, step_options
        nq, nc = self.model.nq, self.model.nc
        q0, v0 = np.ascontiguousarray(x[:nq]), np.ascontiguousarray(x[nq:])
        Q, V, LAM = np.zeros((1, nq)), np.zeros((1, nq)), np.zeros((1, nc))
        it, done, splits = ctypes.c_long(0), ctypes.c_long(0), ctypes.c_long(0)
        P = np.zeros(self.model.nk * self.model.dim)
        U = np.ascontiguousarray(u, float) if self.nu else None
        status = self._stepper._simulate(_ptr(q0), _ptr(v0), float(t), float(self.h), 1, 1, _ptr(U),
                                         self.nu if U is not None else 0, _ptr(np.ascontiguousarray(p, float)),
                                         _ptr(Q), _ptr(V), _ptr(LAM), ctypes.byref(it),
                                         ctypes.byref(step_options(TOL, STEPPER_MAX_ITER, 0)), ctypes.byref(done),
                                         ctypes.byref(splits), _ptr(P))
        return int(status), np.concatenate([Q[0], V[0]]), P

    def _polish(self, eq, Z, x, u, p, t, sel, where):
        """``(Z, lu, R_y)``: Newton on the equations ``eq`` with the modes ``sel`` to its
        rounding floor; ``lu`` factors ``R_Z`` at the last iterate but one (``R_y`` there too),
        whose Newton step is at the rounding floor: the implicit function theorem's matrix."""
        from ncgen.control.step_support import StepDidNotConverge
        tol = POLISH_TOL * self._scale
        for _ in range(POLISH_MAX_ITER):
            R, RZ, Ry = eq.system(Z, x, u, p, t, sel)
            if not np.all(np.isfinite(R)):
                break
            converged = np.max(np.abs(R), initial=0.0) <= tol
            try:
                lu = _Factor(RZ, split=eq.single_rows, columns=getattr(eq, "solve_columns", None))
            except RuntimeError:
                break
            Z = Z - lu.solve(R)   # once more after the test: the quadratic step reaches the rounding floor
            if converged:
                return Z, lu, Ry
        raise StepDidNotConverge(f"{where}: the step's equations with the active set of its contact solve did "
                                 f"not converge (residual {np.max(np.abs(R), initial=0.0):.3g}); no derivatives there")

    def _info(self, info):
        """``(U, U⁻, U_f, g_f, g⁺, π, g_pushed)`` from the residual's ``info``."""
        nd, nk = self.model.nk * self.model.dim, self.model.nk
        o = self.nx + 3 * nd
        return (info[self.nx:self.nx + nd], info[self.nx + nd:o - nd], info[o - nd:o],
                *(info[o + i * nk:o + (i + 1) * nk] for i in range(4)))

    def _modes(self, P, info, previous, velocities=None) -> np.ndarray:
        """Selectors (:mod:`ncgen.control.contact_equations`) from the stepper's impulses ``P``
        and, once solved, the free step's gaps, the slips and the impact test (before:
        ``velocities()``, the contact velocities at the stepper's end and start, evaluated only
        where a contact's impulse is on its cone)."""
        nk, dim = self.model.nk, self.model.dim
        sel = np.zeros(NSEL * nk + NGLOBAL)
        U = U0 = Uf = gf = None
        if info is not None:
            U, U0, Uf, gf, g1, pi, g_pushed = self._info(info)
            vtol = self._vtol(U)
            push = np.min(g1, initial=0.0) < -PENETRATION_TOL
            sel[-1] = push
            if push:   # the pushed contacts: those pushed, and those the push leaves inside
                was = previous[4:NSEL * nk:NSEL] > 0
                big = float(np.max(np.abs(pi), initial=0.0))
                pushed = ((was & (pi > ROUNDOFF * big)) | (~was & (g_pushed < -PENETRATION_TOL * ROUNDOFF))
                          if previous[-1] else g1 < 0)
                sel[4:NSEL * nk:NSEL] = pushed
        S = sel[:NSEL * nk].reshape(nk, NSEL)          # a view: the contacts' selectors
        Pk, mu, e = P.reshape(nk, dim), self._mu, self._e
        closed = Pk[:, 0] > 0
        S[:, 0] = closed
        # closed at the free step's end; a gap within round-off of 0 (bodies falling
        # together in the free step: a stack) counts as closed, the side that presses it
        S[:, 1] = closed if gf is None else closed & (gf <= ROUNDOFF * (1 + np.max(np.abs(U))) * self.h)
        friction = closed & (mu > 0)
        slide = friction & (_row_norms(Pk[:, 1:]) >= mu * Pk[:, 0] * (1 - 1e-9))
        if U is None and velocities is not None and slide.any():
            U, U0 = velocities()
            vtol = self._vtol(U)
        if U is not None:
            slip = U.reshape(nk, dim)[:, 1:] + e[:, None] * U0.reshape(nk, dim)[:, 1:]
            slide &= _row_norms(slip) > vtol
        S[:, 2], S[:, 3] = friction & ~slide, slide
        if info is not None:
            sel[-2] = float(self._jump(U, Uf, sel) > IMPACT_STEPS * self._g * self.h)
        return sel

    def _jump(self, U, Uf, sel) -> float:
        """The impact test's measure: the largest change of a closed contact's velocity."""
        nk, dim = self.model.nk, self.model.dim
        closed = sel[0:NSEL * nk:NSEL] > 0
        return float(np.max(np.abs((U - Uf).reshape(nk, dim)[closed]), initial=0.0))

    def _vtol(self, U) -> float:
        return SWITCH_TOL * (1 + float(np.max(np.abs(U), initial=0.0)))

    def _mode_names(self, sel) -> list[str]:
        S = sel[:NSEL * self.model.nk].reshape(-1, NSEL) > 0
        return _MODE_NAMES[np.where(~S[:, 0], 0, np.where(S[:, 2], 1, np.where(S[:, 3], 2, 3)))].tolist()

    def _switches(self, P, info, sel) -> list[tuple[str, str]]:
        """Contacts (name, reason) at a switching point (module docstring)."""
        U, U0, Uf, gf, g1, pi, _ = self._info(info)
        dim, h = self.model.dim, self.h
        vtol = self._vtol(U)
        ptol = SWITCH_TOL * max(float(np.max(np.abs(P), initial=0.0)), self._scale * self._g * h)
        gtol = vtol * h
        nk, mu, e = self.model.nk, self._mu, self._e
        S = sel[:NSEL * nk].reshape(nk, NSEL) > 0
        Pk, Uk, U0k, Ufk = (a.reshape(nk, dim) for a in (P, U, U0, Uf))
        closed = S[:, 0]
        reasons = [
            (np.abs(gf) <= gtol, "the free step ends with the gap at 0"),
            (closed & (Pk[:, 0] <= ptol), "closed with a normal impulse at 0"),
            (closed & (e > 0) & (np.abs(U0k[:, 0]) <= vtol), "approach velocity at 0 (restitution's kink)"),
            (closed & ~S[:, 1] & (np.abs(2 * gf / h - Ufk[:, 0]) <= vtol), "about to close with its bias at its kink"),
            (closed & S[:, 2] & (_row_norms(Pk[:, 1:]) >= mu * Pk[:, 0] * (1 - SWITCH_TOL)),
             "sticking with the friction on the cone's boundary"),
            (closed & S[:, 3] & (_row_norms(Uk[:, 1:] + e[:, None] * U0k[:, 1:]) <= 1e3 * vtol),
             "sliding with its slip at 0"),
            (~closed & (gf <= 0) & (Uk[:, 0] + e * np.minimum(U0k[:, 0], 0) <= vtol),
             "separated with its normal velocity margin at 0")]
        depths = [
            (np.abs(g1 + PENETRATION_TOL) <= 1e-3 * PENETRATION_TOL, "ends the step at the push-out's threshold depth"),
            (S[:, 4] & (pi <= ptol * h), "pushed out with a push at 0")]
        out = []
        for group in (reasons, depths):       # by contact, each contact's reasons in this order
            flagged = np.column_stack([m for m, _ in group])
            out += [(self.names[k], group[i][1]) for k, i in zip(*np.nonzero(flagged))]
        limit = IMPACT_STEPS * self._g * h
        if limit > 0 and abs(self._jump(U, Uf, sel) - limit) <= 1e-3 * limit:
            out.append(("(step)", "the impact test at its threshold"))
        return out


class AllContactEquations:
    """The step's equations over every contact, the modes as 0/1 selectors
    (:func:`~ncgen.control.contact_equations.contact_residual`): one function for every active
    set, push-outs included; compiled up to :data:`COMPILE_MAX_INSTRUCTIONS`, else run on
    CasADi's virtual machine.  The interface of
    :class:`~ncgen.control.contact_active.ActiveContactEquations`."""

    push_out = True
    #: Most rows hold one unknown alone (separated contacts' ``P = 0``, ``π = 0``): :class:`_Factor` splits them off.
    single_rows = True

    def __init__(self, model, h: float):
        from ncgen.control.step_support import compile_functions
        self.model, self.h = model, h
        system = contact_system(contact_residual(model, h))
        self.evaluation = "compiled" if system.n_instructions() <= COMPILE_MAX_INSTRUCTIONS else "casadi-vm"
        self._system = (compile_functions(f"{model.name}_contact_step", [system])[system.name()]
                        if self.evaluation == "compiled" else _Nonzeros(system))
        self._patterns = [(np.array(sp_.row()), np.array(sp_.colind()), sp_.shape)
                          for sp_ in (system.sparsity_out(2), system.sparsity_out(3))]
        self._rows = contact_function(model)
        self._L = layout(model)
        self._info = None
        #: The rows of ``Z`` holding ``x⁺``: :meth:`jacobian`'s.
        self.state_rows = np.concatenate([np.arange(self._L["vm"].stop)[s] for s in self._L["x1"]])

    def velocities(self, x, x1, p):
        """The contact velocities ``(W(q⁺) v⁺, W(q) v)`` of every contact."""
        nq = self.model.nq
        return (np.asarray(self._rows(xx[:nq], xx[nq:], p)[2].full()).ravel() for xx in (x1, x))

    def start(self, x, x1, P, sel, u, p, t) -> np.ndarray:
        """Newton's start: the free step and the final step from the stepper's end state."""
        nq, nc, L = self.model.nq, self.model.nc, self._L
        Z = np.zeros(L["vm"].stop)
        w = (x1[:nq] - x[:nq]) / self.h
        Z[L["zf"]][:nq] = w
        Z[L["zf"]][nq + nc:2 * nq + nc] = x1[nq:]
        Z[L["P"]] = P
        Z[L["z"]][:nq] = w
        Z[L["z"]][nq + nc:2 * nq + nc] = x1[nq:]
        Z[L["x1"][0]], Z[L["x1"][1]] = x1[:nq], x1[nq:]
        return Z

    def system(self, Z, x, u, p, t, sel):
        """``(R, R_Z, R_y)`` at ``Z`` (``R_Z`` sparse, ``R_y`` dense); :meth:`info` keeps the
        classifying vector of this evaluation."""
        (row, colind, shape), (row_y, colind_y, shape_y) = self._patterns
        R, info, RZ, Ry = self._system(Z, x, u, p, [t], sel)
        self._info = info.copy()
        return R, sp.csc_matrix((RZ, row, colind), shape=shape), sp.csc_matrix((Ry, row_y, colind_y),
                                                                               shape=shape_y).toarray()

    def info(self, Z, x, p, sel) -> np.ndarray:
        return self._info

    def x1(self, Z, x) -> np.ndarray:
        L = self._L
        return np.concatenate([Z[L["x1"][0]], Z[L["x1"][1]]])

    def jacobian(self, dZ, sign: float = 1.0) -> np.ndarray:
        """``∂x⁺/∂y`` from the rows :attr:`state_rows` of ``∂Z/∂y = sign dZ``."""
        return sign * dZ

    def impulses(self, Z, sel) -> np.ndarray:
        return Z[self._L["P"]].copy()

    def push(self, Z) -> np.ndarray:
        return Z[self._L["pi"]].copy()


@lru_cache(maxsize=8)
def _signs(m: int) -> np.ndarray:
    """``m`` random signs, drawn once per ``m`` (the many-column solves' residual test: a failed
    solve is no adversary of a fixed combination)."""
    return np.random.default_rng(39).choice((-1.0, 1.0), m)


def _row_norms(X: np.ndarray) -> np.ndarray:
    """The Euclidean norm of each row of ``X`` (``np.linalg.norm(X, axis=1)``, without its overhead)."""
    return np.sqrt(np.einsum("ij,ij->i", X, X))


class _Nonzeros:
    """A CasADi function on its virtual machine, called as a compiled
    :class:`~ncgen.codegen.direct.DirectFunction` is: its outputs' nonzeros as arrays."""

    def __init__(self, f):
        self.f = f

    def __call__(self, *args):
        return [np.array(out.nonzeros()) for out in self.f(*args)]


def _solve_columns(lu, B: np.ndarray) -> np.ndarray:
    """``A⁻¹ B`` for many columns from SuperLU's factors ``Pr A Pc = L U`` by sparse triangular
    solves (SuperLU's own multi-column solve took 0.5 s where these take 30 ms: the heap's
    690 × 690 system, 120 columns)."""
    n = B.shape[0]
    Pr = sp.csr_matrix((np.ones(n), (lu.perm_r, np.arange(n))), shape=(n, n))
    Y = spla.spsolve_triangular(lu.L.tocsr(), Pr @ B, lower=True, unit_diagonal=True)
    Y = spla.spsolve_triangular(lu.U.tocsr(), Y, lower=False)
    return Y[lu.perm_c]


class _Factor:
    """``R_Z`` factored for solves.  With ``split`` (the all-contacts equations) the rows that
    hold one unknown alone (``P = 0`` of a separated contact, ``π = 0`` of a contact not pushed
    out: most rows of a heap) are solved first, exactly (the matrix is block triangular), and
    the rest by SuperLU's sparse LU (the heap: 690 of 1320 unknowns, 1 ms instead of 100 ms),
    its many columns by sparse triangular solves (:func:`_solve_columns`).  Without (the
    active-contact equations, which have no such rows to speak of) the whole matrix by
    SuperLU with :data:`FAST_LU`, its many columns by SuperLU's own solve (the heap's 480
    unknowns: 120 columns in 1 ms, where the triangular solves take 3 ms) or, for sparse
    columns of which only some rows are wanted (:meth:`solve_rows`), by ``columns(lu, B,
    rows, signs)`` where given (the active-contact equations' compiled solve,
    :meth:`~ncgen.control.contact_active.ActiveContactEquations.solve_columns`; None: a zero
    pivot)."""

    def __init__(self, A, split: bool = True, columns=None):
        self.split, self.columns = split, columns
        if split:
            A = A.tocsr()
            A.eliminate_zeros()          # entries the modes' selectors set to 0
            d = A.diagonal()
            self.single = (np.diff(A.indptr) == 1) & (d != 0)
            self.keep = ~self.single
            self.d = d[self.single]
            rows = A[self.keep]
            self.A_ks = rows[:, self.single]
            self.A_kk = rows[:, self.keep].tocsc()
        else:
            self.A_kk = A
        self.options = {} if split else FAST_LU
        self.lu = self._splu(self.options)

    def _splu(self, options):
        try:
            return spla.splu(self.A_kk, **options)
        except RuntimeError:           # exactly singular: redundant contacts
            return None

    def solve(self, B: np.ndarray) -> np.ndarray:
        """``R_Z⁻¹ B`` for a vector or the columns of a matrix; where ``R_Z`` is singular
        (redundant sticking contacts: a box standing on two or more corners, whose impulses
        are a family — the stepper takes its least-norm member), the least-norm solution:
        ``x⁺`` and its Jacobians do not depend on how the family's impulses are split."""
        if self.split:
            X = np.empty(B.shape)
            X_s = B[self.single] / (self.d if B.ndim == 1 else self.d[:, None])
            B_k = B[self.keep] - self.A_ks @ X_s
            X[self.single] = X_s
        else:
            B_k = B
        X_k = self._lu_solve(B_k)
        if X_k is None and self.options:     # the fast options' pivots too small: SuperLU's defaults
            self.options = {}
            self.lu = self._splu(self.options)
            X_k = self._lu_solve(B_k)
        if X_k is None:
            X_k = np.linalg.lstsq(self.A_kk.toarray(), B_k, rcond=LSTSQ_RCOND)[0]
        if not self.split:
            return X_k
        X[self.keep] = X_k
        return X

    def solve_rows(self, B, rows: np.ndarray) -> np.ndarray:
        """``(R_Z⁻¹ B)[rows]`` for the columns of ``B`` (dense, or sparse CSC: then by
        ``columns`` where given, its solutions' combination with random signs checked as
        :meth:`_lu_solve` checks, and else as :meth:`solve` does)."""
        if sp.issparse(B):
            if self.columns is not None and not self.split and self.lu is not None:
                signs = _signs(B.shape[1])
                solved = self.columns(self.lu, B, rows, signs)
                if solved is not None:
                    X, xs = solved
                    scale = (1 + np.max(np.abs(B.data), initial=0.0)) * B.shape[1]
                    if np.all(np.isfinite(X)) and _residual_ok(self.A_kk, xs, B @ signs, scale):
                        return X
            B = B.toarray()
        return self.solve(B)[rows]

    def _lu_solve(self, B_k):
        """``A_kk⁻¹ B_k`` from the LU factors, or None (and no factors kept) where there are none
        or the solve fails its residual test (1e-9 relative; many columns: their combination
        with random signs, relative to the columns' count)."""
        if self.lu is None:
            return None
        X_k = (self.lu.solve(B_k) if B_k.ndim == 1 else _solve_columns(self.lu, B_k) if self.split else
               self.lu.solve(np.asfortranarray(B_k)))
        X, B, scale = X_k, B_k, 1 + max(B_k.max(initial=0.0), -B_k.min(initial=0.0))   # no temporaries
        if B.ndim == 2:       # a fifth of the cost of every column's residual; a NaN or inf stays in the sum
            signs = _signs(B.shape[1])                         # einsum: no BLAS threads (module docstring)
            X, B, scale = np.einsum("ij,j->i", X, signs), np.einsum("ij,j->i", B, signs), scale * B.shape[1]
        if not _residual_ok(self.A_kk, X, B, scale):
            self.lu = None
            return None
        return X_k


def _residual_ok(A, X, B, scale: float) -> bool:
    """``X`` finite and ``|A X − B|∞ ≤ 1e-9 scale`` (a NaN or inf fails)."""
    return bool(np.all(np.isfinite(X)) and np.max(np.abs(A @ X - B), initial=0.0) <= 1e-9 * scale)
