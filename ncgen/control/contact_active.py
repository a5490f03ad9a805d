"""The contact step's equations over its active contacts only, assembled at run time from
compiled pieces (used by :mod:`ncgen.control.contact_step`).

The equations are those of :mod:`ncgen.control.contact_equations` (the stepper's own formulas;
see its docstring) for a step without a push-out.  A separated contact has ``P = 0`` and
contributes nothing else, so its impulses are no unknowns here; the generalised impulses
enter the RATTLE steps through two unknowns of their own, ``j₀ = W(q)ᵀ P`` and
``j_f = W(q_f)ᵀ P`` (nq each).  Unknowns ``Z = [z_f; y; z; j₀; j_f; P_a]`` (``P_a``: the active
contacts' impulses, dim each, in the order of the model's contacts), rows::

    R = [G_free(z_f); K_f y − [j_f; 0]; G_end(z; j₀, j_f); j₀ − Σ_a W_a(q)ᵀ P_a;
         j_f − Σ_a W_a(q_f)ᵀ P_a; the contact laws of the active contacts].

Compiled once per model and step: the *smooth part* (the rows without the sums, with their
sparse Jacobians in ``Z`` and ``y = [x; u; p]``, O(nq) in size) and, per *kind* of point
contact (equal gap and Jacobian-row formulas in the coordinates the contact depends on:
the equal spheres of a heap are two kinds, sphere–floor and sphere–sphere), a *law kernel*
(one active contact's law rows, ``−W(q)ᵀP`` and ``−W(q_f)ᵀP`` over its coordinates, and
their sparse Jacobian in its local arguments) and an *info kernel* mapped over every contact of
the kind (the velocities and gaps that classify the modes).  A call evaluates the smooth
part once and the law kernel per active contact, and assembles ``R_Z`` and ``R_y`` as one
sparse matrix (``R_y`` in compressed sparse columns: a few nonzeros a column); the state
``x⁺ = [q + h w; v⁺]`` is read from ``z``, and of ``∂Z/∂y`` only its rows (:attr:`state_rows`)
are solved for.
"""
from __future__ import annotations

import hashlib

import casadi as ca
import numpy as np
import scipy.sparse as sp

from ncgen.assembly.stepper_equations import contact_function, stepper_functions
from ncgen.codegen.c_binding import Signature, bind, open_library
from ncgen.codegen.casadi_abi import bind_casadi, work_arrays
from ncgen.codegen.package import ExtraSource
from ncgen.codegen.reroll import REROLL_INSTRUCTIONS
from ncgen.control.contact_equations import rattle_residual
from ncgen.control.discrete import residual_scale
from ncgen.errors import NcgenError

#: Law kernel selectors per active contact: closed at the free step's end, sticking,
#: sliding, impact (the step's), restitution, friction coefficient.
NS = 6
#: Newton iterations per block of the start (:meth:`ActiveContactEquations.start`), and
#: their residual tolerance relative to :func:`~ncgen.control.discrete.residual_scale`
#: (the polish's, :data:`~ncgen.control.contact_step.POLISH_TOL`).
START_ITER, START_TOL = 4, 1e-13
#: Arguments of a contact's kernels, in order, as blocks of nq (then its impulse and p):
#: start positions and velocities, the free step's w and end velocity, the response y's
#: velocity part, the final step's w and end velocity.
BLOCKS = ("q", "v", "wf", "vf", "yv", "w", "v1")
#: The library's own entry points (``<model>_contact_active_`` prefix; ``law`` stands for
#: ``law_<k>``, one per kind of contact), as templates/c/contact_active.c.j2 spells them.
SIGNATURES = {
    "law": Signature("int", (("int", "n"), ("const casadi_real *", "a"), ("const casadi_real *", "s"),
                             ("casadi_real *", "r"), ("casadi_real *", "J"), ("casadi_int *", "iw"),
                             ("casadi_real *", "w"))),
    "lu_columns": Signature("int", (("int", "n"), ("int", "m"), *(("const int *", f) for f in ("l_colind", "l_row")),
                                    ("const double *", "l_x"), *(("const int *", f) for f in ("u_colind", "u_row")),
                                    ("const double *", "u_x"), ("const int *", "perm_r"), ("const int *", "perm_c"),
                                    ("const int *", "b_colind"), ("const int *", "b_row"), ("const double *", "b_x"),
                                    ("int", "nr"), ("const int *", "rows"), ("const double *", "signs"),
                                    ("double *", "y"), ("double *", "X"), ("double *", "xs"))),
}


class _Kind:
    """One kind of point contact: ``rows(q_l, p) -> (g, W)`` (W: dim × n_l, normal row then
    tangent rows), its law kernel (``law``; compiled: ``loop`` over many contacts, with its
    work arrays ``iw``, ``w``; its ``J``'s ``pattern``, rows ``n_r`` and nonzeros ``nnz``),
    info kernel and contacts (indices, local coordinates)."""

    def __init__(self, rows, n_l):
        self.rows, self.n_l = rows, n_l
        self.contacts: list[int] = []
        self.law = self.info = self.pattern = self.loop = self.iw = self.w = self.I = self.info_args = None
        self.n_r = self.nnz = 0


def _finite(d: np.ndarray) -> np.ndarray:
    """A Newton step ``d``, or zeros where it is not finite (a singular block)."""
    return d if np.all(np.isfinite(d)) else np.zeros(len(d))


def _local_rows(g, W, q, p):
    """``(columns, rows function)`` of one point contact: the coordinates its gap and rows
    depend on or act on, and ``(q_l, p) -> (g, W_l)`` in them (subexpressions merged, so that
    equal contacts give equal functions)."""
    expr = ca.vertcat(g, ca.vec(W))
    cols = sorted(set(ca.jacobian_sparsity(expr, q).get_col()) | set(W.sparsity().get_col()))
    ql = ca.SX.sym("q_l", len(cols))
    qfull = ca.SX.zeros(q.shape[0])
    for k, i in enumerate(cols):
        qfull[i] = ql[k]
    f = ca.Function("f", [q, p], [g, W[:, cols]])
    g_l, W_l = ca.cse([*f(qfull, p)])
    return cols, ca.Function("rows", [ql, p], [ca.densify(g_l), ca.densify(W_l)], ["q_l", "p"], ["g", "W"])


def _law_kernel(kind: _Kind, dim: int, np_: int, h: float, name: str) -> ca.Function:
    """``(a, s) -> (r, J)``: one active contact's rows ``r = [laws (dim); −W(q)ᵀP; −W(q_f)ᵀP]``
    and ``J = ∂r/∂a`` (sparse), ``a = [q, v, w_f, v_f, y_v, w, v⁺ (local); P (dim); p]``."""
    n = kind.n_l
    a = ca.SX.sym("a", len(BLOCKS) * n + dim + np_)
    q, v, wf, vf, yv, w, v1 = (a[i * n:(i + 1) * n] for i in range(len(BLOCKS)))
    P, p = a[len(BLOCKS) * n:len(BLOCKS) * n + dim], a[len(BLOCKS) * n + dim:]
    s = ca.SX.sym("s", NS)
    closed_free, stick, slide, impact, e, mu = (s[i] for i in range(NS))
    U, U0, Uf, gf, _, W0, Wf = _velocities(kind.rows, q, v, wf, vf, yv, w, v1, p, impact, h)
    bias = closed_free * e * ca.fmin(U0[0], 0) + (1 - closed_free) * ca.fmax(0, 2 * gf / h - Uf[0])
    PT, VT = P[1:], U[1:] + e * U0[1:]
    speed = ca.sqrt(ca.sumsqr(VT) + (1 - slide))
    r = ca.vertcat(U[0] + bias, stick * VT + slide * (PT + mu * P[0] * VT / speed) + (1 - stick - slide) * PT,
                   -ca.mtimes(W0.T, P), -ca.mtimes(Wf.T, P))
    return ca.Function(name, [a, s], [ca.densify(r), ca.jacobian(r, a)], ["a", "s"], ["r", "J"])


def _velocities(rows, q, v, wf, vf, yv, w, v1, p, impact, h):
    """``(U, U⁻, U_f, g_f, g⁺, W(q), W(q_f))`` of one contact (module docstring of
    :mod:`ncgen.control.contact_equations`)."""
    qf = q + h * wf
    _, W0 = rows(q, p)
    gf, Wf = rows(qf, p)
    g1, W1 = rows(q + h * w, p)
    U0, Uf = ca.mtimes(W0, v), ca.mtimes(Wf, vf)
    U = impact * ca.mtimes(W1, v1) + (1 - impact) * (Uf + ca.mtimes(Wf, yv))
    return U, U0, Uf, gf, g1, W0, Wf


def _info_kernel(kind: _Kind, np_: int, h: float, name: str) -> ca.Function:
    """``(a, p, impact) -> [U; U⁻; U_f; g_f; g⁺]`` of every contact of ``kind`` (mapped: ``a``
    one column per contact, its ``q, v, w_f, v_f, y_v, w, v⁺``)."""
    n = kind.n_l
    a, p, impact = ca.SX.sym("a", len(BLOCKS) * n), ca.SX.sym("p", np_), ca.SX.sym("impact")
    U, U0, Uf, gf, g1, _, _ = _velocities(kind.rows, *(a[i * n:(i + 1) * n] for i in range(len(BLOCKS))),
                                          p, impact, h)
    one = ca.Function(f"{name}_one", [a, p, impact], [ca.densify(ca.vertcat(U, U0, Uf, gf, g1))],
                      ["a", "p", "impact"], ["info"])
    return one.map(name, "serial", len(kind.contacts), [1, 2], [])


class ActiveContactEquations:
    """The step's equations over the active contacts (module docstring) of ``model`` with
    step ``h``: :meth:`start`, :meth:`system`, :meth:`info`, :meth:`x1`, :meth:`jacobian`."""

    def __init__(self, model, h: float):
        from ncgen.control.step_support import compile_functions

        self.model, self.h = model, h
        nq, nc, self.dim = model.nq, model.nc, model.dim
        self.n1, self.nq = nq + nc, nq
        self.nZs = 5 * self.n1 + 2 * nq
        self.ny = 2 * nq + model.nu + model.np
        smooth = self._smooth_function()
        self._kinds, self._cols = self._contact_kinds()
        for k, kind in enumerate(self._kinds):
            kind.law = _law_kernel(kind, self.dim, model.np, h, f"contact_law{k}")
            kind.info = _info_kernel(kind, model.np, h, f"contact_info{k}")
        functions = [smooth, self._steps_function] + [f for kind in self._kinds for f in (kind.law, kind.info)]
        name = f"{model.name}_contact_active"
        laws = [{"name": kind.law.name(), "n_a": kind.law.nnz_in(0), "n_s": NS, "n_r": kind.law.nnz_out(0),
                 "nnz_J": kind.law.nnz_out(1)} for kind in self._kinds]
        # rerolled: a long map over many contacts stays a loop (not unrolled)
        compiled = compile_functions(name, functions, reroll_instructions=REROLL_INSTRUCTIONS,
                                     extra_sources=[ExtraSource("contact_active.c.j2", "contact_active.c",
                                                                {"laws": laws}),
                                                    ExtraSource("runtime/ncgen_lu_columns.h", "ncgen_lu_columns.h",
                                                                included=True)])
        self._smooth, self._steps = compiled[smooth.name()], compiled[self._steps_function.name()]
        lib = open_library(self._smooth.library)
        for k, kind in enumerate(self._kinds):
            kind.pattern = kind.law.sparsity_out(1)
            kind.n_r, kind.nnz = kind.law.nnz_out(0), kind.law.nnz_out(1)
            kind.law, kind.info = compiled[kind.law.name()], compiled[kind.info.name()]
            kind.loop = bind(lib, f"{name}_law_{k}", SIGNATURES["law"], addresses=True)
            law = f"{name}_{laws[k]['name']}"
            kind.iw, kind.w = work_arrays(bind_casadi(lib, law), law)
        self._lu_columns = bind(lib, f"{name}_lu_columns", SIGNATURES["lu_columns"], addresses=True)
        self._kind_of = np.empty(model.nk, int)
        for k, kind in enumerate(self._kinds):
            self._kind_of[kind.contacts] = k
            kind.I = np.array([self._cols[c] for c in kind.contacts])     # contacts × n_l
            # the info kernel's argument: per contact its BLOCKS' local coordinates
            kind.info_args = (np.arange(len(BLOCKS))[None, :, None] * self.nq + kind.I[:, None, :]).ravel()
        # the smooth part's Jacobians as (row, column) lists in [Z; y]
        self._smooth_rc = [(np.array(smooth.sparsity_out(i).row()), np.array(smooth.sparsity_out(i).get_col()))
                           for i in (1, 2)]
        self._scale = residual_scale(model)
        self._e_mu = np.array([[c["restitution"], c["mu"]] for c in model.contacts]).reshape(-1, 2)
        self._active_key = None
        self._columns_buffers = (np.empty((0, 0)), np.empty(0), np.empty(0))
        #: The rows of ``Z`` that ``x⁺`` reads (``w``, then ``v⁺``): :meth:`jacobian`'s.
        self.state_rows = np.concatenate([3 * self.n1 + np.arange(nq), 4 * self.n1 + np.arange(nq)])

    # ----------------------------------------------------------------- building
    def _smooth_function(self) -> ca.Function:
        model, h, nq, nc, n1 = self.model, self.h, self.nq, self.model.nc, self.n1
        newton, velocity = stepper_functions(model)[:2]
        Z = ca.SX.sym("Z", self.nZs)
        x, u, p, t = ca.SX.sym("x", 2 * nq), ca.SX.sym("u", model.nu), ca.SX.sym("p", model.np), ca.SX.sym("t")
        q, v = x[:nq], x[nq:]
        zf, y, z = Z[:2 * n1], Z[2 * n1:3 * n1], Z[3 * n1:5 * n1]
        j0, jf = Z[5 * n1:5 * n1 + nq], Z[5 * n1 + nq:]
        zero = ca.SX.zeros(nq)
        G_free, K_f = rattle_residual(newton, velocity, nq, nc, h, t, q, v, u, p, zf, zero, zero)
        G_end, _ = rattle_residual(newton, velocity, nq, nc, h, t, q, v, u, p, z, j0, jf)
        R = ca.densify(ca.vertcat(G_free, ca.mtimes(K_f, y) - ca.vertcat(jf, ca.SX.zeros(nc)), G_end, j0, jf))
        yy = ca.vertcat(x, u, p)
        R_Z = ca.jacobian(R, Z)
        blocks = [slice(0, 2 * n1), slice(2 * n1, 3 * n1), slice(3 * n1, 5 * n1)]
        D = ca.vertcat(*(ca.solve(R_Z[b, b], R[b]) for b in blocks))
        self._steps_function = ca.Function("contact_block_steps", [Z, x, u, p, t], [R, ca.densify(D)],
                                           ["Z", "x", "u", "p", "t"], ["R", "D"])
        return ca.Function("contact_smooth", [Z, x, u, p, t], [R, R_Z, ca.jacobian(R, yy)],
                           ["Z", "x", "u", "p", "t"], ["R", "R_Z", "R_y"])

    def _contact_kinds(self):
        """The kinds of point contact (:class:`_Kind`) and each contact's coordinates."""
        model = self.model
        q, p = ca.SX.sym("q", model.nq), ca.SX.sym("p", model.np)
        g, Wt, _ = contact_function(model)(q, ca.SX.zeros(model.nq), p)
        kinds: dict[str, _Kind] = {}
        cols = []
        dim = self.dim
        for k in range(model.nk):
            c, rows = _local_rows(g[k], Wt[:, k * dim:(k + 1) * dim].T, q, p)
            key = hashlib.sha256(rows.serialize().encode()).hexdigest()
            kind = kinds.setdefault(key, _Kind(rows, len(c)))
            kind.contacts.append(k)
            cols.append(np.array(c, int))
        return list(kinds.values()), cols

    # ------------------------------------------------------------------- layout
    def _gather(self, active):
        """Per-active-set index tables (kept for the last active set): per kind of contact
        (:meth:`_laws` calls its law kernel once over them) its active contacts' places in
        ``active``, their kernel arguments' places in the gather vector
        ``[q, v, w_f, v_f, y_v, w, v⁺, P_a, p]`` and their rows' places in ``R`` (one row of
        each per contact); the rows and columns in ``[Z; y]`` of every nonzero of ``[R_Z R_y]``
        (the smooth part's, then each kind's contacts' ``J``), summed into ``R_Z`` and ``R_y``
        (both CSC)."""
        key = tuple(active)
        if key == self._active_key:
            return self._tables
        nq, n1, nZs, dim, npar = self.nq, self.n1, self.nZs, self.dim, self.model.np
        na = len(active)
        nZ = nZs + na * dim
        p_y = nZ + 2 * nq + self.model.nu + np.arange(npar)
        gathered = [0, nq, 2 * nq, 3 * nq, 4 * nq, 5 * nq, 6 * nq]          # BLOCKS in the gather vector
        placed = [nZ, nZ + nq, 0, n1, 2 * n1, 3 * n1, 4 * n1]               # ... and in [Z; y]
        (rz, cz), (ry, cy) = self._smooth_rc
        groups, rows_all, cols_all = [], [rz, ry], [cz, cy + nZ]
        kinds = self._kind_of[active]
        for k, kind in enumerate(self._kinds):
            pos = np.flatnonzero(kinds == k)
            if not len(pos):
                continue
            src, rrows = [], []
            J = kind.pattern
            for a in pos:
                I, P_a = self._cols[active[a]], nZs + a * dim + np.arange(dim)
                src.append(np.concatenate([s + I for s in gathered] + [7 * nq + a * dim + np.arange(dim),
                                                                       7 * nq + na * dim + np.arange(npar)]))
                cols = np.concatenate([s + I for s in placed] + [P_a, p_y])
                rows = np.concatenate([P_a, 5 * n1 + I, 5 * n1 + nq + I])
                rrows.append(rows)
                rows_all.append(rows[J.row()])
                cols_all.append(cols[J.get_col()])
            groups.append((kind, pos, np.array(src), np.array(rrows).ravel()))
        rows, cols = np.concatenate(rows_all), np.concatenate(cols_all)
        # [R_Z R_y]'s nonzeros summed into R_Z's CSC data and R_y's dense entries
        in_Z = cols < nZ
        keys, where = np.unique(cols[in_Z] * nZ + rows[in_Z], return_inverse=True)
        indptr = np.searchsorted(keys // nZ, np.arange(nZ + 1))
        keys_y, where_y = np.unique((cols[~in_Z] - nZ) * nZ + rows[~in_Z], return_inverse=True)
        indptr_y = np.searchsorted(keys_y // nZ, np.arange(self.ny + 1))
        self._tables = (groups, nZ, np.flatnonzero(in_Z), np.flatnonzero(~in_Z), where, len(keys), keys % nZ, indptr,
                        where_y, len(keys_y), keys_y % nZ, indptr_y)
        self._active_key = key
        return self._tables

    def _blocks(self, Z, x):
        """The gather vector's block part ``[q, v, w_f, v_f, y_v, w, v⁺]``."""
        nq, n1 = self.nq, self.n1
        return np.concatenate([x, Z[:nq], Z[n1:n1 + nq], Z[2 * n1:2 * n1 + nq], Z[3 * n1:3 * n1 + nq],
                               Z[4 * n1:4 * n1 + nq]])

    # ---------------------------------------------------------------- interface
    #: No push-out in these equations (a step with one uses the all-contacts equations).
    push_out = False
    #: Few rows hold one unknown alone: :class:`~ncgen.control.contact_step._Factor` factors all.
    single_rows = False

    @staticmethod
    def active(sel) -> np.ndarray:
        """The active (closed) contacts of the selectors ``sel`` (:mod:`contact_equations`)."""
        from ncgen.control.contact_equations import NSEL
        nk = (len(sel) - 2) // NSEL
        return np.flatnonzero(sel[0:NSEL * nk:NSEL] > 0)

    def start(self, x, x1, P, sel, u, p, t) -> np.ndarray:
        """Newton's start from the stepper's end state ``x1`` and impulses ``P`` (all contacts),
        with the unknowns the stepper does not return solved for them (:meth:`_complete`)."""
        nq, n1, dim = self.nq, self.n1, self.dim
        active = self.active(sel)
        Z = np.zeros(self.nZs + len(active) * dim)
        w = (x1[:nq] - x[:nq]) / self.h
        for o in (0, 3 * n1):
            Z[o:o + nq], Z[o + n1:o + n1 + nq] = w, x1[nq:]
        Z[self.nZs:] = P.reshape(-1, dim)[active].ravel()
        return self._complete(Z, x, u, p, t, sel)

    def _complete(self, Z, x, u, p, t, sel) -> np.ndarray:
        """The start ``Z`` with the free step ``z_f`` (Newton on ``G_free``, its own block of
        the smooth part), the generalised impulses ``j₀, j_f`` of the impulses ``P_a``, the
        response ``y = K_f⁻¹ [j_f; 0]`` and the final step's ``z`` (Newton on ``G_end`` with
        those impulses) solved in turn, each to the rounding floor: where the stepper's
        impulses solve the contact laws to it, ``Z`` solves the whole system and the polish
        needs one evaluation and one factorisation (the heap's step: 0.9 ms less).  Each
        block's Newton stops after :data:`START_ITER` iterations (the polish goes on from there)."""
        n1, nZs = self.n1, self.nZs
        tol = START_TOL * self._scale
        free, response, end = slice(0, 2 * n1), slice(2 * n1, 3 * n1), slice(3 * n1, 5 * n1)
        self._block_newton(Z, x, u, p, t, free, tol)
        active = self.active(sel)
        groups, nZ = self._gather(active)[:2]
        R_laws = self._laws(Z, x, p, sel, active, groups, nZ)[0]
        Z[5 * n1:nZs] = -R_laws[5 * n1:nZs]      # j₀ = Σ W_a(q)ᵀ P_a, j_f = Σ W_a(q_f)ᵀ P_a
        R_s, D = self._steps(Z[:nZs], x, u, p, [t])
        Z[response] -= _finite(D[response])      # linear in y
        self._block_newton(Z, x, u, p, t, end, tol, (R_s, D))
        return Z

    def _block_newton(self, Z, x, u, p, t, s, tol, evaluated=None):
        """Newton on the smooth part's rows ``s`` in the unknowns ``s`` (``Z`` in place), its
        steps ``J_ss⁻¹ R_s`` compiled (``contact_block_steps``: CasADi's sparse QR of each
        diagonal block; 0 where a block is singular: left to the polish); ``evaluated``: that
        function's ``(R, D)`` at ``Z`` if at hand."""
        for _ in range(START_ITER):
            R_s, D = evaluated if evaluated is not None else self._steps(Z[:self.nZs], x, u, p, [t])
            evaluated = None
            if np.max(np.abs(R_s[s]), initial=0.0) <= tol:
                break
            Z[s] -= _finite(D[s])

    def system(self, Z, x, u, p, t, sel):
        """``(R, R_Z, R_y)`` at ``Z`` (``R_Z`` and ``R_y`` sparse CSC)."""
        active = self.active(sel)
        groups, nZ, in_Z, in_y, where, nnz, indices, indptr, where_y, nnz_y, indices_y, indptr_y = self._gather(active)
        R, data = self._laws(Z, x, p, sel, active, groups, nZ)
        R_s, J_Z, J_y = self._smooth(Z[:self.nZs], x, u, p, [t])
        R[:self.nZs] += R_s
        data = np.concatenate([J_Z, J_y] + data)
        R_Z = sp.csc_matrix((np.bincount(where, data[in_Z], nnz), indices, indptr), shape=(nZ, nZ))
        R_y = sp.csc_matrix((np.bincount(where_y, data[in_y], nnz_y), indices_y, indptr_y), shape=(nZ, self.ny))
        return R, R_Z, R_y

    def _laws(self, Z, x, p, sel, active, groups, nZ):
        """``(R, J)``: the law kernels' rows summed into a residual of length ``nZ`` and their
        Jacobians' nonzeros (one array per kind, in the order of :meth:`_gather`); each kind's
        kernel runs over its active contacts in one C call."""
        R, data = np.zeros(nZ), []
        if len(active):
            g = np.concatenate([self._blocks(Z, x), Z[self.nZs:], p])
            S = self._selectors(active, sel)
            for kind, pos, src, rows in groups:
                a, s = g[src], np.ascontiguousarray(S[pos])
                r, J = np.empty((len(pos), kind.n_r)), np.empty((len(pos), kind.nnz))
                if kind.loop(len(pos), a.ctypes.data, s.ctypes.data, r.ctypes.data, J.ctypes.data,
                             kind.iw.ctypes.data, kind.w.ctypes.data):
                    raise NcgenError(f"{self.model.name}: the compiled contact law kernel failed")
                R += np.bincount(rows, r.ravel(), nZ)
                data.append(J.ravel())
        return R, data

    def solve_columns(self, lu, B, rows: np.ndarray, signs: np.ndarray):
        """``((A⁻¹ B)[rows], A⁻¹ B signs)`` for the many sparse columns of ``B`` (CSC) from
        SuperLU's factors ``lu`` of ``A`` (``ncgen_lu_columns.h``, compiled with the kernels:
        each column through the factors' columns it reaches; the heap's 120 columns 9× fewer
        operations than SuperLU's dense solve; of each solution only the rows asked for
        written); None where ``U`` has a zero pivot.  The rows are a buffer of this object,
        overwritten by the next call (fresh arrays cost their page faults)."""
        L, U = lu.L, lu.U
        n, m = B.shape
        X, y, xs = self._columns_buffers
        if X.shape != (len(rows), m) or len(xs) != n:
            X, y, xs = self._columns_buffers = (np.empty((len(rows), m), order="F"), np.empty(2 * n), np.empty(n))
        arrays = [np.ascontiguousarray(a, np.intc) if a.dtype.kind == "i" else np.ascontiguousarray(a, float)
                  for a in (L.indptr, L.indices, L.data, U.indptr, U.indices, U.data, lu.perm_r, lu.perm_c,
                            B.indptr, B.indices, B.data)]
        rows, signs = np.ascontiguousarray(rows, np.intc), np.ascontiguousarray(signs, float)
        if self._lu_columns(n, m, *(a.ctypes.data for a in arrays), len(rows), rows.ctypes.data, signs.ctypes.data,
                            y.ctypes.data, X.ctypes.data, xs.ctypes.data):
            return None
        return X, xs

    def _selectors(self, active, sel) -> np.ndarray:
        """The law kernels' selectors ``s`` (:data:`NS`) of the active contacts."""
        from ncgen.control.contact_equations import NSEL
        b = NSEL * active
        return np.column_stack([sel[b + 1], sel[b + 2], sel[b + 3], np.full(len(active), sel[-2]),
                                self._e_mu[active]])

    def info(self, Z, x, p, sel) -> np.ndarray:
        """The info vector of :func:`~ncgen.control.contact_equations.contact_residual`
        (``[x⁺; U; U⁻; U_f; g_f; g⁺; π; the pushed gaps]``, π = 0 and the pushed gaps g⁺:
        no push-out here) over every contact."""
        dim, nk = self.dim, self.model.nk
        B = self._blocks(Z, x)
        out = np.empty((nk, 3 * dim + 2))
        for kind in self._kinds:
            res = kind.info(B[kind.info_args], p, [sel[-2]])[0]
            out[kind.contacts] = res.reshape(len(kind.contacts), -1)
        U, U0, Uf = (out[:, i * dim:(i + 1) * dim].ravel() for i in range(3))
        g1 = out[:, 3 * dim + 1]
        return np.concatenate([self.x1(Z, x), U, U0, Uf, out[:, 3 * dim], g1, np.zeros(nk), g1])

    def velocities(self, x, x1, p):
        """The contact velocities ``(W(q⁺) v⁺, W(q) v)`` of every contact."""
        nq, n1 = self.nq, self.n1
        Z = np.zeros(self.nZs)
        Z[3 * n1:3 * n1 + nq], Z[4 * n1:4 * n1 + nq] = (x1[:nq] - x[:nq]) / self.h, x1[nq:]
        sel = np.zeros(2)
        sel[0] = 1.0                      # "impact": U from the end of the step
        info = self.info(Z, x, p, sel)
        nd = self.model.nk * self.dim
        return info[2 * nq:2 * nq + nd], info[2 * nq + nd:2 * nq + 2 * nd]

    def push(self, Z) -> np.ndarray:
        return np.zeros(self.model.nk)

    def x1(self, Z, x) -> np.ndarray:
        """``x⁺ = [q + h w; v⁺]``."""
        nq, n1 = self.nq, self.n1
        return np.concatenate([x[:nq] + self.h * Z[3 * n1:3 * n1 + nq], Z[4 * n1:4 * n1 + nq]])

    def jacobian(self, dZ, sign: float = 1.0) -> np.ndarray:
        """``∂x⁺/∂y`` from the rows :attr:`state_rows` of ``∂Z/∂y = sign dZ``."""
        nq = self.nq
        J = sign * dZ
        J[:nq] *= self.h
        J[np.arange(nq), np.arange(nq)] += 1.0
        return J

    def impulses(self, Z, sel) -> np.ndarray:
        """Every contact's impulse (nk·dim, zero where separated)."""
        P = np.zeros((self.model.nk, self.dim))
        P[self.active(sel)] = Z[self.nZs:].reshape(-1, self.dim)
        return P.ravel()
